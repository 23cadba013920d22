"""Survey: where the radar sees each front end alone, and how strong.

Each FE plays a target alone at full weight, at the rig's reference range and level; the radar's
strongest detection gives the direction it sees the FE in and its level. On the bench the seen
direction differs from the FE's mechanical direction by the radar's near field, the FE's antenna
offsets and any misplacement; that difference is what synthesis must account for. Measurements
run through a ``measure`` (schedule in, one `Detections` per frame out): the simulated radar, or
a real bench through `rts_scenario.pipeline.Pipeline.play`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .calibration import pattern_schedule
from .detections import Detections
from .radar.profile import RadarProfile
from .rig import Rig
from .schedule import Schedule

FloatArray = NDArray[np.float64]
Measure = Callable[[Schedule], list[Detections]]

# Frames per FE, averaged (noise).
REPEATS = 4


@dataclass(frozen=True)
class SurveyResult:
    """Where the radar sees each FE (NaN where it saw nothing), shape (F,) each.

    ``level_db`` is the detected RCS minus the rig's reference RCS: 0 dB for a channel that
    plays the reference level exactly.
    """

    rig: str
    radar: str
    az_deg: FloatArray
    el_deg: FloatArray
    seen_az_deg: FloatArray
    seen_el_deg: FloatArray
    level_db: FloatArray

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (``null`` for what was not seen)."""
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"rig": self.rig, "radar": self.radar, "front_ends": [
            {"index": i, "az_deg": num(self.az_deg[i]), "el_deg": num(self.el_deg[i]),
             "seen_az_deg": num(self.seen_az_deg[i]), "seen_el_deg": num(self.seen_el_deg[i]),
             "level_db": num(self.level_db[i])} for i in range(self.az_deg.size)]}

    def table(self) -> str:
        """Render the survey for people."""
        head = (f"{'FE':>3} {'az deg':>8} {'el deg':>8} {'seen az':>9} {'seen el':>9} "
                f"{'d az':>7} {'d el':>7} {'level dB':>8}")
        lines = [head, "-" * len(head)]
        for i in range(self.az_deg.size):  # one line per FE
            d_az = self.seen_az_deg[i] - self.az_deg[i]
            d_el = self.seen_el_deg[i] - self.el_deg[i]
            lines.append(f"{i:>3} {self.az_deg[i]:>8.3f} {self.el_deg[i]:>8.3f} "
                         f"{self.seen_az_deg[i]:>9.4f} {self.seen_el_deg[i]:>9.4f} "
                         f"{d_az:>7.4f} {d_el:>7.4f} {self.level_db[i]:>8.2f}")
        return "\n".join(lines)


def survey(rig: Rig, radar: RadarProfile, measure: Measure, repeats: int = REPEATS
           ) -> SurveyResult:
    """Play each FE alone ``repeats`` times; return where the radar sees it, averaged."""
    n = rig.n_front_ends
    ref = rig.reference
    rows = [[(q, 1.0, 0.0)] for q in np.repeat(np.arange(n), repeats).tolist()]
    cycles = measure(pattern_schedule(rig, radar, rows, ref.range_m, ref.attenuation_db))
    seen = np.full((len(rows), 3), np.nan)
    for i, cycle in enumerate(cycles):  # one cycle per frame of the pattern
        k = cycle.strongest()
        if k is None:
            continue
        for j, values in enumerate((cycle.az_deg, cycle.el_deg, cycle.rcs_dbsm)):
            if values is not None:
                seen[i, j] = values[k]
    with np.errstate(invalid="ignore"):
        per_fe = np.nanmean(seen.reshape(n, repeats, 3), axis=1) if np.isfinite(seen).any() \
            else np.full((n, 3), np.nan)
    return SurveyResult(rig=rig.name, radar=radar.name, az_deg=rig.az_deg.copy(),
                        el_deg=rig.el_deg.copy(), seen_az_deg=per_fe[:, 0],
                        seen_el_deg=per_fe[:, 1], level_db=per_fe[:, 2] - ref.rcs_dbsm)


__all__ = ["SurveyResult", "survey"]
