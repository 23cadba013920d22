"""The verdict of a run and its evidence: per target, per quantity, per frame.

Statistics are kept running (`RunningStats`) so a run of any length reports in bounded memory;
the per-frame record (`FrameRecord`) is written to disk only when asked for.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Collection, Iterable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .scenario.model import run_label

FloatArray = NDArray[np.float64]

# Percentiles come from a histogram of |error| with bins this much wider than the one below
# (1 % wide: a percentile is exact to 0.5 %) from HIST_LOW to HIST_HIGH; smaller errors count
# as zero, larger ones as HIST_HIGH (count, max and rms stay exact). About 3,500 bins: 14 kB
# per target and quantity, whatever the length of the run.
HIST_RATIO = 1.01
HIST_LOW = 1e-9
HIST_HIGH = 1e6
_LOG_RATIO = math.log(HIST_RATIO)
HIST_BINS = int(math.ceil(math.log(HIST_HIGH / HIST_LOW) / _LOG_RATIO)) + 2


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
        stats = RunningStats(1)
        stats.add(np.asarray(errors, dtype=np.float64).reshape(-1, 1))
        return stats.result()


class RunningStats:
    """Count, rms, max and percentiles of |error| of ``n`` series, fed in batches.

    Memory is constant: percentiles are read from a geometric histogram (`HIST_RATIO`).
    """

    def __init__(self, n: int = 1) -> None:
        self.count = np.zeros(n, dtype=np.int64)
        self.sum_sq = np.zeros(n)
        self.max = np.zeros(n)
        self.hist = np.zeros((n, HIST_BINS), dtype=np.int32)

    def add(self, errors: FloatArray, mask: NDArray[np.bool_] | None = None) -> None:
        """Take the finite values of ``errors`` (shape ``(..., n)``) where ``mask`` holds."""
        e = np.abs(np.asarray(errors, dtype=np.float64))
        if self.count.size == 0:  # no series (a scene without targets)
            return
        e = e.reshape(-1, self.count.size)
        take = np.isfinite(e)
        if mask is not None:
            take &= np.asarray(mask, dtype=bool).reshape(e.shape)
        series = np.broadcast_to(np.arange(self.count.size), e.shape)[take]
        e = e[take]
        if e.size == 0:
            return
        n = self.count.size
        self.count += np.bincount(series, minlength=n)
        self.sum_sq += np.bincount(series, weights=e * e, minlength=n)
        np.maximum.at(self.max, series, e)
        self.hist += np.bincount(series * HIST_BINS + _bin(e), minlength=n * HIST_BINS
                                 ).reshape(n, HIST_BINS).astype(np.int32)

    def result(self, i: int | None = None) -> ErrorStats:
        """Statistics of series ``i``, or of all series together."""
        pick = slice(None) if i is None else slice(i, i + 1)
        count = int(self.count[pick].sum())
        if count == 0:
            nan = float("nan")
            return ErrorStats(0, nan, nan, nan, nan)
        top = float(self.max[pick].max())
        hist = self.hist[pick].sum(axis=0)
        return ErrorStats(count, math.sqrt(float(self.sum_sq[pick].sum()) / count), top,
                          _percentile(hist, count, 50.0, top), _percentile(hist, count, 95.0, top))


def _percentile(hist: NDArray[np.int64], count: int, q: float, top: float) -> float:
    """Read the ``q``-th percentile (0..100) from a histogram: its bin's geometric middle."""
    rank = q / 100.0 * (count - 1)
    b = int(np.searchsorted(np.cumsum(hist), rank, side="right"))
    if b == 0:
        return 0.0
    return min(HIST_LOW * HIST_RATIO ** (b - 0.5), top)


def _bin(e: FloatArray) -> NDArray[np.int64]:
    """Histogram bin of each |error|: 0 below HIST_LOW, then geometric bins."""
    with np.errstate(divide="ignore"):
        b = np.floor(np.log(np.maximum(e, HIST_LOW * 0.5) / HIST_LOW) / _LOG_RATIO) + 1
    return np.clip(b, 0, HIST_BINS - 1).astype(np.int64)


