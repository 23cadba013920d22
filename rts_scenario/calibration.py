"""Phase and gain coherence of the RTS channels: pairwise sweeps, closed by least squares.

The paper calibrates two FEs at a time: with both on, it sweeps one channel's delay (that is,
its carrier phase) and keeps the setting where the superimposed target's angle error is
smallest. Here each pair plays a target with unequal weights (1 and ``weight_ratio``), so the
synthesized angle moves along the pair's line with the pair's phase difference; that shift is
an even function of the phase error around coherence, so the first harmonic of the sweep puts
coherence at its phase exactly (no search on a grid, robust to noise). Where the coherent pair
peaks then gives the gain ratio, by inverting the array model (detected levels, also recorded,
are too coarse on classic CAN).

Phase coherence is only measurable in pairs but needed between all channels at once: the
differences of all pairs (6 per quad) are solved together by least squares for one offset per
channel (the first FE is the reference). A pair whose residual stands out reveals a bad channel
or a moved FE.

Measurements run through `measure` - schedule in, one `Detections` per frame out - so the same
procedure drives the built-in simulated radar directly (`simulated_measure`) or any bench through
the pipeline (`rts_scenario.pipeline.Pipeline.play`: an output plus the radar's CAN bus).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from .detections import Detections
from .errors import RtsError
from .peak_search import find_peak, snapshot
from .radar.profile import RadarProfile
from .radar.simulate import ChannelErrors, SimulatedRadar
from .rig import Rig
from .schedule import Schedule
from .schedule.build import channel_delays

FloatArray = NDArray[np.float64]
Measure = Callable[[Schedule], list[Detections]]

# A pair whose phase residual exceeds this (deg), or gain residual this (dB), is suspect.
SUSPECT_PHASE_DEG = 3.0
SUSPECT_GAIN_DB = 0.3
# Frames per pair at its coherence point, averaged for the gain.
GAIN_REPEATS = 4


@dataclass(frozen=True)
class PairMeasurement:
    """One pair's measurement: FE ``a`` (strong) and ``b`` (weak, swept).

    ``phase_deg`` and ``gain_db`` are a minus b; ``level_db`` is the difference of the detected
    single-channel levels (coarse, for the record).
    """

    a: int
    b: int
    sweep_deg: FloatArray
    shift_deg: FloatArray
    phase_deg: float
    gain_db: float
    level_db: float
    swing_deg: float


@dataclass(frozen=True)
class CalibrationResult:
    """Per-channel offsets relative to the reference FE, and the evidence for them."""

    phase_deg: FloatArray
    gain_db: FloatArray
    pairs: tuple[PairMeasurement, ...]
    phase_residual_deg: FloatArray
    gain_residual_db: FloatArray

    @property
    def suspects(self) -> list[str]:
        """Pairs whose measurements do not fit the others (bad channel, moved FE)."""
        out = []
        for p, rp, rg in zip(self.pairs, self.phase_residual_deg, self.gain_residual_db,
                             strict=True):
            if abs(rp) > SUSPECT_PHASE_DEG or abs(rg) > SUSPECT_GAIN_DB:
                out.append(f"FE {p.a}-{p.b}: residual {rp:+.1f} deg, {rg:+.2f} dB")
        return out

    def apply(self, rig: Rig) -> Rig:
        """Return the rig with these offsets added to its calibration (phase and gain)."""
        return replace(rig, cal_phase_deg=_wrap(rig.cal_phase_deg - self.phase_deg),
                       cal_gain_db=rig.cal_gain_db + self.gain_db)


def _wrap(deg: FloatArray | float) -> FloatArray:
    return np.mod(np.asarray(deg) + 180.0, 360.0) - 180.0


def pairs_of(rig: Rig) -> list[tuple[int, int]]:
    """Every pair of FEs that share a quad (6 per quad)."""
    found = set()
    for quad in rig.quads:
        for a, b in combinations(sorted(quad.tolist()), 2):
            found.add((a, b))
    return sorted(found)


def calibrate(rig: Rig, radar: RadarProfile, measure: Measure, *, sweep_step_deg: float = 15.0,
              weight_ratio: float = 0.5, range_m: float = 10.0, attenuation_db: float = 40.0,
              progress: Callable[[int, int], None] | None = None) -> CalibrationResult:
    """Measure every pair and solve for per-channel phase and gain offsets.

    Parameters
    ----------
    rig : Rig
        The rig; its current calibration is the starting point.
    radar : RadarProfile
        The radar (wavelength and array for the expected angles).
    measure : callable
        Plays a schedule, returns one `Detections` per frame.
    sweep_step_deg : float
        Phase step of the sweep (a full turn is swept).
    weight_ratio : float
        Amplitude of the swept channel relative to the other (unequal weights make the angle
        depend on the phase).
    """
    pairs = pairs_of(rig)
    sweep = np.arange(0.0, 360.0, sweep_step_deg)
    # Round 1: each pair alone, then with the weak channel's phase swept.
    rows: list[list[tuple[int, float, float]]] = []
    for a, b in pairs:
        rows += [[(a, 1.0, 0.0)], [(b, 1.0, 0.0)]]
        rows += [[(a, 1.0, 0.0), (b, weight_ratio, s)] for s in sweep]
    batch = len(sweep) + 2
    dets = _measure_pairs(rig, radar, measure, rows, batch, range_m, attenuation_db, progress)
    fitted = [_fit_phase(rig, radar, a, b, sweep, weight_ratio, dets[i * batch : (i + 1) * batch])
              for i, (a, b) in enumerate(pairs)]
    # Round 2: each pair at its coherence point; where it peaks gives the gain ratio.
    rows = [[(a, 1.0, 0.0), (b, weight_ratio, f.phase_deg)] for (a, b), f in zip(pairs, fitted,
                                                                                strict=True)
            for _ in range(GAIN_REPEATS)]
    dets = _measure_pairs(rig, radar, measure, rows, GAIN_REPEATS, range_m, attenuation_db,
                          None)
    measured = [_fit_gain(rig, radar, f, weight_ratio,
                          dets[i * GAIN_REPEATS : (i + 1) * GAIN_REPEATS])
                for i, f in enumerate(fitted)]
    phase, phase_res = _close(rig.n_front_ends, measured, "phase_deg", circular=True)
    gain, gain_res = _close(rig.n_front_ends, measured, "gain_db", circular=False)
    return CalibrationResult(phase_deg=phase, gain_db=gain, pairs=tuple(measured),
                             phase_residual_deg=phase_res, gain_residual_db=gain_res)


def _measure_pairs(rig: Rig, radar: RadarProfile, measure: Measure,
                   rows: list[list[tuple[int, float, float]]], batch: int, range_m: float,
                   level_db: float, progress: Callable[[int, int], None] | None
                   ) -> list[Detections]:
    """Play the frames, one pair's batch at a time (like on the bench)."""
    schedule = pattern_schedule(rig, radar, rows, range_m, level_db)
    dets: list[Detections] = []
    total = len(rows) // batch
    for i in range(total):  # one pair at a time
        dets += measure(schedule.frames(i * batch, (i + 1) * batch))
        if progress is not None:
            progress(i + 1, total)
    return dets


