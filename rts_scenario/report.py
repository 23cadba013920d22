"""The verdict of a run and its evidence: per target, per quantity, per frame."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass
class ErrorStats:
    """Error statistics of one quantity over matched detections."""

    count: int
    rms: float
    max: float
    p50: float
    p95: float

    @classmethod
    def of(cls, errors: FloatArray) -> ErrorStats:
        """Statistics of the finite values of ``errors``."""
        e = np.abs(errors[np.isfinite(errors)])
        if e.size == 0:
            return cls(0, float("nan"), float("nan"), float("nan"), float("nan"))
        return cls(int(e.size), float(np.sqrt(np.mean(e * e))), float(e.max()),
                   float(np.percentile(e, 50)), float(np.percentile(e, 95)))


@dataclass
class TargetResult:
    """One target's result."""

    name: str
    checkable_frames: int
    detected_frames: int
    detection_rate: float
    errors: dict[str, ErrorStats]
    passed: bool


@dataclass
class Report:
    """The verdict of a run and the evidence for it."""

    scene: str
    passed: bool
    reasons: list[str]
    frames: dict[str, int]
    targets: list[TargetResult]
    errors: dict[str, ErrorStats]
    detection_rate: float
    false_detections: int
    false_detections_per_frame: float
    bus: dict[str, int]
    timing: dict[str, float] = field(default_factory=dict)
    per_frame: dict[str, Any] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (per-frame arrays left out)."""
        out = asdict(self)
        out.pop("per_frame")
        return out

    def to_json(self) -> str:
        """Render the report as JSON (keys documented in docs/report.md)."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=True) + "\n"

    def table(self) -> str:
        """Render the report as a text table for people."""
        head = (f"{'target':<18} {'frames':>6} {'det. rate':>9}  {'range rms/max m':>15}  "
                f"{'vel rms/max m/s':>15}  {'az rms/max deg':>14}  {'el rms/max deg':>14}  "
                f"verdict")
        lines = [head, "-" * len(head)]

        def pair(s: ErrorStats) -> str:
            return "-" if not s.count else f"{s.rms:.3f}/{s.max:.3f}"

        for t in self.targets:
            e = t.errors
            lines.append(
                f"{t.name:<18} {t.checkable_frames:>6} {t.detection_rate:>9.1%}  "
                f"{pair(e['range_m']):>15}  {pair(e['radial_velocity_mps']):>15}  "
                f"{pair(e['az_deg']):>14}  {pair(e['el_deg']):>14}  "
                f"{'pass' if t.passed else 'FAIL'}")
        f = self.frames
        lines.append(f"frames: {f['total']} in the scene, {f['checked']} checked, "
                     f"{f['missing']} missing, {f['incomplete']} incomplete; "
                     f"false detections: {self.false_detections} "
                     f"({self.false_detections_per_frame:.3f} per frame)")
        problems = {k: v for k, v in self.bus.items() if k != "messages" and v}
        if problems:
            lines.append("bus: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in
                                             problems.items()))
        lines.append(("PASS" if self.passed else "FAIL") + f": {self.scene}"
                     + ("" if self.passed else " - " + "; ".join(self.reasons)))
        return "\n".join(lines)