class FrameRecord:
    """Per-frame arrays of a run, spilled to disk batch by batch (read back on demand).

    Each `append` writes one ``.npz`` with arrays whose first axis is frames; `load`
    concatenates them. The files live in ``folder`` (a private temporary folder by default,
    removed with the record).
    """

    def __init__(self, folder: str | Path | None = None) -> None:
        self._tmp = None if folder is not None else tempfile.TemporaryDirectory(
            prefix="rts-scenario-record-")
        self.folder = Path(folder if folder is not None else self._tmp.name)  # type: ignore[union-attr]
        self.folder.mkdir(parents=True, exist_ok=True)
        self.parts = 0
        self.frames = 0

    def append(self, arrays: dict[str, np.ndarray]) -> None:
        """Write one batch (all arrays share their first axis)."""
        np.savez(self.folder / f"part-{self.parts:06d}.npz", **arrays)  # type: ignore[arg-type]
        self.parts += 1
        self.frames += len(next(iter(arrays.values()))) if arrays else 0

    def load(self) -> dict[str, np.ndarray]:
        """All batches, concatenated along frames."""
        chunks: dict[str, list[np.ndarray]] = {}
        for i in range(self.parts):  # one file per batch
            with np.load(self.folder / f"part-{i:06d}.npz") as part:
                for key in part.files:
                    chunks.setdefault(key, []).append(part[key])
        return {k: np.concatenate(v) for k, v in chunks.items()}

    def close(self) -> None:
        """Remove the private folder (a named folder stays)."""
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


@dataclass
class TargetResult:
    """One target's result.

    ``passed``: the target fails none of the verdict's rules. ``checked``: some radar cycle
    in which it was checkable was received whole and judged; a target never checked (under
    limits the scene expects all along, say) has ``passed`` true and ``checked`` false, and the
    table says ``not checked``, not ``pass``.
    """

    name: str
    checkable_frames: int
    detected_frames: int
    detection_rate: float
    errors: dict[str, ErrorStats]
    passed: bool
    out_of_tolerance_frames: int = 0
    missed_frames: int = 0
    unchecked_frames: int = 0
    limits: dict[str, int] = field(default_factory=dict)
    unexpected_limits: list[str] = field(default_factory=list)
    played_frames: int = 0
    checked: bool = field(init=False)

    def __post_init__(self) -> None:
        self.checked = self.checkable_frames > self.unchecked_frames

    @property
    def verdict(self) -> str:
        """The table's verdict: ``pass``, ``not checked``, ``FAIL`` or ``FAIL (not checked)``."""
        if self.passed:
            return "pass" if self.checked else "not checked"
        return "FAIL" if self.checked else "FAIL (not checked)"


def not_checked_note(not_checked: int, targets: int) -> str:
    """`` (N of M targets not checked: ...)`` after a pass's name, or "" where all were.

    A scene that expects its limits may pass with targets the RTS never played or the radar
    could not be judged on: the pass says so beside its name, not only in its table.
    """
    if not not_checked:
        return ""
    return (f" ({not_checked} of {targets} targets not checked: under limits the scene "
            f"expects all along)")