def pattern_schedule(rig: Rig, radar: RadarProfile, rows: list[list[tuple[int, float, float]]],
                     range_m: float, level_db: float) -> Schedule:
    """Return a test pattern: one frame per row, the listed FEs of each row on.

    Each row item is ``(fe, weight, extra phase deg)``; the target is at ``range_m``,
    approaching at 1 m/s, with ``level_db`` of attenuation at weight 1 (plus each channel's
    calibration).
    """
    n = len(rows)
    fe = np.full((n, 1, 4), -1, dtype=np.int64)
    weight = np.zeros((n, 1, 4))
    extra = np.zeros((n, 1, 4))
    for f, row in enumerate(rows):  # building the test pattern, not a hot path
        for c, item in enumerate(row):
            fe[f, 0, c], weight[f, 0, c], extra[f, 0, c] = item
    active = fe >= 0
    fe0 = np.maximum(fe, 0)
    # Delays on the RTS's grid, their rounding given back in phase as the rig's delay model says.
    delay, phase = channel_delays(rig, radar, np.asarray(range_m, dtype=np.float64), fe0)
    doppler = np.full(fe.shape, 2.0 * 1.0 / radar.wavelength_m)  # approaching at 1 m/s
    with np.errstate(divide="ignore"):
        attenuation = level_db - 20.0 * np.log10(weight) + rig.cal_gain_db[fe0]
    phase = phase + np.radians(extra)
    nan = np.nan
    schedule = Schedule(
        t_s=np.arange(n, dtype=np.float64) * 0.05, frame_index=np.arange(n), names=("calibration",),
        quad=np.full((n, 1), -1), fe=np.where(active, fe, -1), weight=weight,
        attenuation_db=np.where(active, attenuation, nan), delay_s=np.where(active, delay, nan),
        doppler_hz=np.where(active, doppler, nan), phase_rad=np.where(active, phase, nan),
        active=active, status=np.zeros((n, 1), dtype=np.uint16),
        angle_error_deg=np.zeros((n, 1, 2)))
    return schedule


