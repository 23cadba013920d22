"""Survey: where the radar sees each front end alone, and how strong.

Each FE plays a target alone at full weight, at the rig's reference range and level; the radar's
strongest detection where the pattern's echo shows (`rts_scenario.gate`: about its range and
radial velocity; not a reflection in the room) gives the direction it sees the FE in and its
level. On the bench the seen direction differs from the FE's mechanical direction by the radar's
near field, the FE's antenna offsets and any misplacement; that difference is what synthesis
must account for. Measurements run through a ``measure`` (schedule in, one `Detections` per
frame out): the simulated radar, or a real bench through `rts_scenario.pipeline.Pipeline.play`.
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
from .gate import Gate
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
    """Play each FE alone ``repeats`` times; return where the radar sees it, averaged.

    Each cycle is read at its strongest detection in the pattern's gate (`rts_scenario.gate`);
    an FE with none there in any of its cycles is not seen (NaN).
    """
    n = rig.n_front_ends
    ref = rig.reference
    rows = [[(q, 1.0, 0.0)] for q in np.repeat(np.arange(n), repeats).tolist()]
    pattern = pattern_schedule(rig, radar, rows, ref.range_m, ref.attenuation_db)
    cycles = measure(pattern)
    gate = Gate.of(rig, radar, pattern)
    seen = np.full((len(rows), 3), np.nan)
    for i, cycle in enumerate(cycles):  # one cycle per frame of the pattern
        k = gate.strongest(cycle, i)
        if k is None:
            continue
        for j, values in enumerate((cycle.az_deg, cycle.el_deg, cycle.rcs_dbsm)):
            if values is not None:
                seen[i, j] = values[k]
    # The mean of each FE's repeats that saw it; NaN for an FE none saw (no empty mean).
    per_repeat = seen.reshape(n, repeats, 3)
    valid = np.isfinite(per_repeat)
    count = valid.sum(axis=1)
    total = np.where(valid, per_repeat, 0.0).sum(axis=1)
    per_fe = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return SurveyResult(rig=rig.name, radar=radar.name, az_deg=rig.az_deg.copy(),
                        el_deg=rig.el_deg.copy(), seen_az_deg=per_fe[:, 0],
                        seen_el_deg=per_fe[:, 1], level_db=per_fe[:, 2] - ref.rcs_dbsm)


def modeled_directions(rig: Rig, radar: RadarProfile, estimator: str = "bartlett"
                       ) -> tuple[FloatArray, FloatArray]:
    """Where the solver's model expects the radar to see each FE alone: az, el deg, (F,) each.

    Each FE's modeled response on the radar's virtual array (`rts_scenario.responses`: physical
    antennas, distances, antenna offsets, near field) read by the radar's estimator.
    """
    from .radar.angle import make_estimator
    from .schedule.build import solver_inputs

    array, model = solver_inputs(radar, "modeled")
    assert model is not None
    vectors = model.vectors(rig, np.arange(rig.n_front_ends), array)
    est = make_estimator(estimator, array)(vectors.T)
    first = np.unique(est.source, return_index=True)[1]
    return est.az_deg[first], est.el_deg[first]


def placed_by_survey(rig: Rig, radar: RadarProfile, result: SurveyResult, *,
                     estimator: str = "bartlett", steps: int = 4) -> Rig:
    """Return the rig with FE directions moved so that its model shows what the survey saw.

    An FE that is not where the rig file says (mounting, a bent bracket) is seen elsewhere; the
    exact method solves with modeled responses, so the rig's direction of each FE is moved until
    its modeled response is seen where the radar saw it (fixed-point steps on the difference;
    the near field and antenna offsets stay in the model). FEs the survey did not see keep their
    directions. The survey's ``seen`` values are kept in the rig.
    """
    import dataclasses

    seen_az, seen_el = result.seen_az_deg, result.seen_el_deg
    ok = np.isfinite(seen_az) & np.isfinite(seen_el)
    az, el = rig.az_deg.copy(), rig.el_deg.copy()
    placed = rig
    for _ in range(steps):  # each step leaves a small fraction of the miss
        model_az, model_el = modeled_directions(placed, radar, estimator)
        az = np.where(ok, az + seen_az - model_az, az)
        el = np.where(ok, el + seen_el - model_el, el)
        placed = dataclasses.replace(placed, az_deg=az, el_deg=el)
    seen = np.stack([seen_az, seen_el, result.level_db], axis=1)
    return dataclasses.replace(placed, seen=seen)


__all__ = ["SurveyResult", "modeled_directions", "placed_by_survey", "survey"]