@dataclass
class Report:
    """The verdict of a run and the evidence for it.

    ``scene_limits`` names the limits the whole scene hits (``{"why": ..., "expected": ...}``).
    ``solver_plan`` says where the run's solver plan came from (built, memory, disk).
    ``radar_clock`` is when the radar measured, as the check took it: its counter start, cycle
    and phase, each from the profile or learnt from the cycles' bus times
    (`rts_scenario.radar.clock.ClockTrack`).
    ``playback`` is how the schedule went out (`rts_scenario.playback.Playback`: frames sent,
    their lateness, the ambiguity window, the RTS's counters where it reports them).
    ``expected_not_hit`` lists the limits the scene expects that no target (or, for a
    target's own, that target) hit: the scene may not test what it means to.
    ``variant`` names the combination of the scene's ``parametrize`` block that ran, as the
    pytest plugin names it (``""`` for a scene without one), ``parameters`` holds its values.
    ``worst_frames`` lists the worst target-frames (misses first, then by error over
    tolerance); ``record`` holds every frame's arrays when the run was asked to record them
    (`per_frame` reads them back).
    """

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
    invalid_detections: int = 0
    folded_detections: int = 0
    target_frames: dict[str, int] = field(default_factory=dict)
    scene_limits: dict[str, dict[str, Any]] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    solver_plan: str = ""
    radar_clock: dict[str, Any] = field(default_factory=dict)
    playback: dict[str, Any] = field(default_factory=dict)
    variant: str = ""
    parameters: dict[str, Any] = field(default_factory=dict)
    expected_not_hit: list[str] = field(default_factory=list)
    # What the run was held to: ``tolerances`` per quantity, ``detection_rate`` (per target)
    # and ``max_false_detections_per_frame``, as the scene gives them or their defaults.
    expectations: dict[str, Any] = field(default_factory=dict)
    # The checked quantities (tolerance keys) the run's CAN mapping does not carry: ``why``,
    # the scene's ``tolerance`` and whether the scene ``written`` it (then it fails the run as
    # ``quantity_unchecked`` unless expected); the run was not held to those tolerances.
    unchecked_quantities: dict[str, dict[str, Any]] = field(default_factory=dict)
    worst_frames: list[dict[str, Any]] = field(default_factory=list, repr=False)
    record: FrameRecord | None = field(default=None, repr=False, compare=False)

    def add_expected_not_hit(self, limits: list[str]) -> None:
        """Add expected scene-wide ``limits`` the run did not hit, judged apart from the checker.

        They join the scene-wide ones (sorted), before the targets' own (``"name: limit"``: a
        limit's name holds no colon).
        """
        scene = sorted({*(x for x in self.expected_not_hit if ":" not in x), *limits})
        self.expected_not_hit = scene + [x for x in self.expected_not_hit if ":" in x]

    def add_playback_limits(self, limits: Mapping[str, str], expected: Collection[str]) -> None:
        """Add the scene-wide ``limits`` the playback hit (name -> why) to ``scene_limits``.

        ``expected``: the scene's expected limits (those hit and expected say so).
        """
        for name, why in limits.items():
            self.scene_limits[name] = {"why": why, "expected": name in expected}

    @property
    def label(self) -> str:
        """``scene[variant]``, as the pytest plugin names the run (``scene`` without one)."""
        return run_label(self.scene, self.variant)

    @property
    def not_checked_targets(self) -> list[str]:
        """Targets no radar cycle judged (`TargetResult.checked`): under limits all along."""
        return [t.name for t in self.targets if not t.checked]

    @property
    def verdict_line(self) -> str:
        """``PASS: label``, or ``FAIL: label - reasons``: the table's last line.

        A pass with targets never checked says how many (`not_checked_note`).
        """
        if self.passed:
            return f"PASS: {self.label}" + not_checked_note(len(self.not_checked_targets),
                                                            len(self.targets))
        return f"FAIL: {self.label} - " + "; ".join(self.reasons)

    @property
    def reason_codes(self) -> list[str]:
        """The codes of the reasons the run failed, each once (`reason_codes`)."""
        return reason_codes(self.reasons)

    @property
    def per_frame(self) -> dict[str, np.ndarray]:
        """Every frame's arrays, read back from the record (empty without one).

        Keys: ``frame``, ``t_s``, ``detected``, ``checkable``, ``frame_status``,
        ``adjacent_frame``, ``error_<quantity>`` (docs/report.md).
        """
        return self.record.load() if self.record is not None else {}

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (per-frame arrays and the worst frames left out)."""
        out = {k: v for k, v in asdict(_without_record(self)).items()
               if k not in ("record", "worst_frames")}
        return dict(strict(out))

    def to_json(self) -> str:
        """Render the report as strict JSON (keys documented in docs/report.md; NaN: null)."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    def table(self, verdict: bool = True) -> str:
        """Render the report as a text table for people; its last line the verdict (``verdict``).

        The pytest plugin leaves the verdict out: its failure text begins with it.
        """
        head = (f"{'target':<18} {'cycles':>6} {'det. rate':>9} {'missed':>6} {'out tol':>7}  "
                f"{'range rms/max m':>15}  {'vel rms/max m/s':>15}  {'az rms/max deg':>14}  "
                f"{'el rms/max deg':>14}  {'rcs rms/max dB':>14}  verdict")
        # An empty bench has no target rows: say what its run checks instead.
        lines = [head, "-" * len(head)] if self.targets else [
            "no targets: an empty bench, the radar's false detections are all the run checks"]

        def pair(s: ErrorStats) -> str:
            return "-" if not s.count else f"{s.rms:.3f}/{s.max:.3f}"

        for t in self.targets:
            e = t.errors
            rate = "-" if not t.checkable_frames else f"{t.detection_rate:.1%}"
            lines.append(
                f"{t.name:<18} {t.checkable_frames:>6} {rate:>9} {t.missed_frames:>6} "
                f"{t.out_of_tolerance_frames:>7}  "
                f"{pair(e['range_m']):>15}  {pair(e['radial_velocity_mps']):>15}  "
                f"{pair(e['az_deg']):>14}  {pair(e['el_deg']):>14}  {pair(e['rcs_dbsm']):>14}  "
                f"{t.verdict}")
        held = self.expectations
        if held:
            # A verdict says what it was held to, a pass as much as a fail.
            tol = held["tolerances"]
            # A quantity the mapping does not carry held nothing: said so in its place.
            unchecked = self.unchecked_quantities
            lines.append("held to: " + ", ".join(
                f"{name} not checked ({unchecked[key]['why']})"
                if key in unchecked and unchecked[key].get("target_cycles") is None
                else f"{name} {tol[key]:g} {unit}"
                + (f" (not checked {unchecked[key]['why']})" if key in unchecked else "")
                for key, name, unit in _HELD_TO if key in tol)
                + (f"; detection rate >= {held['detection_rate']:.1%} per target"
                   if self.targets else "")
                + f"; false detections <= {held['max_false_detections_per_frame']:g} per cycle")
        limited = [t for t in self.targets if t.limits]
        if limited or self.scene_limits:
            lines.append("limits (target-frames not played or not measurable as specified): "
                         + "; ".join(
                             [f"{name}{' (expected)' if hit['expected'] else ''}"
                              for name, hit in self.scene_limits.items()]
                             + [f"{t.name} " + ", ".join(
                                 f"{lim} {n}{'' if lim in t.unexpected_limits else ' (expected)'}"
                                 for lim, n in t.limits.items()) for t in limited]))
        if self.expected_not_hit:
            lines.append("expected limits not hit: " + "; ".join(self.expected_not_hit))
        f = self.frames
        lines.append(f"radar cycles: {f['total']} during the scene, {f['checked']} checked, "
                     f"{f.get('unmatched', 0)} with unmatched targets, "
                     f"{f['missing']} missing, {f['incomplete']} incomplete"
                     + "".join(f", {f[k]} {k}" for k in ("late", "repeated") if f.get(k))
                     + (f", {f['before_scene']} before the scene's start (not checked)"
                        if f.get("before_scene") else "")
                     + (f", {f['after_scene']} after the scene's end (not checked)"
                        if f.get("after_scene") else "")
                     + "; "
                     f"false detections: {self.false_detections} "
                     f"({self.false_detections_per_frame:.3f} per cycle)"
                     + (f"; invalid detections (not a number): {self.invalid_detections}"
                        if self.invalid_detections else "")
                     + (f"; folded detections (echoes beyond the radar's unambiguous range "
                        f"or velocity, not false): {self.folded_detections}"
                        if self.folded_detections else ""))
        if f.get("ambiguous"):
            window = self.playback.get("ambiguity_window_s")
            early = self.radar_clock.get("early_s")
            lines.append(f"frame changes: {f['ambiguous']} cycles measured within "
                         + (f"{window * 1e3:.3g} ms" if window is not None
                            else "the ambiguity window")
                         + " of a frame change"
                         + (f" ({early * 1e3:.3g} ms more after one: the interface's clock is "
                            f"tied to the host's within that)" if early else "")
                         + f", {f.get('adjacent_frame', 0)} of them judged "
                         f"against the frame across it (more targets detected)")
        lag = self.radar_clock.get("detection_lag_s")
        if lag is not None:
            error = self.radar_clock.get("detection_lag_error_s") or 0.0
            coupling = self.radar_clock.get("detection_lag_coupling_s") or 0.0
            lines.append(f"time alignment: the detections fit the scene {abs(lag) * 1e3:.1f} ms "
                         f"(+-{3e3 * error:.1f} ms) {'before' if lag > 0 else 'after'} the "
                         f"cycles' times"
                         + (f" (the radar's range-Doppler coupling: {abs(coupling) * 1e3:.1f} "
                            f"ms {'before' if coupling > 0 else 'after'})" if coupling else ""))
        untold = self.radar_clock.get("detection_lag_untold")
        if untold:
            lines.append(f"time alignment: not told ({untold})")
        for step in self.radar_clock.get("host_clock_steps") or []:
            lines.append(f"host clock: the wall clock stepped {step['size_s'] * 1e3:+.1f} ms "
                         f"at {step['at_s']:.3f} s after the scene's start (within "
                         f"{step['within_s'] * 1e3:.0f} ms before); corrected: "
                         f"{step['corrected']}")
        if self.playback:
            lines.append(_playback_line(self.playback))
        problems = {k: v for k, v in self.bus.items() if k != "messages" and v}
        if problems:
            lines.append("bus: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in
                                             problems.items()))
        if verdict:
            lines.append(self.verdict_line)
        return "\n".join(lines)