def _strongest(d: Detections, what: str, pair: tuple[int, int]) -> float:
    k = d.strongest()
    values = getattr(d, what)
    if k is None or values is None:
        raise RtsError(f"calibration: no detection with {what} for FE pair {pair[0]}-{pair[1]} "
                       f"in cycle {d.cycle}; check that the radar sees the rig")
    return float(values[k])


def _axis(rig: Rig, a: int, b: int) -> FloatArray:
    axis = np.array([rig.az_deg[b] - rig.az_deg[a], rig.el_deg[b] - rig.el_deg[a]])
    return axis / np.linalg.norm(axis)


def _shift(rig: Rig, a: int, b: int, dets: list[Detections]) -> FloatArray:
    """Project each frame's detection on the pair's axis (deg)."""
    axis = _axis(rig, a, b)
    az = np.array([_strongest(d, "az_deg", (a, b)) for d in dets])
    el = np.array([_strongest(d, "el_deg", (a, b)) for d in dets])
    return az * axis[0] + el * axis[1]


def _model_shift(rig: Rig, radar: RadarProfile, a: int, b: int, weight: float) -> float:
    """Where a coherent pair with weights (1, weight) peaks along its axis (nominal geometry)."""
    x = snapshot(radar.array, [[1.0, weight]], rig.az_deg[[a, b]], rig.el_deg[[a, b]])
    az_win = (min(rig.az_deg[[a, b]]) - 3.0, max(rig.az_deg[[a, b]]) + 3.0)
    el_win = (min(rig.el_deg[[a, b]]) - 3.0, max(rig.el_deg[[a, b]]) + 3.0)
    p_az, p_el = find_peak(radar.array, x, az_range_deg=az_win, el_range_deg=el_win,
                           grid_step_deg=0.1)
    axis = _axis(rig, a, b)
    return float(p_az[0] * axis[0] + p_el[0] * axis[1])


def _fit_phase(rig: Rig, radar: RadarProfile, a: int, b: int, sweep: FloatArray, ratio: float,
               dets: list[Detections]) -> PairMeasurement:
    """Phase difference (a - b): the first-harmonic phase of the sweep's shift."""
    level_a = _strongest(dets[0], "rcs_dbsm", (a, b))
    level_b = _strongest(dets[1], "rcs_dbsm", (a, b))
    shift = _shift(rig, a, b, dets[2:]) - _model_shift(rig, radar, a, b, ratio)
    # The shift towards the weak FE is largest when coherent and even around that point.
    theta = np.radians(sweep)
    design = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta)])
    _, p1, p2 = np.linalg.lstsq(design, shift, rcond=None)[0]
    # Applying phase s to b is coherent when s = phi_a - phi_b.
    return PairMeasurement(a=a, b=b, sweep_deg=sweep, shift_deg=shift,
                           phase_deg=float(_wrap(np.degrees(np.arctan2(p2, p1)))),
                           gain_db=float("nan"), level_db=level_a - level_b,
                           swing_deg=float(np.hypot(p1, p2)))


def _fit_gain(rig: Rig, radar: RadarProfile, pair: PairMeasurement, ratio: float,
              dets: list[Detections]) -> PairMeasurement:
    """Gain difference (a - b): b's strength that puts the coherent peak where it was seen.

    Secant steps on the array model (the detected levels are too coarse on classic CAN).
    """
    a, b = pair.a, pair.b
    seen = float(np.mean(_shift(rig, a, b, dets)))

    def miss(gain_b_db: float) -> float:
        return _model_shift(rig, radar, a, b, ratio * 10.0 ** (gain_b_db / 20.0)) - seen

    x0, x1 = 0.0, 0.5
    f0, f1 = miss(x0), miss(x1)
    for _ in range(10):  # secant steps: a handful converge
        if abs(f1) < 1e-7 or f1 == f0:
            break
        x0, x1 = x1, x1 - f1 * (x1 - x0) / (f1 - f0)
        f0, f1 = f1, miss(x1)
    return replace(pair, gain_db=-x1)


