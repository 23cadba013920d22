"""Build per-frame four-channel schedules: what each RTS channel must do for each target.

For every frame f, target k and channel c (the quad's FE in paper order) the schedule holds the
FE index, attenuation, delay, Doppler shift and phase, and per entry (f, k) a set of status
flags. Formulas (DESIGN.md 5.4):

- level: a real target of RCS sigma at range R returns amplitude ~ sqrt(sigma) / R^2, so one FE
  at full weight needs ``A = A_ref - (rcs - rcs_ref) + 40 log10(R / R_ref)`` dB; the
  superposition's peak gain is ``g = |sum_q w_q f_q| / M`` and channel q gets
  ``A - 20 log10(w_q / g)`` plus its calibration gain offset, fitted to the attenuator by
  `rts_scenario.schedule.quantization`;
- delay: ``tau_q = 2R/c0 - 2 R_c,q / c0 - tau_hw + delta_q``; quantizing it is compensated in
  the channel phase so the channels stay coherent;
- Doppler: ``doppler_hz`` of the track on all channels;
- phase: the channel's calibration phase (plus the delay-quantization compensation), on the
  phase shifter's steps (`rts_scenario.schedule.quantization.phase_settings`; the angle error
  reported includes the rounding);
- echo slots: `rts_scenario.schedule.echo_slots`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import VirtualArray, direction_cosines
from ..kinematics import Tracks
from ..propagation import C0_MPS
from ..radar.profile import RadarProfile
from ..responses import FrontEndModel
from ..rig import HardwareLimits, Rig
from ..solver import Reason, solve_weights, solver_plan
from ..solver.estimator_aware import estimator_weights, plan_method
from ..workers import with_one_blas_thread
from .echo_slots import assign_echo_slots
from .model import BLOCKING, Schedule, ScheduleError, Status
from .quantization import (
    ANGLE_TIE_DEG,
    QUANTIZATION_MODES,
    peak_near,
    phase_rounding,
    phase_settings,
    start_attenuator_settings,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
# A quad's levels: weights, attenuations, phases, predicted angle errors, clipping, and
# whether the settings play a peak near the set direction.
Levels = tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_],
               NDArray[np.bool_]]

# What the solver takes the FEs' echoes to be (`solver_inputs`); the first is the default.
FE_RESPONSES = ("modeled", "plane-wave")
# A delay that rounds to the minimum is not too close: far below any delay step.
DELAY_SLACK_S = 1e-18

_REASON_STATUS = {
    Reason.OK: Status.OK,
    Reason.OUTSIDE: Status.OUT_OF_COVERAGE,
    Reason.NO_SOLUTION: Status.NOT_SYNTHESIZABLE,
    Reason.DEGENERATE: Status.NOT_SYNTHESIZABLE,
    Reason.SPLIT: Status.SPLIT,
    Reason.NOT_CONVERGED: Status.NOT_SYNTHESIZABLE,
}


@with_one_blas_thread
def build_schedule(
    tracks: Tracks,
    rig: Rig,
    radar: RadarProfile,
    *,
    method: str = "exact",
    quantization: str = "aware",
    frame_rate_hz: float | None = None,
    fe_responses: str = FE_RESPONSES[0],
    estimator: str = "bartlett",
    angle_tolerance_deg: tuple[float, float] | None = None,
    frame_index: NDArray[np.int64] | None = None,
) -> Schedule:
    """Turn per-frame target tracks into channel settings for the rig.

    Parameters
    ----------
    tracks : Tracks
        Ground truth per frame and target (`rts_scenario.kinematics.compute_tracks`).
    rig : Rig
        The RTS rig, with its calibration and hardware limits.
    radar : RadarProfile
        The radar under test (array, wavelength and physical antennas).
    method : {"exact", "paper", "estimator"}
        Weight solver method; ``"estimator"``: exact weights aimed so that the radar's
        ``estimator`` reads the set angle (`rts_scenario.solver.estimator_aware`).
    quantization : {"aware", "naive"}
        How attenuations and phases snap to the attenuator's and phase shifter's steps (no
        effect without steps).
    frame_rate_hz : float, optional
        Scene frame rate, checked against the rig's update rate.
    fe_responses : {"modeled", "plane-wave"}
        What the solver takes each FE's echo on the radar's array to be (`solver_inputs`).
    estimator : str
        The radar's angle estimator (a registered name), for ``method="estimator"``.
    angle_tolerance_deg : (float, float), optional
        The scene's azimuth and elevation tolerances: a target whose synthesized angle the
        RTS's steps move by more than `BENCH_ANGLE_SHARE` of either is flagged
        ``ANGLE_QUANTIZED`` (played off its angle; its predicted error against the weights'
        own, before the steps, so a method's intended aim is not counted). Without: no flag.
    frame_index : ndarray, shape (F,), optional
        The frames' numbers in the scene (default 0, 1, ...): a batch of a scene's frames
        (`compute_tracks` at some of its times) keeps the scene's numbers, which an output
        streams (a UDP stream's frames must go forward).

    Raises
    ------
    ScheduleError
        If the scene's frame rate exceeds the rig's update rate, or its frame period is not more
        than twice the time a radar cycle may show either frame, or a mode is unknown.
    """
    array, model = solver_inputs(radar, fe_responses)
    limits = rig.limits
    if quantization not in QUANTIZATION_MODES:
        raise ScheduleError(f"quantization: unknown mode {quantization!r}; valid modes: "
                            f"{', '.join(QUANTIZATION_MODES)}")
    problem = None if frame_rate_hz is None else radar.frame_rate_problem(frame_rate_hz, rig)
    if problem is not None:
        raise ScheduleError(f"frame_rate_hz: {problem}")
    shape = tracks.range_m.shape
    status = np.where(tracks.present, Status.OK, Status.NOT_PRESENT).astype(np.uint16)
    status |= np.where(tracks.present & ~tracks.in_coverage, Status.OUT_OF_COVERAGE,
                       Status.OK).astype(np.uint16)

    # A target whose direction never changes (a static scene) is solved once, not per frame.
    todo = tracks.present & tracks.in_coverage
    first = np.argmax(todo, axis=0)
    steady = np.all(((tracks.az_deg == tracks.az_deg[first, np.arange(shape[1])])
                     & (tracks.el_deg == tracks.el_deg[first, np.arange(shape[1])])) | ~todo,
                    axis=0)
    solve = todo & ~steady[None, :]
    solve[first[steady], np.flatnonzero(steady)] = todo[first[steady], np.flatnonzero(steady)]
    flat = np.flatnonzero(solve.ravel())
    if method == "estimator":
        sol = estimator_weights(tracks.az_deg.ravel()[flat], tracks.el_deg.ravel()[flat],
                                rig=rig, array=array, estimator=estimator, model=model)
    else:
        sol = solve_weights(tracks.az_deg.ravel()[flat], tracks.el_deg.ravel()[flat], rig=rig,
                            array=array, method=method, model=model)
    # Broadcast each steady target's solution to all its frames.
    source = np.full(shape, -1, dtype=np.int64)
    source.ravel()[flat] = np.arange(flat.size)
    source = np.where(steady[None, :] & todo, source[first, np.arange(shape[1])][None, :],
                      source)
    pick = source.ravel()[todo.ravel()]
    quad = np.full(shape, -1, dtype=np.int64)
    weight = np.zeros((*shape, 4))
    quad.ravel()[todo.ravel()] = sol.quad[pick]
    weight.reshape(-1, 4)[todo.ravel()] = sol.weights[pick]
    reason_status = np.array([_REASON_STATUS[Reason(r)] for r in range(len(Reason))],
                             dtype=np.uint16)
    status.ravel()[todo.ravel()] |= reason_status[sol.reason[pick]]

    ok = status == Status.OK
    fe = np.where(ok[..., None], rig.quads[np.maximum(quad, 0)], -1)

    # Level of one FE at full weight, then per channel with the superposition gain.
    ref = rig.reference
    with np.errstate(divide="ignore"):
        single_db = (ref.attenuation_db - (tracks.rcs_dbsm - ref.rcs_dbsm)
                     + 40.0 * np.log10(tracks.range_m / ref.range_m))
    attenuation = np.full((*shape, 4), np.nan)
    solved = weight.copy()  # before the steps: what the method aims at
    angle_error = np.zeros((*shape, 2))
    clipped = np.zeros(shape, dtype=bool)
    no_peak = np.zeros(shape, dtype=bool)
    fe0 = np.maximum(fe, 0)
    delay, exact_phase = channel_delays(rig, radar, tracks.range_m[..., None], fe0)
    # On the phase shifter's steps; a quad's entries may take a neighbouring step (below).
    phase = limits.phase_setting(exact_phase)
    straddle_db = _straddle_db(rig, radar, tracks, delay, fe0)
    # The FEs' responses on the array (estimator-aware weights are exact weights re-aimed).
    responses = solver_plan(rig, array, plan_method(method), model).responses
    # Per quad of the rig, vectorized over its entries. A quad's quantization search runs on the
    # worker threads while the next quad's responses are evaluated here (one quad pending).
    pending: list[tuple[NDArray[np.intp], Callable[[], Levels]]] = []
    try:
        for q in range(len(rig.quads)):
            sel = np.flatnonzero((quad.ravel() == q) & ok.ravel())
            if sel.size == 0:
                continue
            u, s = direction_cosines(np.radians(tracks.az_deg.ravel()[sel]),
                                     np.radians(tracks.el_deg.ravel()[sel]))
            resp = responses[q].evaluate(u, s)
            # A channel's calibration gain offset is part of its setting, so it is quantized
            # too. So is the level that makes up for the channel's delay rounding
            # (`_straddle_db`).
            offset = rig.cal_gain_db[rig.quads[q]][None, :] + straddle_db.reshape(-1, 4)[sel]
            pending.append((sel, _start_levels(resp, weight.reshape(-1, 4)[sel],
                                               single_db.ravel()[sel][:, None] + offset,
                                               exact_phase.reshape(-1, 4)[sel],
                                               array.n_elements, limits, quantization, u, s)))
            if len(pending) > 1:
                _store_levels(*pending.pop(0), weight, attenuation, phase, angle_error,
                              clipped, no_peak)
        while pending:
            _store_levels(*pending.pop(0), weight, attenuation, phase, angle_error, clipped,
                          no_peak)
    except BaseException:
        # No search goes on behind the caller's back once it hears of the error.
        for _, finish in pending:
            with contextlib.suppress(Exception):
                finish()
        raise
    if angle_tolerance_deg is not None:
        # With steps, every entry; on a continuous rig, those played whose attenuator's range
        # switched off a channel the method wanted (it needs more than the maximum): playing
        # it too loud would move the angle more, leaving it out may move it too.
        stepped = limits.attenuation_step_db > 0.0 or limits.phase_step_deg > 0.0
        # (A weight below `WANTED_WEIGHT`, -180 dB, is rounding: the solver's 1e-17 is 0.)
        switched_off = ((solved > WANTED_WEIGHT) & np.isnan(attenuation)).any(axis=-1)
        judged = ok if stepped else ok & switched_off & (weight > 0.0).any(axis=-1)
        if judged.any():
            status |= _angle_quantized(angle_error, no_peak, solved, quad, judged, tracks,
                                       responses, angle_tolerance_deg)
    # Quantization may switch an idle channel on (weakly) to hold the angle.
    active = ok[..., None] & (weight > 0.0)
    attenuation[~active] = np.nan
    status |= np.where(clipped, Status.ATTENUATION_CLIPPED, 0).astype(np.uint16)

    # Judged on the channels played; where the attenuator left none on, on those the solver
    # wants (at range 0 the level needed is infinite and the steps leave no channel on). A
    # channel the steps switched off is not played: its delay does not matter.
    close = delay < limits.delay_min_s - DELAY_SLACK_S
    wanted = ok[..., None] & (solved > 0.0) & ~active.any(axis=-1, keepdims=True)
    too_close = ((active | wanted) & close).any(axis=-1)
    status |= np.where(too_close, Status.TOO_CLOSE, 0).astype(np.uint16)
    if limits.delay_max_s is not None:
        too_far = (active & (delay > limits.delay_max_s + DELAY_SLACK_S)).any(axis=-1)
        status |= np.where(too_far, Status.TOO_FAR, 0).astype(np.uint16)

    doppler = np.broadcast_to(tracks.doppler_hz[..., None], (*shape, 4)).copy()
    off_range = (tracks.doppler_hz < limits.doppler_min_hz) | (
        tracks.doppler_hz > limits.doppler_max_hz)
    status |= np.where(off_range & ok, Status.DOPPLER_OUT_OF_RANGE, 0).astype(np.uint16)

    status |= assign_echo_slots(fe, active & ((status & BLOCKING) == 0)[..., None], tracks,
                                limits.echoes_per_channel, rig.n_front_ends)

    emitted = ((status & BLOCKING) == 0)[..., None] & active
    nan = np.nan
    return Schedule(
        t_s=tracks.t_s, frame_index=_frame_numbers(frame_index, shape[0]),
        names=tracks.names,
        quad=np.where(emitted.any(-1), quad, -1), fe=np.where(emitted, fe, -1),
        weight=np.where(emitted, weight, 0.0),
        attenuation_db=np.where(emitted, attenuation, nan),
        delay_s=np.where(emitted, delay, nan), doppler_hz=np.where(emitted, doppler, nan),
        phase_rad=np.where(emitted, phase, nan), active=emitted, status=status,
        angle_error_deg=np.where(emitted.any(-1)[..., None], angle_error, nan),
    )


def _straddle_db(rig: Rig, radar: RadarProfile, tracks: Tracks, delay: FloatArray,
                 fe: IntArray) -> FloatArray:
    """Level (dB, added to the attenuation) that makes up for each channel's delay rounding.

    On a delay grid the channels of one target arrive up to a step apart, so the radar's range
    FFT reads them at slightly different offsets from the target's range cell and the window
    weighs them differently (about 3 % between channels 100 ps apart on a 40 MHz/us chirp,
    0.1 deg of angle). Each channel is set ``W(b - k) / W(b_q - k)`` stronger, ``b`` the
    target's range bin, ``b_q`` the channel's, ``k = round(b)`` the cell the radar reads (a
    target within the channels' spread of a cell border may be read at the other cell).
    """
    if rig.limits.delay_step_s <= 0.0:
        return np.zeros(delay.shape)
    exact = _exact_delays(rig, tracks.range_m[..., None], fe)
    target = radar.range_bin(2.0 * tracks.range_m / C0_MPS, tracks.doppler_hz)
    channel = target[..., None] + radar.range_bin(delay - exact)
    cell = np.round(target)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        out: FloatArray = 20.0 * np.log10(radar.range_response(channel - cell)
                                          / radar.range_response(target[..., None] - cell))
    return np.where(np.isfinite(out), out, 0.0)


def _start_levels(
    resp: NDArray[np.complex128], weights: FloatArray, single_db: FloatArray,
    phase: FloatArray, n_elements: int, limits: HardwareLimits, mode: str, u: FloatArray,
    s: FloatArray,
) -> Callable[[], Levels]:
    """Start fitting a quad's levels; the returned function waits and gives the result.

    The result: weights, channel attenuations (N, 4), channel phases (N, 4), predicted angle
    errors (N, 2) and clipping (N,). ``single_db`` (N, 4) is each channel's attenuation for
    full weight (calibration included), ``phase`` (N, 4) its exact phase. The phases go on the
    phase shifter's nearest steps, and the attenuations are fitted to the attenuator's range
    and step with the channels as those phases play them
    (`rts_scenario.schedule.quantization.attenuator_settings`, which also says what clipped
    means), for the target's level as the superposition with those phases gives it.
    Quantization-aware, entries whose angle neighbouring phase steps keep better
    (`rts_scenario.schedule.quantization.phase_settings`) are fitted with those too, and the
    fit with the smaller predicted angle error is kept. The weights follow from the settings;
    the angle error, from both settings.
    """
    on = weights > 0.0
    nearest = limits.phase_setting(phase)
    chosen_phase = phase_settings(resp, weights, phase, limits, mode, u, s)
    if limits.phase_step_deg > 0.0:
        # Each channel's echo as the phase shifter plays it: turned by its rounding.
        resp = resp * phase_rounding(nearest, phase).T[None, :, :]

    def start(turned: NDArray[np.complex128], at: slice | NDArray[np.intp],
              ) -> tuple[FloatArray, Callable[[], tuple[FloatArray, NDArray[np.bool_]]]]:
        """Start fitting the attenuators of entries ``at`` with their echoes ``turned``."""
        # The superposition's gain as the phases play it (turned from the solved phases, the
        # peak is weaker), and each channel's attenuation at weight 1 for the target's level.
        gain = np.abs(np.einsum("qn,nq->n", turned[0], weights[at])) / n_elements
        full = single_db[at] + 20.0 * np.log10(gain)[:, None]
        with np.errstate(divide="ignore"):
            exact = np.where(on[at], full - 20.0 * np.log10(np.where(on[at], weights[at], 1.0)),
                             np.inf)
        return full, start_attenuator_settings(turned, weights[at], full, exact, limits, mode,
                                               u[at], s[at])

    full, settings = start(resp, slice(None))
    # Aware: where neighbouring phase steps keep the angle better, the attenuators are fitted
    # to those too, and the better of the two fits is kept (never worse than the nearest steps).
    other = np.flatnonzero((chosen_phase != nearest).any(axis=1))
    other_resp = resp[:, :, other] * phase_rounding(chosen_phase[other], nearest[other]).T[None]
    other_full, other_settings = start(other_resp, other) if other.size else (full, None)

    def levels(chosen: FloatArray, full: FloatArray, turned: NDArray[np.complex128],
               at: slice | NDArray[np.intp]
               ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Return the settings' weights, predicted angle error and whether they play a peak.

        A peak near the set direction, that is; where there is none, the error says nothing.
        """
        new_w = np.where(np.isfinite(chosen), 10.0 ** (-(chosen - full) / 20.0), 0.0)
        top = new_w.max(axis=1, keepdims=True)
        new_w = new_w / np.where(top > 0.0, top, 1.0)
        err, has_peak = peak_near(turned, new_w, u[at], s[at])
        return new_w, err, has_peak

    def finish() -> Levels:
        chosen, clipped = settings()
        new_w, err, has_peak = levels(chosen, full, resp, slice(None))
        set_phase = nearest.copy()
        if other_settings is not None:
            other_chosen, other_clipped = other_settings()
            other_w, other_err, other_peak = levels(other_chosen, other_full, other_resp, other)
            # Settings that play no peak near the set direction lose to settings that do.
            better = other_peak & (~has_peak[other] | (np.hypot(*other_err.T)
                                                       < np.hypot(*err[other].T)
                                                       - ANGLE_TIE_DEG))
            at = other[better]
            chosen[at], new_w[at], err[at], clipped[at], has_peak[at] = (
                other_chosen[better], other_w[better], other_err[better], other_clipped[better],
                True)
            set_phase[at] = chosen_phase[at]
        return (new_w, np.where(np.isfinite(chosen), chosen, np.nan), set_phase, err, clipped,
                has_peak)

    return finish


# The share of the scene's angle tolerance the RTS's steps may take: beyond it a target is
# flagged ANGLE_QUANTIZED (the radar would be judged for an angle the bench moved).
BENCH_ANGLE_SHARE = 1.0 / 3.0


# A solved weight (the largest 1) that a channel switched off beyond the attenuator's range
# is judged for (`ANGLE_QUANTIZED` on a continuous rig): below it, rounding.
WANTED_WEIGHT = 1e-9


def _frame_numbers(frame_index: NDArray[np.int64] | None, n_frames: int) -> NDArray[np.int64]:
    """Return ``frame_index`` checked (one whole number >= 0 per frame, increasing), or 0.. ."""
    if frame_index is None:
        return np.arange(n_frames)
    index = np.asarray(frame_index)
    if index.shape != (n_frames,) or not np.issubdtype(index.dtype, np.integer) or (
            n_frames and (index.min() < 0 or (np.diff(index) <= 0).any())):
        raise ScheduleError(f"frame_index: one increasing whole number >= 0 per frame of the "
                            f"tracks ({n_frames}), got shape {index.shape} of {index.dtype}")
    return index.astype(np.int64)


def _angle_quantized(angle_error: FloatArray, no_peak: NDArray[np.bool_], solved: FloatArray,
                     quad: NDArray[np.int64], ok: NDArray[np.bool_], tracks: Tracks,
                     responses: Sequence[Any], tolerance_deg: tuple[float, float]
                     ) -> NDArray[np.uint16]:
    """Flag entries whose synthesized angle the RTS's steps move beyond `BENCH_ANGLE_SHARE`.

    The steps' share is the predicted error ``angle_error`` of the settings played less that
    of the ``solved`` weights before the steps (zero for the exact method, the method's own
    for the paper's or an estimator's aim), evaluated where the whole error exceeds the share.
    Flagged too: settings that play no peak near the set direction (``no_peak``: their
    predicted error says nothing).
    """
    bound = BENCH_ANGLE_SHARE * np.asarray(tolerance_deg, dtype=np.float64)
    out = np.where(ok & no_peak, Status.ANGLE_QUANTIZED, 0).astype(np.uint16)
    maybe = ok & ~no_peak & (np.abs(np.nan_to_num(angle_error)) > bound).any(axis=-1)
    for q in np.unique(quad[maybe]):
        sel = np.flatnonzero((maybe & (quad == q)).ravel())
        u, s = direction_cosines(np.radians(tracks.az_deg.ravel()[sel]),
                                 np.radians(tracks.el_deg.ravel()[sel]))
        own, _ = peak_near(responses[q].evaluate(u, s), solved.reshape(-1, 4)[sel], u, s)
        moved = (np.abs(angle_error.reshape(-1, 2)[sel] - own) > bound).any(axis=-1)
        out.ravel()[sel[moved]] = Status.ANGLE_QUANTIZED
    return out


def _store_levels(sel: NDArray[np.intp], finish: Callable[[], Levels],
                  weight: FloatArray, attenuation: FloatArray, phase: FloatArray,
                  angle_error: FloatArray, clipped: NDArray[np.bool_],
                  no_peak: NDArray[np.bool_]) -> None:
    """Wait for a quad's levels (`_start_levels`) and write them at its entries ``sel``."""
    w, att, ph, err, clip, has_peak = finish()
    clipped.ravel()[sel] = clip
    no_peak.ravel()[sel] = ~has_peak
    weight.reshape(-1, 4)[sel] = w
    attenuation.reshape(-1, 4)[sel] = att
    phase.reshape(-1, 4)[sel] = ph
    angle_error.reshape(-1, 2)[sel] = err


def solver_inputs(
    radar: RadarProfile, fe_responses: str
) -> tuple[VirtualArray, FrontEndModel | None]:
    """Return the array and FE response model the schedule solves the weights with.

    ``"plane-wave"``: the profile's virtual array at its nominal wavelength, each FE's echo the
    steering vector of its direction (DESIGN.md 5.1). ``"modeled"``: the array the radar's
    estimator steers (`RadarProfile.steering_array`) and each FE's echo modeled on the bench
    from the radar's physical antennas, the FE distances and antenna offsets (DESIGN.md 5.5b,
    `rts_scenario.responses`): the synthesized peak is then where the radar looks for it.
    """
    if fe_responses == "plane-wave":
        return radar.array, None
    if fe_responses == "modeled":
        return radar.steering_array, radar.front_end_model
    raise ScheduleError(f"fe_responses: unknown model {fe_responses!r}; valid models: "
                        f"{', '.join(FE_RESPONSES)}")


def _exact_delays(rig: Rig, range_m: FloatArray, fe: IntArray) -> FloatArray:
    """RTS delay that puts echoes through FEs ``fe`` at ``range_m``, before the delay grid."""
    return (2.0 * range_m / C0_MPS - 2.0 * rig.distance_m[fe] / C0_MPS - rig.limits.latency_s
            + rig.cal_delay_s[fe])


def channel_delays(rig: Rig, radar: RadarProfile, range_m: FloatArray,
                   fe: IntArray) -> tuple[FloatArray, FloatArray]:
    """Return the RTS delay and channel phase of echoes at ``range_m`` through FEs ``fe``.

    The echo through FE q must arrive ``2R/c0`` after transmission: the RTS delays it by
    ``2R/c0 - 2 R_c,q/c0 - latency + calibration delay``, on the delay step's grid. A quantized
    delay turns the echo's phase by ``-2 pi f (delay - exact)``: it is given back in the channel
    phase (with the calibration phase), f the frequency of the signal the RTS delays (the IF of
    a digital RTS, the carrier for an RF delay line: ``rig.rts``) where the radar reads the
    phase, at the centre of its sampled sweep, less the sweep over the echo's lateness.

    Parameters
    ----------
    rig, radar : Rig, RadarProfile
    range_m : ndarray
        Target range, broadcast against ``fe``.
    fe : ndarray of int
        Rig FE index of each channel.

    Returns
    -------
    delay_s, phase_rad : ndarray
        Shape of the broadcast inputs; the phase wrapped to [-pi, pi).
    """
    limits = rig.limits
    exact = _exact_delays(rig, range_m, fe)
    delay = exact
    if limits.delay_step_s > 0.0:
        delay = np.round(exact / limits.delay_step_s) * limits.delay_step_s
    quantum = delay - exact
    late_s = 2.0 * range_m / C0_MPS + 0.5 * quantum
    delayed_hz = (rig.rts.delayed_frequency_hz(radar.fc_hz)
                  + radar.sampled_centre_frequency_hz - radar.fc_hz
                  - radar.slope_hz_per_s * late_s)
    phase = np.radians(rig.cal_phase_deg[fe]) + 2.0 * np.pi * delayed_hz * quantum
    return delay, np.mod(phase + np.pi, 2.0 * np.pi) - np.pi


# Delay steps up to this share of the radar's range bin go without a note: the schedule's
# phase and level corrections leave no error a radar reports (100 ps on kit-table1 is 0.05).
COARSE_DELAY_STEP_BINS = 0.25


def delay_step_note(rig: Rig, radar: RadarProfile) -> str | None:
    """Say what the rig's delay step costs when it is coarse for ``radar``; None when not.

    Each channel's delay is rounded to the step, so one target's channels reach the radar up to
    a step apart and its range is off by up to a quarter step times c0 (half a step of
    round-trip delay). The schedule gives the rounding back in phase and in level at the range
    cell the radar reads, not at its neighbours, which the radar's range interpolation and
    level reading also use: range and RCS errors grow with the step.
    """
    step_s = rig.limits.delay_step_s
    bins = float(radar.range_bin(step_s))
    if not bins > COARSE_DELAY_STEP_BINS:
        return None
    return (f"rig {rig.name!r}: limits.delay_step_s = {step_s:g} s is {bins:.2g} range bins of "
            f"radar {radar.name!r} ({radar.range_bin_m:.3g} m per bin): each channel's delay "
            f"is rounded by up to {step_s / 2:g} s, so a target's channels are played up to "
            f"{C0_MPS * step_s / 4:.3g} m off its range; expect range and RCS errors that grow "
            f"with the step beyond {COARSE_DELAY_STEP_BINS:g} bins")


# FE phases further apart than this (deg) from the FEs' distances behind an IF RTS, with no
# phase calibration: `if_distance_note` says so.
IF_DISTANCE_PHASE_DEG = 5.0


def if_distance_note(rig: Rig, radar: RadarProfile) -> str | None:
    """Say that an IF RTS's FEs at different distances need a phase calibration; None if not.

    A digital RTS delays the signal at its IF: each FE's air path ``D`` turns its echo by
    ``(f - f_if) 2 D / c0`` (184 deg per mm at 77 GHz), which the RTS's delay does not take
    back, as an RF delay line would. The schedule leaves it to the rig's phase calibration
    (`calibrate` measures it): a rig without one (every ``calibration.phase_deg`` 0) whose FEs'
    distances turn them more than `IF_DISTANCE_PHASE_DEG` apart plays its targets off their
    angles, on a bench and on the built-in simulated radar alike.
    """
    if rig.rts.delay_model != "if" or np.any(rig.cal_phase_deg != 0.0):
        return None
    turn = 360.0 * (radar.fc_hz - rig.rts.if_frequency_hz) * 2.0 * rig.distance_m / C0_MPS
    apart = (turn - turn[0] + 180.0) % 360.0 - 180.0
    if not np.abs(apart).max() > IF_DISTANCE_PHASE_DEG:
        return None
    per_mm = 360.0 * (radar.fc_hz - rig.rts.if_frequency_hz) * 2e-3 / C0_MPS
    return (f"rig {rig.name!r}: its FEs lie {rig.distance_m.min():.4g} to "
            f"{rig.distance_m.max():.4g} m from the radar behind an IF RTS (rts.delay_model if), "
            f"and it has no phase calibration: each FE's air path turns its echo by "
            f"{per_mm % 360.0:.0f} deg per mm of distance (modulo 360) at the "
            f"{radar.fc_hz / 1e9:.4g} GHz of radar {radar.name!r}, which the RTS's delay does "
            f"not take back; here they lie up to {np.abs(apart).max():.0f} deg apart, so its "
            f"targets are played off their angles: calibrate the rig (rts-scenario calibrate "
            f"measures each FE's phase)")


def calibration_note(rig: Rig) -> str | None:
    """Say that a rig's calibration plays as errors on the built-in simulated radar; else None.

    A rig's ``calibration`` entries cancel the channel errors of the bench they were measured
    on; the simulated radar's bench has none of them (unless a calibration study injects them),
    so there each offset turns, weakens or delays its channel for nothing, and targets land off
    their angles and levels: a failure is the rig file's, not the radar's.
    """
    offsets = [(name, values) for name, values in (
        ("phase_deg", rig.cal_phase_deg), ("gain_db", rig.cal_gain_db),
        ("delay_s", rig.cal_delay_s)) if np.any(values != 0.0)]
    if not offsets:
        return None
    said = "; ".join(f"calibration.{name} " + ", ".join(f"{v:.4g}" for v in values)
                     for name, values in offsets)
    return (f"rig {rig.name!r} carries the calibration of its bench ({said}); the built-in "
            f"simulated radar plays a bench without those channel errors, where the offsets "
            f"turn, weaken or delay each channel for nothing and can put targets off their "
            f"angles and levels: a failure here may be the rig file's, not the radar's (for the "
            f"simulated radar, a copy of the rig without its calibration entries)")


__all__ = ["FE_RESPONSES", "IF_DISTANCE_PHASE_DEG", "build_schedule", "calibration_note",
           "channel_delays", "delay_step_note", "if_distance_note", "solver_inputs"]