def _playback_line(p: dict[str, Any]) -> str:
    """One line on how the schedule went out and what the RTS says it applied."""
    late = p["lateness_s"]
    # No RTS took part where the run played to the built-in radar: said, not left to guess.
    simulated = p.get("output") == "simulated-radar"
    text = (f"playback: {p['frames_sent']} frames sent"
            + (" to the built-in simulated radar (no RTS)" if simulated else ""))
    if late.get("max") is not None and math.isfinite(late["max"]):
        text += (f", late by {late['p50'] * 1e3:.2f} ms median, {late['max'] * 1e3:.2f} ms "
                 f"worst ({p['late_frames']} later than a frame period)")
    rts = p.get("rts")
    if rts is None and not simulated:
        text += ("; the RTS reports no counters: frames lost on the way show only as radar "
                 "misses")
    elif rts is not None:
        text += "; RTS: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in rts.items()
                                      if v or k == "frames_applied")
    gone = p.get("rts_unreachable")
    if gone:
        text += (f"; {gone['datagrams']} datagrams came back undelivered from "
                 f"{gone['address']} ({gone['error']})")
    return text


# The tolerances as the `held to:` line names them.
_HELD_TO = (("range_m", "range", "m"), ("radial_velocity_mps", "radial velocity", "m/s"),
            ("az_deg", "az", "deg"), ("el_deg", "el", "deg"), ("rcs_db", "rcs", "dB"))