def _close(n_fe: int, pairs: list[PairMeasurement], field: str,
           circular: bool) -> tuple[FloatArray, FloatArray]:
    """Least squares for per-channel values v with v_a - v_b = pair value (v_0 = 0)."""
    design = np.zeros((len(pairs), n_fe))
    values = np.array([getattr(p, field) for p in pairs])
    for i, p in enumerate(pairs):
        design[i, p.a], design[i, p.b] = 1.0, -1.0
    design = design[:, 1:]  # the first FE is the reference
    if circular:
        # Unwrap each pair against a first solution grown along a spanning tree from the
        # reference (a least-squares fit of wrapped values can land a quarter turn off).
        first = np.full(n_fe, np.nan)
        first[0] = 0.0
        for _ in range(n_fe):  # grow the tree one layer at a time
            for p, v in zip(pairs, values, strict=True):
                if np.isnan(first[p.b]) and not np.isnan(first[p.a]):
                    first[p.b] = first[p.a] - v
                elif np.isnan(first[p.a]) and not np.isnan(first[p.b]):
                    first[p.a] = first[p.b] + v
        if np.isnan(first).any():
            raise RtsError("calibration: the measured pairs do not connect every channel")
        predicted = design @ first[1:]
        values = predicted + _wrap(values - predicted)
    solution = np.linalg.lstsq(design, values, rcond=None)[0]
    residual = values - design @ solution
    if circular:
        residual = _wrap(residual)
    return np.concatenate([[0.0], solution]), residual


def simulated_measure(radar: RadarProfile, rig: Rig, errors: ChannelErrors, *,
                      fidelity: str = "analytic", noise: bool = False,
                      rng: np.random.Generator | None = None,
                      estimator: str = "bartlett") -> Measure:
    """Play schedules on the simulated radar with injected channel errors (a `measure`)."""
    sim = SimulatedRadar(radar, rig, fidelity=fidelity, noise=noise, errors=errors,
                         rng=rng or np.random.default_rng(0), estimator=estimator)
    return sim.process


def grid_errors(rig: Rig, radar: RadarProfile, measure: Measure,
                method: str = "exact", estimator: str = "bartlett") -> FloatArray:
    """Measure detected minus set angle (deg, (G, 2)) over a grid inside the rig's quads.

    The grid is the paper's (azimuth -3..3 deg x elevation -6..6 deg) for kit-table1, and a
    6 x 5 grid over the middle of every quad otherwise.
    """
    from .evaluation import evaluation_grid
    from .kinematics import Tracks
    from .schedule import build_schedule

    if rig.name == "kit-table1":
        az, el = evaluation_grid()
    else:
        a, b = (g.ravel() for g in np.meshgrid(np.linspace(0.2, 0.8, 6), np.linspace(0.2, 0.8, 5)))
        corners = rig.quads[:, [0, 1, 3, 2]]
        p0, p1, p3, p2 = (np.stack([rig.az_deg[corners[:, i]], rig.el_deg[corners[:, i]]], -1)
                          for i in range(4))
        pts = (((1 - a) * (1 - b))[:, None, None] * p0 + (a * (1 - b))[:, None, None] * p1
               + (a * b)[:, None, None] * p3 + ((1 - a) * b)[:, None, None] * p2)
        az, el = pts[..., 0].ravel(), pts[..., 1].ravel()
    n = az.size
    one = np.ones((n, 1), dtype=bool)
    tracks = Tracks(names=("grid",), t_s=np.arange(n, dtype=np.float64) * 0.05,
                    range_m=np.full((n, 1), 10.0),
                    radial_velocity_mps=np.full((n, 1), -1.0),
                    doppler_hz=np.full((n, 1), 2.0 / radar.wavelength_m),
                    rcs_dbsm=np.full((n, 1), 10.0), az_deg=az[:, None], el_deg=el[:, None],
                    position_m=np.zeros((n, 1, 3)), present=one, in_coverage=one, in_range=one,
                    in_velocity=one)
    schedule = build_schedule(tracks, rig, radar, method=method, estimator=estimator)
    dets = measure(schedule)
    out = np.full((n, 2), np.nan)
    for i, d in enumerate(dets):  # one target per frame
        k = d.strongest()
        if k is not None and d.az_deg is not None and d.el_deg is not None:
            out[i] = d.az_deg[k] - az[i], d.el_deg[k] - el[i]
    return out
