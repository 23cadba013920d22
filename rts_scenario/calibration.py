"""Phase and gain coherence of the RTS channels for any radar: fitted delay sweeps, closed.

Pairwise delay sweeps, each fitted with the radar's own array and estimator, closed by least
squares over all pairs.

The paper calibrates two FEs at a time: with both on, it sweeps one channel's *delay* and
watches the angle of the superimposed target. Here a first measurement plays each FE alone and
reads its level at the radar (the RCS it reports). Then each pair plays a target whose swept
channel arrives at ``weight_ratio`` of the other's amplitude, its weight set from those levels
(on the attenuator's steps, within its range), while its delay steps over one turn of the phase
the RTS gives a delay: ``2 pi f_if tau`` for a digital RTS that delays at an intermediate
frequency, ``2 pi f_c tau`` for an RF delay line (the rig's ``rts.delay_model``), on the RTS's
delay grid. Unequal echoes make the angle follow the phase; echoes of equal strength would
cancel at one phase, where the angle tells little (a channel about 6 dB stronger than its
weight says at a fixed 0.5 does that).

Each sweep is fitted with a model of what the radar reports, which assumes neither a symmetric
array nor a Bartlett radar:

- the two FEs' response vectors on the radar's virtual array, modeled from the bench's geometry
  (physical antennas, FE distances and antenna offsets, near field: `rts_scenario.responses`,
  the vectors the exact method solves with);
- the swept echo's phase from the delay model, and its amplitude through the radar's range
  window (Hann) at the range offset the delay makes (a turn at 500 MHz is 2 ns, 0.3 m), read at
  the range cell the radar reports;
- the radar's own angle estimator (`bartlett`, `ti` or one registered in the estimator registry).

The fit's two unknowns per pair are the channels' phase and gain difference; it takes the
weights as played (the attenuators' settings), the single levels only as its starting point.
Calibration results are channel phase and gain offsets, applied by the RTS per channel (the
schedule's ``phase_rad`` and attenuation), so calibrated channels keep their ranges.

Phase coherence is only measurable in pairs but needed between all channels at once: the
differences of all pairs (6 per quad) are solved together by least squares for one offset per
channel (the first FE is the reference). A pair whose closure residual stands out, or whose sweep
the model does not fit, reveals a bad channel or a moved FE.

Every measurement reads each cycle at its strongest detection within the pattern's gate
(`rts_scenario.gate`: about the range its delay gives and the radial velocity its Doppler
gives), never at a stronger reflection in the room; an FE alone or a pair with detections but
none in the gate is a measurement that failed, named with the strongest detection outside it.

Measurements run through `measure` - schedule in, one `Detections` per frame out - so the same
procedure drives the built-in simulated radar directly (`simulated_measure`) or any bench through
the pipeline (`rts_scenario.pipeline.Pipeline.play`: an output plus the radar's CAN bus).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from .detections import Detections
from .errors import MeasurementError, RtsError
from .gate import Gate, echo_delays_s
from .propagation import C0_MPS
from .radar.angle import make_estimator
from .radar.profile import RadarProfile
from .radar.simulate import ChannelErrors, SimulatedRadar
from .rig import Rig
from .schedule import Schedule
from .schedule.build import DELAY_SLACK_S, channel_delays, solver_inputs

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
Measure = Callable[[Schedule], list[Detections]]
# One frame of a test pattern: (fe, weight, extra phase deg[, extra delay s]) per channel.
Row = Sequence[tuple[float, ...]]

# A pair whose closure residual exceeds this (deg), or gain residual this (dB), or whose sweep
# the model misses by more than this rms (deg), is suspect.
SUSPECT_PHASE_DEG = 3.0
SUSPECT_GAIN_DB = 0.3
SUSPECT_FIT_DEG = 0.05
# After calibration, the check grid may be seen at most this far (deg) off the angle the schedule
# predicts (its attenuator, phase shifter and delay steps). A calibrated simulated bench stays
# below 0.01 deg (0.005 deg steps on classic CAN); one channel left 0.3 dB off costs 0.08-0.13
# deg on the shipped rigs, 10 deg of phase 0.13-0.24 deg on the awr1843boost.
MAX_EXCESS_ERROR_DEG = 0.1


@dataclass(frozen=True)
class PairMeasurement:
    """One pair's measurement: FE ``a`` (the reference) and ``b`` (its delay swept).

    ``delay_s`` are the delays added to b, ``sweep_deg`` the phases they give b's echo (the
    rig's delay model); ``az_deg``/``el_deg`` what the radar reported, ``shift_deg`` its
    projection on the pair's axis and ``model_shift_deg`` the fitted model's.
    ``phase_deg`` and ``gain_db`` are a minus b; ``level_db`` is the difference of the
    single-channel levels (a minus b, the radar's RCS: coarse); ``weight_db`` b's weight over
    a's as the attenuators played it (their calibration gains taken out), set so that b
    arrives at ``weight_ratio`` of a; ``fit_rms_deg`` how well the model fits.
    """

    a: int
    b: int
    delay_s: FloatArray
    sweep_deg: FloatArray
    az_deg: FloatArray
    el_deg: FloatArray
    shift_deg: FloatArray
    model_shift_deg: FloatArray
    phase_deg: float
    gain_db: float
    level_db: float
    weight_db: float
    fit_rms_deg: float


@dataclass(frozen=True)
class CalibrationResult:
    """Per-channel offsets relative to the reference FE, and the evidence for them.

    ``single_rcs_dbsm`` (F,) is each FE's level played alone, the RCS the radar reported (NaN
    for an FE in no pair): what each pair's weights were set from. ``remeasured`` names the
    measurements played a second time (``"FEs alone"``, ``"FE pair 0-2"``): some of their
    cycles did not come back the first time.
    """

    phase_deg: FloatArray
    gain_db: FloatArray
    pairs: tuple[PairMeasurement, ...]
    phase_residual_deg: FloatArray
    gain_residual_db: FloatArray
    single_rcs_dbsm: FloatArray
    remeasured: tuple[str, ...] = ()

    @property
    def suspects(self) -> list[str]:
        """Pairs whose measurements do not fit the others or the model (bad channel, moved FE)."""
        out = []
        for p, rp, rg in zip(self.pairs, self.phase_residual_deg, self.gain_residual_db,
                             strict=True):
            if (abs(rp) > SUSPECT_PHASE_DEG or abs(rg) > SUSPECT_GAIN_DB
                    or not p.fit_rms_deg <= SUSPECT_FIT_DEG):
                out.append(f"FE {p.a}-{p.b}: residual {rp:+.1f} deg, {rg:+.2f} dB, sweep "
                           f"fit {p.fit_rms_deg:.3f} deg rms")
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


def delayed_frequency_hz(rig: Rig, radar: RadarProfile, range_m: float) -> float:
    """Frequency at which an extra RTS delay turns an echo at ``range_m`` (Hz).

    The rig's delay model (IF or carrier), read where the radar reads the phase: at the centre
    of its sampled sweep, less the sweep over the echo's lateness (as `channel_delays`).
    """
    return (rig.rts.delayed_frequency_hz(radar.fc_hz) + radar.sampled_centre_frequency_hz
            - radar.fc_hz - radar.slope_hz_per_s * 2.0 * range_m / C0_MPS)


def sweep_delays(rig: Rig, radar: RadarProfile, steps: int,
                 range_m: float) -> tuple[FloatArray, FloatArray]:
    """Delays to add to a channel for a sweep over one phase turn, and their phases (deg).

    The wanted phases are ``steps`` equal steps of a turn; each delay is the shortest one on the
    RTS's delay grid (the least range offset) whose phase is within half a step of the wanted
    one, else the one whose phase comes nearest. A grid coarser than a phase step repeats
    phases; the fit uses the phases obtained.
    """
    f_hz = delayed_frequency_hz(rig, radar, range_m)
    turn_s = 1.0 / f_hz
    wanted = (np.arange(steps) / steps - 0.5) * turn_s
    step = rig.limits.delay_step_s
    if step > 0.0:
        reach = int(np.ceil(max(turn_s, step) / step)) * 2
        grid = np.arange(-reach, reach + 1) * step
        grid_turns = np.mod(-grid * f_hz + 0.5, 1.0) - 0.5
        want_turns = -wanted * f_hz
        miss = np.abs(np.mod(grid_turns[None, :] - want_turns[:, None] + 0.5, 1.0) - 0.5)
        # The shortest delay within half a phase step of the wanted phase, else the nearest.
        score = (np.where(miss <= 0.5 / steps, 0.0, miss * 1e6)
                 + np.abs(grid)[None, :] / (np.abs(grid).max() + step))
        wanted = grid[np.argmin(score, axis=1)]
    phase = -360.0 * f_hz * wanted
    return wanted, _wrap(phase)


def calibrate(rig: Rig, radar: RadarProfile, measure: Measure, *, estimator: str = "bartlett",
              steps: int = 24, weight_ratio: float = 0.5, range_m: float = 10.0,
              attenuation_db: float = 40.0,
              progress: Callable[[int, int], None] | None = None) -> CalibrationResult:
    """Measure each FE alone, then every pair with a delay sweep; solve for per-channel offsets.

    The first measurement plays each FE alone at weight 1 (``attenuation_db``) and reads its
    level, the RCS the radar reports. Each pair's measurement (one per pair, as on the bench)
    then plays the swept channel at the weight that makes it arrive at ``weight_ratio`` of the
    other's amplitude given those levels, the stronger channel at weight 1 (both stronger
    where the other's attenuation would pass the attenuator's maximum; on coarse steps, the
    steps nearest the wanted contrast); a pair the attenuator cannot play at least half that
    many dB apart is refused. The fit takes the weights as the attenuators played them. A
    measurement some of whose cycles did not come back (a frame the host sent after the cycle
    measuring it, a cycle lost) is played once more; the second one is taken. Each cycle is
    read at its strongest detection in the pattern's gate (`rts_scenario.gate.Gate`), never at
    a reflection in the room.

    Parameters
    ----------
    rig : Rig
        The rig; its current calibration is the starting point.
    radar : RadarProfile
        The radar: its antennas, chirp and array for the model of what it reports.
    measure : callable
        Plays a schedule, returns one `Detections` per frame.
    estimator : str
        The radar's angle estimator (a name in the estimator registry).
    steps : int
        Delay steps per sweep (over one phase turn).
    weight_ratio : float
        Amplitude at which the swept channel arrives at the radar relative to the other
        (unequal echoes make the angle depend on the phase).
    range_m : float
        The pattern's target range (m).
    attenuation_db : float
        The pattern's attenuation at weight 1 (plus each channel's calibration gain).
    progress : callable, optional
        Called with (pairs measured, pairs) after each pair's measurement.

    Raises
    ------
    MeasurementError
        An FE alone, or a pair, came back without a detection in its gate or without its
        cycle.
    RtsError
        A pair the attenuator's range and steps cannot play far enough from equal echoes.
    """
    if steps < 8:
        raise RtsError(f"calibration: steps must be >= 8, got {steps}")
    if not 0.0 < weight_ratio < 1.0:
        raise RtsError(f"calibration: weight_ratio must be within 0 and 1 (exclusive), got "
                       f"{weight_ratio}")
    pairs = pairs_of(rig)
    fes = sorted({q for pair in pairs for q in pair})
    singles = pattern_schedule(rig, radar, [[(q, 1.0, 0.0)] for q in fes], range_m,
                               attenuation_db)
    remeasured: list[str] = []
    level = _single_levels(rig, fes, Gate.of(rig, radar, singles),
                           _measured(measure, singles, "FEs alone", remeasured))
    delays, sweep_deg = sweep_delays(rig, radar, steps, range_m)
    rows: list[Row] = []
    for a, b in pairs:
        w_a, w_b = _pair_weights(rig, a, b, level, weight_ratio, attenuation_db)
        rows += [[(a, w_a, 0.0, 0.0), (b, w_b, 0.0, float(d))] for d in delays]
    schedule = pattern_schedule(rig, radar, rows, range_m, attenuation_db)
    dets: list[list[Detections]] = []
    for i in range(len(pairs)):  # one pair at a time, like on the bench
        a, b = pairs[i]
        dets.append(_measured(measure, schedule.frames(i * steps, (i + 1) * steps),
                              f"FE pair {a}-{b}", remeasured))
        # A pair that failed twice fails the calibration now, not after the pairs after it.
        _require_cycles((a, b), dets[-1])
        if progress is not None:
            progress(i + 1, len(pairs))
    model = _PairModel(rig, radar, estimator, range_m, attenuation_db)
    measured = [model.fit(a, b, delays, sweep_deg, schedule.frames(i * steps, (i + 1) * steps),
                          dets[i], (float(level[a]), float(level[b])))
                for i, (a, b) in enumerate(pairs)]
    phase, phase_res = _close(rig.n_front_ends, measured, "phase_deg", circular=True)
    gain, gain_res = _close(rig.n_front_ends, measured, "gain_db", circular=False)
    return CalibrationResult(phase_deg=phase, gain_db=gain, pairs=tuple(measured),
                             phase_residual_deg=phase_res, gain_residual_db=gain_res,
                             single_rcs_dbsm=level, remeasured=tuple(remeasured))


# Why a frame's cycle is missing after `_measured` played its measurement a second time.
_TWICE = ("measured twice: the radar's cycle measuring it did not come back either time "
          "(lost, later than the measurement waited for, or not told from the frame before's: "
          "a frame the host sent after that cycle); check the host's load and the bus")


def _measured(measure: Measure, schedule: Schedule, what: str,
              remeasured: list[str]) -> list[Detections]:
    """Play ``schedule``; once more where some of its cycles did not come back.

    A bench has hiccups: a loaded host sends a frame after the radar's cycle measuring it, a
    cycle is lost on the bus. The second measurement is taken whole (its cycles are never
    mixed with the first's); where it misses cycles too, the fit says which. Where none came
    back the radar does not report at all: measuring again would not help.
    """
    cycles = measure(schedule)
    back = [d.complete for d in cycles]
    if any(back) and not all(back):
        remeasured.append(what)
        cycles = measure(schedule)
    return cycles


def _single_levels(rig: Rig, fes: list[int], gate: Gate,
                   cycles: list[Detections]) -> FloatArray:
    """Each FE's level played alone (its strongest detection's RCS in ``gate``), else NaN.

    Every FE must be measured: its level sets its pairs' weights, and a guessed level could
    play a pair through cancellation. A detection outside the gate is not the FE's (a
    reflection in the room): an FE with only such detections is named with the strongest.
    """
    if len(cycles) != len(fes):
        raise RtsError(f"calibration: {len(cycles)} cycles reported for the {len(fes)} FEs "
                       f"played alone; the radar must report every frame")
    level = np.full(rig.n_front_ends, np.nan)
    # Not one cycle came back: the radar does not see the rig, or reports elsewhere.
    none_back = not any(d.complete for d in cycles)
    misses: list[str] = []
    unseen: list[int] = []
    for i, (q, d) in enumerate(zip(fes, cycles, strict=True)):
        if not d.complete and not none_back:
            # No cycle for the frame: lost on the bus, later than the measurement waited for,
            # or not told from the frame before's (docs/bench.md section 6).
            raise MeasurementError(f"no cycle for FE {q} played alone (frame {d.cycle}), "
                                   f"{_TWICE}")
        k = gate.strongest(d, i)
        if k is not None and d.rcs_dbsm is not None and np.isfinite(d.rcs_dbsm[k]):
            level[q] = d.rcs_dbsm[k]
            continue
        miss = gate.miss(f"FE {q} played alone", d, i)
        if miss is None:
            unseen.append(i)
        else:
            misses.append(miss)
    if unseen:
        names = ", ".join(str(fes[i]) for i in unseen)
        where = ", ".join(str(cycles[i].cycle) for i in unseen)
        what = "the rig" if len(unseen) == len(fes) else f"FE {names}"
        misses.append(f"no detection with rcs_dbsm of FE {names} played alone "
                      f"(cycle{'s' if len(unseen) > 1 else ''} {where}): its level at the "
                      f"radar sets the weights of its pairs; check that the radar sees {what}")
    if misses:
        raise MeasurementError("; ".join(misses))
    return level


def _pair_weights(rig: Rig, a: int, b: int, level_db: FloatArray, ratio: float,
                  attenuation_db: float) -> tuple[float, float]:
    """Weights of a and b that make b arrive at ``ratio`` of a, given their single levels.

    The stronger weight is 1 (the level the single channels were measured at); where the
    other's attenuation would pass the attenuator's maximum, both are played that much
    stronger. On an attenuator with steps, of the settings about the wanted ones the pair
    whose echoes' sum swings closest to the wanted depth over the sweep is played (the nearest
    steps may put the echoes at equal strength). A pair the attenuator cannot play at least
    half the wanted dB apart is refused: its sweep would pass near cancellation.
    """
    lim = rig.limits
    want_db = 20.0 * np.log10(ratio)  # b's echo over a's at the radar
    weight_db = want_db + level_db[a] - level_db[b]  # b's weight over a's
    nominal = attenuation_db + rig.cal_gain_db[[a, b]]  # each channel's attenuation at weight 1
    att = nominal - np.array([min(0.0, -weight_db), min(0.0, weight_db)])
    att -= max(0.0, float(att.max()) - lim.attenuation_max_db)
    att = np.clip(att, lim.attenuation_min_db, lim.attenuation_max_db)
    step = lim.attenuation_step_db
    if step > 0.0:
        top = np.floor((lim.attenuation_max_db - lim.attenuation_min_db) / step + 1e-9)
        k = (att - lim.attenuation_min_db) / step
        ks = [np.clip(np.array([np.floor(k[i] + 1e-9), np.ceil(k[i] - 1e-9)]), 0.0, top)
              for i in range(2)]
        grid_a, grid_b = (g.ravel() for g in np.meshgrid(*ks))
        options = lim.attenuation_min_db + np.stack([grid_a, grid_b], axis=-1) * step
    else:
        options = att[None, :]
    # b's echo over a's at the radar for each option, and how deep the sum of the two swings
    # over the sweep (0: cancellation; the wanted ratio's depth is the aim).
    arrives_db = (level_db[b] - (options[:, 1] - nominal[1])
                  - (level_db[a] - (options[:, 0] - nominal[0])))
    depth = np.abs(np.tanh(arrives_db * np.log(10.0) / 40.0))
    best = int(np.argmin(np.abs(depth - abs(np.tanh(want_db * np.log(10.0) / 40.0)))))
    if abs(arrives_db[best]) < abs(want_db) / 2.0:
        raise RtsError(
            f"rig {rig.name!r}: FE pair {a}-{b} cannot be played with FE {b}'s echo at least "
            f"{abs(want_db) / 2.0:.1f} dB from FE {a}'s at the radar (it wants {want_db:+.1f} "
            f"dB; their levels alone {level_db[a]:.2f} and {level_db[b]:.2f} dBsm; the "
            f"attenuator's limits.attenuation_min_db = {lim.attenuation_min_db:g}, "
            f"limits.attenuation_max_db = {lim.attenuation_max_db:g}, "
            f"limits.attenuation_step_db = {step:g} allow {arrives_db[best]:+.1f} dB at best): "
            f"its sweep would pass near cancellation, where the angle tells little")
    w_a, w_b = 10.0 ** ((nominal - options[best]) / 20.0)
    return float(w_a), float(w_b)


def pattern_schedule(rig: Rig, radar: RadarProfile, rows: Sequence[Row], range_m: float,
                     level_db: float) -> Schedule:
    """Return a test pattern: one frame per row, the listed FEs of each row on.

    Each row item is ``(fe, weight, extra phase deg)`` or ``(fe, weight, extra phase deg,
    extra delay s)``; the target is at ``range_m``, approaching at 1 m/s, with ``level_db`` of
    attenuation at weight 1 (plus each channel's calibration), on the attenuator's steps; each
    channel's phase (its calibration, the delay rounding's compensation and the extra phase)
    on the phase shifter's steps. An extra delay is added to the channel's delay as it is (on
    the RTS's grid if it is on it), its phase not given back.
    """
    n = len(rows)
    fe = np.full((n, 1, 4), -1, dtype=np.int64)
    weight = np.zeros((n, 1, 4))
    extra = np.zeros((n, 1, 4))
    extra_delay = np.zeros((n, 1, 4))
    for f, row in enumerate(rows):  # building the test pattern, not a hot path
        for c, item in enumerate(row):
            fe[f, 0, c], weight[f, 0, c], extra[f, 0, c] = item[:3]
            if len(item) > 3:
                extra_delay[f, 0, c] = item[3]
    active = fe >= 0
    fe0 = np.maximum(fe, 0)
    # Delays on the RTS's grid, their rounding given back in phase as the rig's delay model says.
    delay, phase = channel_delays(rig, radar, np.asarray(range_m, dtype=np.float64), fe0)
    delay = delay + extra_delay
    doppler = np.full(fe.shape, 2.0 * 1.0 / radar.wavelength_m)  # approaching at 1 m/s
    with np.errstate(divide="ignore"):
        attenuation = level_db - 20.0 * np.log10(weight) + rig.cal_gain_db[fe0]
    phase = phase + np.radians(extra)
    _check_pattern_limits(rig, fe, active, attenuation, delay, doppler, range_m)
    # On the attenuator's and phase shifter's steps, as the RTS will set them (the fit takes
    # the rounding back).
    attenuation = rig.limits.attenuator_setting(attenuation)
    phase = rig.limits.phase_setting(phase)
    nan = np.nan
    schedule = Schedule(
        t_s=np.arange(n, dtype=np.float64) * 0.05, frame_index=np.arange(n), names=("calibration",),
        quad=np.full((n, 1), -1), fe=np.where(active, fe, -1), weight=weight,
        attenuation_db=np.where(active, attenuation, nan), delay_s=np.where(active, delay, nan),
        doppler_hz=np.where(active, doppler, nan), phase_rad=np.where(active, phase, nan),
        active=active, status=np.zeros((n, 1), dtype=np.uint16),
        angle_error_deg=np.zeros((n, 1, 2)))
    return schedule


# Settings this close to a limit are within it (rounding of the delay grid, as a scene's
# schedule takes it, and of dB sums).
_LIMIT_SLACK = {"delay": DELAY_SLACK_S, "attenuation": 1e-9, "doppler": 1e-9}


def _check_pattern_limits(rig: Rig, fe: NDArray[np.int64], active: NDArray[np.bool_],
                          attenuation: NDArray[np.float64], delay: NDArray[np.float64],
                          doppler: NDArray[np.float64], range_m: float) -> None:
    """Refuse a test pattern with a setting beyond the rig's limits (`HardwareLimits`).

    The RTS cannot play it as sent (a scene's schedule flags such entries; a test pattern has
    no verdict to fail), and what the radar measured of it would pass for a measurement.
    """
    lim = rig.limits
    far = () if lim.delay_max_s is None else (
        ("delay", delay, "s", "delay_max_s", lim.delay_max_s, 1.0,
         f" (a target at {range_m:g} m, less the FE's distance and limits.latency_s)"),)
    checks = (
        ("delay", delay, "s", "delay_min_s", lim.delay_min_s, -1.0,
         f" (a target at {range_m:g} m, less the FE's distance and limits.latency_s)"),
        *far,
        ("attenuation", attenuation, "dB", "attenuation_min_db", lim.attenuation_min_db, -1.0,
         " (the level plus the channel's calibration gain_db)"),
        ("attenuation", attenuation, "dB", "attenuation_max_db", lim.attenuation_max_db, 1.0,
         " (the level plus the channel's calibration gain_db)"),
        ("doppler", doppler, "Hz", "doppler_min_hz", lim.doppler_min_hz, -1.0,
         " (the pattern's target approaches at 1 m/s)"),
        ("doppler", doppler, "Hz", "doppler_max_hz", lim.doppler_max_hz, 1.0,
         " (the pattern's target approaches at 1 m/s)"),
    )
    for what, values, unit, key, limit, side, why in checks:
        beyond = active & (side * (values - limit) > _LIMIT_SLACK[what])
        if beyond.any():
            f, k, c = (int(i) for i in np.argwhere(beyond)[0])
            word = "below" if side < 0 else "above"
            raise RtsError(f"rig {rig.name!r}: the test pattern needs {what} "
                           f"{values[f, k, c]:.6g} {unit} on FE {int(fe[f, k, c])}, {word} "
                           f"limits.{key} = {limit:g} {unit}{why}: the RTS cannot play it")


def _require_cycles(pair: tuple[int, int], sweep: list[Detections]) -> None:
    """Raise `MeasurementError` unless every frame of a pair's measurement has its cycle."""
    if not any(d.complete for d in sweep):
        # Not one cycle came back: the radar does not see the rig, or reports elsewhere.
        raise MeasurementError(f"no detection for FE pair {pair[0]}-{pair[1]} in cycle "
                               f"{sweep[0].cycle}; check that the radar sees the rig")
    for d in sweep:
        if not d.complete:
            # No cycle for the frame: lost on the bus, later than the measurement waited for,
            # or not told from the frame before's (docs/bench.md section 6). The radar may
            # well see the rig: say what is missing.
            raise MeasurementError(f"no cycle for FE pair {pair[0]}-{pair[1]}'s frame "
                                   f"{d.cycle}, {_TWICE}")


def _pair_readings(gate: Gate, sweep: list[Detections], pair: tuple[int, int],
                   quantities: Sequence[str], levels: str) -> list[FloatArray]:
    """Each quantity of the strongest detection in ``gate`` of every cycle of a pair's sweep.

    Every cycle came back (`_require_cycles`); one without a detection in the gate is a
    measurement that failed, named with the strongest detection outside it where there is one
    (a reflection in the room), else with ``levels``: the FEs' levels alone and as the pair
    played them (its sum dips below the radar's threshold where the FEs alone were near it).
    """
    name = f"FE pair {pair[0]}-{pair[1]}"
    out = np.full((len(quantities), len(sweep)), np.nan)
    for i, d in enumerate(sweep):
        k = gate.strongest(d, i)
        if k is None:
            raise MeasurementError(gate.miss(name, d, i)
                                   or f"no detection for {name} in cycle {d.cycle}: {levels}")
        for j, what in enumerate(quantities):
            values = getattr(d, what)
            if values is None:
                # The radar does not see the rig, or reports elsewhere.
                raise MeasurementError(f"no detection with {what} for {name} in cycle "
                                       f"{d.cycle}; check that the radar sees the rig")
            out[j, i] = values[k]
    return list(out)


class _PairModel:
    """What the radar reports for a pair (b at a weight relative to a), given a - b."""

    def __init__(self, rig: Rig, radar: RadarProfile, estimator: str, range_m: float,
                 attenuation_db: float) -> None:
        array, fe_model = solver_inputs(radar, "modeled")
        assert fe_model is not None
        self.rig, self.radar, self.range_m = rig, radar, range_m
        self.attenuation_db = attenuation_db
        self.vectors = fe_model.vectors(rig, np.arange(rig.n_front_ends), array)  # (M, F)
        self.estimate = make_estimator(estimator, array)
        self.n = radar.adc_samples

    def _echo_bins(self, schedule: Schedule) -> FloatArray:
        """Fractional range bin of each channel's echo (frames, 4), from its total delay."""
        return self.radar.range_bin(echo_delays_s(self.rig, schedule)[:, 0, :],
                                    schedule.doppler_hz[:, 0, :])

    def predict(self, a: int, b: int, theta_deg: FloatArray, level: FloatArray,
                phase_deg: FloatArray, gain_db: FloatArray, weight_db: float,
                steps_deg: float = 0.0) -> tuple[FloatArray, FloatArray]:
        """Return the reported (az, el) for candidates ``phase_deg``/``gain_db`` (P,): (P, S).

        ``level`` (S, 2) is each echo's amplitude through the range window at the cell read;
        ``weight_db`` b's weight over a's as played (the attenuators' settings less the
        channels' calibration gains), ``steps_deg`` how much more b's phase than a's the phase
        shifter's steps turned.
        """
        rel = (10.0 ** ((weight_db - np.asarray(gain_db)[:, None]) / 20.0)
               * np.exp(1j * np.radians(theta_deg[None, :] + steps_deg
                                        - np.asarray(phase_deg)[:, None])))
        x = (level[None, :, 0, None] * self.vectors[:, a][None, None, :]
             + (rel * level[None, :, 1])[..., None] * self.vectors[:, b][None, None, :])
        shape = x.shape[:2]
        est = self.estimate(x.reshape(-1, x.shape[-1]))
        first = np.unique(est.source, return_index=True)[1]
        az = np.full(shape[0] * shape[1], np.nan)
        el = np.full(shape[0] * shape[1], np.nan)
        az[est.source[first]] = est.az_deg[first]
        el[est.source[first]] = est.el_deg[first]
        return az.reshape(shape), el.reshape(shape)

    def fit(self, a: int, b: int, delays: FloatArray, sweep_deg: FloatArray,
            schedule: Schedule, sweep: list[Detections],
            alone_dbsm: tuple[float, float]) -> PairMeasurement:
        """Fit phase and gain difference (a - b) to one pair's sweep.

        ``alone_dbsm`` are a's and b's levels played alone (the radar's RCS at weight 1);
        their difference is the fit's start.
        """
        pair = (a, b)
        level_db = alone_dbsm[0] - alone_dbsm[1]
        if len(sweep) != len(delays):
            raise RtsError(f"calibration: FE pair {a}-{b}: {len(sweep)} cycles reported for "
                           f"{len(delays)} frames played; the radar must report every frame")
        _require_cycles((a, b), sweep)
        channel = [int(np.flatnonzero(schedule.fe[0, 0] == q)[0]) for q in pair]
        att = schedule.attenuation_db[0, 0, channel]
        # Each FE's level as the pair played it: alone less the attenuation beyond weight 1's.
        played = (np.asarray(alone_dbsm)
                  - (att - self.attenuation_db - self.rig.cal_gain_db[[a, b]]))
        dip = 20.0 * np.log10(abs(10.0 ** (played[0] / 20.0) - 10.0 ** (played[1] / 20.0)))
        levels = (f"FE {a} seen alone at {alone_dbsm[0]:.2f} dBsm and played in the pair at "
                  f"{played[0]:.2f} dBsm, FE {b} seen alone at {alone_dbsm[1]:.2f} dBsm and "
                  f"played at {played[1]:.2f} dBsm: as the sweep turns their echoes against "
                  f"each other their sum falls towards {dip:.2f} dBsm; below the radar's "
                  f"detection threshold?")
        az, el, rng = _pair_readings(Gate.of(self.rig, self.radar, schedule), sweep, pair,
                                     ("az_deg", "el_deg", "range_m"), levels)
        # Each echo through the range window at the cell the radar read (folding included).
        cell = np.round(rng / self.radar.range_bin_m)
        bins = self._echo_bins(schedule)
        offset = bins[:, channel] - cell[:, None]
        offset = np.mod(offset + self.n / 2.0, self.n) - self.n / 2.0
        level = self.radar.range_response(offset)
        # b's weight over a's as the attenuators played it (on their steps, within their
        # range), the channels' calibration gains taken out: what the fit's gain is beyond.
        weight_db = float(-(att[1] - att[0]) + (self.rig.cal_gain_db[b]
                                                 - self.rig.cal_gain_db[a]))
        # Likewise the phase shifter's steps: each channel's phase as played less the one asked
        # (its calibration phase and the delay rounding's compensation), b's less a's.
        _, asked = channel_delays(self.rig, self.radar, np.asarray(self.range_m),
                                  np.asarray(pair))
        turned = schedule.phase_rad[0, 0, channel] - asked
        steps_deg = float(_wrap(np.degrees(turned[1] - turned[0])))

        def residual(x: FloatArray) -> FloatArray:
            p_az, p_el = self.predict(a, b, sweep_deg, level, x[:1], x[1:], weight_db,
                                      steps_deg)
            out = np.concatenate([p_az[0] - az, p_el[0] - el])
            return np.where(np.isfinite(out), out, 10.0)

        # Start from the best phase and gain on a coarse grid, then fit both. The gains tried
        # lie about the one the channels' single levels give (a coarse measurement: the
        # radar's RCS, on its bus's steps) and at equal gains: a start at equal gains alone
        # leaves channels a few dB apart in a wrong minimum.
        # Phases first, at equal gains and at the single levels' gain; then the gains about
        # the latter at the best phase (a full grid of both costs 4x as many predictions).
        levels = np.round(level_db)
        phases = np.arange(0.0, 360.0, 5.0)

        def best_of(p: FloatArray, g: FloatArray) -> tuple[float, float]:
            c_az, c_el = self.predict(a, b, sweep_deg, level, p, g, weight_db, steps_deg)
            cost = np.nansum(np.minimum((c_az - az) ** 2 + (c_el - el) ** 2, 100.0), axis=1)
            i = int(np.argmin(cost))
            return float(p[i]), float(g[i])

        first = np.unique([0.0, levels])
        coarse_p, coarse_g = (g.ravel() for g in np.meshgrid(phases, first))
        phase0, _ = best_of(coarse_p, coarse_g)
        gains = np.unique(np.concatenate([np.arange(-3.0, 4.0) + levels, [0.0]]))
        start = np.array(best_of(np.full(gains.size, phase0), gains))
        fit = least_squares(residual, start, x_scale=np.array([1.0, 0.1]), diff_step=1e-7,
                            loss="soft_l1", f_scale=0.05, xtol=1e-12, ftol=1e-12, gtol=1e-12)
        phase, gain = float(_wrap(fit.x[0])), float(fit.x[1])
        m_az, m_el = self.predict(a, b, sweep_deg, level, np.array([phase]), np.array([gain]),
                                  weight_db, steps_deg)
        axis = _axis(self.rig, a, b)
        return PairMeasurement(
            a=a, b=b, delay_s=delays, sweep_deg=sweep_deg, az_deg=az, el_deg=el,
            shift_deg=az * axis[0] + el * axis[1],
            model_shift_deg=m_az[0] * axis[0] + m_el[0] * axis[1], phase_deg=phase,
            gain_db=gain, level_db=level_db, weight_db=weight_db,
            fit_rms_deg=float(np.sqrt(np.mean((m_az[0] - az) ** 2 + (m_el[0] - el) ** 2))))


def _axis(rig: Rig, a: int, b: int) -> FloatArray:
    axis = np.array([rig.az_deg[b] - rig.az_deg[a], rig.el_deg[b] - rig.el_deg[a]])
    return axis / np.linalg.norm(axis)


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
        # Each channel's phase in [-180, 180), as the rig file and the report give it: the
        # solution grown along the grid may be more than a turn from the reference.
        return np.concatenate([[0.0], _wrap(solution)]), _wrap(residual)
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
    6 x 5 grid over the middle of every quad otherwise. NaN where the radar reported nothing
    in the point's gate (`rts_scenario.gate`).
    """
    return check_grid(rig, radar, measure, method, estimator).error_deg


@dataclass(frozen=True)
class GridCheck:
    """The angle errors over the check grid (`grid_errors`), and what the schedule expected.

    ``error_deg`` (G, 2) is detected minus set angle (the strongest detection in the point's
    gate), NaN where the radar reported nothing there;
    ``predicted_deg`` (G, 2) the error the schedule predicts from the rig's attenuator and delay
    steps (the bench's own limit, not the calibration's) for a Bartlett radar, zero for other
    estimators (the schedule's prediction is the beamformer's), NaN where nothing was played;
    ``played`` (G,) whether any channel played the point and ``status`` (G,) the schedule's
    flags (`rts_scenario.schedule.model.Status`), which say why a point was not played.
    """

    error_deg: FloatArray
    predicted_deg: FloatArray
    played: NDArray[np.bool_]
    status: NDArray[np.uint16]

    def summary(self) -> dict[str, float | int | None]:
        """Return the statistics ``--json`` reports (docs/cli.md); ``None`` where undefined.

        ``max_excess_error_deg`` is the largest angle by which a detection is off the angle the
        schedule predicted: the error the bench's steps do not explain.
        """
        mag = np.hypot(self.error_deg[:, 0], self.error_deg[:, 1])
        excess = np.hypot(*(self.error_deg - self.predicted_deg).T)
        seen = np.isfinite(mag)

        def largest(x: FloatArray) -> float | None:
            return float(np.max(x[seen])) if seen.any() else None

        return {"max_error_deg": largest(mag),
                "rms_error_deg": float(np.sqrt(np.mean(mag[seen] ** 2))) if seen.any() else None,
                "max_excess_error_deg": largest(excess),
                "points": int(mag.size), "missed": int((~seen).sum()),
                "not_played": int(np.count_nonzero(~self.played))}


def check_grid(rig: Rig, radar: RadarProfile, measure: Measure, method: str = "exact",
               estimator: str = "bartlett", remeasured: list[str] | None = None,
               what: str = "check grid") -> GridCheck:
    """Play the check grid of `grid_errors`; return the errors and the schedule's view.

    Played once more where some of its cycles did not come back (a bench's hiccup, as the
    calibration's measurements are); ``what`` is then added to ``remeasured``.
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
    dets = _measured(measure, schedule, what, [] if remeasured is None else remeasured)
    gate = Gate.of(rig, radar, schedule)
    out = np.full((n, 2), np.nan)
    for i, d in enumerate(dets):  # one target per frame, read in its gate
        k = gate.strongest(d, i)
        if k is not None and d.az_deg is not None and d.el_deg is not None:
            out[i] = d.az_deg[k] - az[i], d.el_deg[k] - el[i]
    played: NDArray[np.bool_] = np.any(schedule.active[:, 0], axis=1)
    # The schedule predicts the beamformer's peak: a Bartlett radar's angle, not another's.
    predicted = schedule.angle_error_deg[:, 0] if estimator == "bartlett" else 0.0
    return GridCheck(error_deg=out, predicted_deg=np.where(played[:, None], predicted, np.nan),
                     played=played, status=schedule.status[:, 0].copy())


def failures(result: CalibrationResult, before: GridCheck, after: GridCheck,
             max_excess_deg: float = MAX_EXCESS_ERROR_DEG, radar: str | None = None,
             estimator: str | None = None) -> list[str]:
    """Return why a calibration cannot be trusted, one sentence per reason (none: it passed).

    ``radar`` and ``estimator``: the radar profile and estimator the pairs were fitted with,
    named where suspect pairs may mean either is not the radar's (the command's options).
    It fails when a pair is suspect (its measurement contradicts the others or the model),
    when a point of the check grid could not be played or was not detected after calibration
    (the calibrated rig is unverified there), or when the angle error after calibration exceeds
    what the rig's attenuator, phase shifter and delay steps predict by more than
    ``max_excess_deg``.
    """
    from .schedule.model import BLOCKING, Status

    out = []
    if result.suspects:
        out.append(f"{len(result.suspects)} of {len(result.pairs)} FE pairs are suspect "
                   f"(closure residual above {SUSPECT_PHASE_DEG:g} deg or {SUSPECT_GAIN_DB:g} "
                   f"dB, or sweep fit worse than {SUSPECT_FIT_DEG:g} deg rms): a bad channel, a "
                   f"moved FE or the wrong estimator"
                   + ("" if radar is None or estimator is None else
                      f" (--estimator {estimator}) or radar profile (--radar {radar}"
                      + (", calibrate's default" if radar == "paper" else "")
                      + "): name the radar under test"))
    stats, was = after.summary(), before.summary()
    points = stats["points"]
    blocked = int(stats["not_played"] or 0)
    if blocked:
        flags = int(np.bitwise_or.reduce(after.status[~after.played] & BLOCKING))
        why = ", ".join((s.name or "").lower().replace("_", " ") for s in Status
                        if s and flags & s) or "no channel on"
        out.append(f"{blocked} of {points} check-grid points could not be played on this rig "
                   f"for this radar ({why}): the calibration is not verified there")
    unseen = int(np.count_nonzero(after.played & np.isnan(after.error_deg).any(axis=1)))
    if unseen:
        out.append(f"the radar reported no target at {unseen} of {points} played check-grid "
                   f"points after calibration")
    excess = stats["max_excess_error_deg"]
    if excess is not None and excess > max_excess_deg:
        worse = ("" if was["max_error_deg"] is None else
                 f"; max angle error {was['max_error_deg']:.4f} deg before, "
                 f"{stats['max_error_deg']:.4f} deg after")
        out.append(f"after calibration the radar sees the check grid up to {excess:.4f} deg off "
                   f"the predicted angle (tolerance {max_excess_deg:g} deg){worse}")
    return out