class FailReason(str):
    """Why a run fails: the sentence people read, and its ``codes``, names tools can match.

    A code is the name of what failed the run (docs/report.md, reason codes): a limit's
    (``too_close``, ``frames_lost``), or ``detection_rate``, ``radar_clock``, ... It is a
    `str`, so a report's ``reasons`` read, print and serialize as the sentences they are.
    """

    codes: tuple[str, ...]

    def __new__(cls, text: str, *codes: str) -> FailReason:
        """Make the reason ``text`` with its ``codes`` (at least one)."""
        reason = super().__new__(cls, text)
        reason.codes = codes
        return reason

    def __reduce__(self) -> tuple[Any, tuple[str, ...]]:
        return FailReason, (str(self), *self.codes)


# The code of a reason given as a plain sentence, without its codes.
UNCODED_REASON = "other"

# Codes that say the bench, not the radar, failed the run: the RTS did not play the schedule
# (another rig, another sender's stream, datagrams back undelivered, frames it did not apply,
# frames the host sent late), or the radar's messages were not seen (a silent bus, messages the
# mapping does not match or on other channels), or another radar's cycles came with them, or
# the mapping the bus is read with does not carry a quantity the scene means checked. A
# scene's ``xfail`` mark (a known failure of the radar's check) does not cover them: such a
# run fails (`bench_failures`).
BENCH_FAILURE_CODES = ("rts_rig", "rts_stream", "rts_unreachable", "frames_lost",
                       "frames_sent_late", "bus_silent", "mapping", "radar_channel",
                       "foreign_cycles", "quantity_unchecked", "crowded_in_analytic")


def bench_failures(codes: Iterable[str], playback: Mapping[str, Any] | None = None
                   ) -> list[str]:
    """Return those of a failed run's reason ``codes`` that are bench failures, in order.

    ``playback``: the run's (`Report.playback`). Datagrams that came back undelivered count
    whatever the scene expects: a scene that declares ``frames_lost`` (an RTS that drops some
    frames) drops the reason, but nothing listening is no RTS at all.
    """
    found = [code for code in codes if code in BENCH_FAILURE_CODES]
    if playback and playback.get("rts_unreachable") and "rts_unreachable" not in found:
        found.append("rts_unreachable")
    return found


def reason_codes(reasons: Iterable[str]) -> list[str]:
    """Return the codes of ``reasons`` (`FailReason`), each once, in the order they come."""
    codes = (code for reason in reasons
             for code in (getattr(reason, "codes", None) or (UNCODED_REASON,)))
    return list(dict.fromkeys(codes))


def _without_record(report: Report) -> Report:
    # asdict deep-copies every field; the record is a handle, not data.
    return replace(report, record=None)


def strict(value: Any) -> Any:
    """Non-finite floats become None (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict(v) for v in value]
    return value
