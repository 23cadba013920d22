"""Per-frame four-channel schedules: what each RTS channel must do for each target.

For every frame f, target k and channel c (the quad's FE in paper order) the schedule holds the
FE index, attenuation, delay, Doppler shift and phase, and per entry (f, k) a set of status
flags. Formulas (DESIGN.md 5.4):

- level: a real target of RCS sigma at range R returns amplitude ~ sqrt(sigma) / R^2, so one FE
  at full weight needs ``A = A_ref - (rcs - rcs_ref) + 40 log10(R / R_ref)`` dB; the
  superposition's peak gain is ``g = |sum_q w_q f_q| / M`` and channel q gets
  ``A - 20 log10(w_q / g)`` plus its calibration gain offset;
- delay: ``tau_q = 2R/c0 - 2 R_c,q / c0 - tau_hw + delta_q``; quantizing it is compensated in
  the channel phase so the channels stay coherent;
- Doppler: ``doppler_hz`` of the track on all channels;
- phase: the channel's calibration phase (plus the delay-quantization compensation).

Hardware limits come from the rig. With an attenuation step, each channel's attenuation is set
to the grid value below or above the exact one, choosing the combination whose synthesized
angle is closest to the set angle (a Newton step on the exact beamformer response predicts the
angle of every combination); the predicted remaining error is kept per entry.

Echo slots: each FE channel produces at most ``echoes_per_channel`` echoes per frame. Rule: a
target keeps its echoes when, on every FE it uses, fewer than that many nearer targets (range;
ties: larger RCS, then lower index) use the FE in that frame; otherwise it is flagged
``NO_ECHO_SLOT`` and not emitted (a partial set of channels would move its angle).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntFlag

import numpy as np
from numpy.typing import NDArray

from .arrays import (
    angles_from_cosines,
    direction_cosines,
    power_curvature,
)
from .constants import C0_MPS
from .errors import RtsError
from .kinematics import Tracks
from .radar.profile import RadarProfile
from .rig import HardwareLimits, Rig
from .solver import Reason, solve_weights, solver_plan

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

QUANTIZATION_MODES = ("aware", "naive")
# Candidates ranked best by the linear model that the exact prediction then compares.
SHORTLIST = 8
# The quantization-aware search moves two channels by up to SEARCH_STEPS grid steps either side
# of their nearest setting, on the entries whose current setting errs more than
# SEARCH_ABOVE_DEG (wider passes follow for what is left), and the weakest channel by up to
# FINE_STEPS. Entries go in blocks of SEARCH_BLOCK.
SEARCH_STEPS = (2, 4)
SEARCH_ABOVE_DEG = (0.005, 0.03)
FINE_STEPS = 8
SEARCH_BLOCK = 1024


class ScheduleError(RtsError):
    """A schedule cannot be built (e.g. the scene outpaces the RTS)."""


class Status(IntFlag):
    """Per-entry flags. Any flag but ``ATTENUATION_CLIPPED`` keeps the entry from being emitted."""

    OK = 0
    NOT_PRESENT = 1
    OUT_OF_COVERAGE = 2
    NOT_SYNTHESIZABLE = 4
    SPLIT = 8
    TOO_CLOSE = 16
    DOPPLER_OUT_OF_RANGE = 32
    NO_ECHO_SLOT = 64
    ATTENUATION_CLIPPED = 128


BLOCKING = Status(~Status.ATTENUATION_CLIPPED & 0xFF)

_REASON_STATUS = {
    Reason.OK: Status.OK,
    Reason.OUTSIDE: Status.OUT_OF_COVERAGE,
    Reason.NO_SOLUTION: Status.NOT_SYNTHESIZABLE,
    Reason.DEGENERATE: Status.NOT_SYNTHESIZABLE,
    Reason.SPLIT: Status.SPLIT,
    Reason.NOT_CONVERGED: Status.NOT_SYNTHESIZABLE,
}


@dataclass(frozen=True)
class Schedule:
    """Channel settings per frame (F), target (K) and channel (4, paper order).

    Attributes
    ----------
    t_s : ndarray, shape (F,)
        Frame times.
    frame_index : ndarray, shape (F,)
        Index of each frame in the whole scene (batches keep it).
    names : tuple of str
        Target names (K).
    quad : ndarray, shape (F, K)
        Quad used, -1 when not synthesized.
    fe : ndarray, shape (F, K, 4)
        Rig FE index of each channel, -1 when not synthesized.
    weight : ndarray, shape (F, K, 4)
        Linear amplitude weights after quantization (max 1 per emitted entry).
    attenuation_db, delay_s, doppler_hz, phase_rad : ndarray, shape (F, K, 4)
        The channel settings (NaN where the channel is off).
    active : ndarray of bool, shape (F, K, 4)
        Channels that emit an echo.
    status : ndarray, shape (F, K)
        `Status` flags.
    angle_error_deg : ndarray, shape (F, K, 2)
        Predicted azimuth and elevation error left by the quantization of the attenuations.
    """

    t_s: FloatArray
    frame_index: IntArray
    names: tuple[str, ...]
    quad: IntArray
    fe: IntArray
    weight: FloatArray
    attenuation_db: FloatArray
    delay_s: FloatArray
    doppler_hz: FloatArray
    phase_rad: FloatArray
    active: BoolArray
    status: NDArray[np.uint16]
    angle_error_deg: FloatArray

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.t_s.size)

    @property
    def emitted(self) -> BoolArray:
        """Entries (F, K) the RTS plays."""
        return (self.status & BLOCKING) == 0

    def frames(self, start: int, stop: int) -> Schedule:
        """Return the frames ``start:stop`` as a schedule of their own (views, no copy)."""
        part = slice(start, stop)
        return Schedule(**{
            f.name: getattr(self, f.name) if f.name == "names" else getattr(self, f.name)[part]
            for f in fields(self)
        })

    def changed(self) -> BoolArray:
        """Entries (F, K) that differ from the previous frame (all of frame 0).

        Static targets and unchanged entries need not be sent again: an output in delta mode
        sends only these.
        """
        out = np.ones(self.status.shape, dtype=bool)
        if self.n_frames > 1:
            same = self.status[1:] == self.status[:-1]
            for name in ("fe", "attenuation_db", "delay_s", "doppler_hz", "phase_rad", "active"):
                a = getattr(self, name)
                same &= np.all((a[1:] == a[:-1]) | (np.isnan(a[1:]) & np.isnan(a[:-1]))
                               if a.dtype.kind == "f" else a[1:] == a[:-1], axis=-1)
            out[1:] = ~same
        return out


def build_schedule(
    tracks: Tracks,
    rig: Rig,
    radar: RadarProfile,
    *,
    method: str = "exact",
    quantization: str = "aware",
    frame_rate_hz: float | None = None,
) -> Schedule:
    """Turn per-frame target tracks into channel settings for the rig.

    Parameters
    ----------
    tracks : Tracks
        Ground truth per frame and target (`rts_scenario.kinematics.compute_tracks`).
    rig : Rig
        The RTS rig, with its calibration and hardware limits.
    radar : RadarProfile
        The radar under test (array and wavelength).
    method : {"exact", "paper"}
        Weight solver method.
    quantization : {"aware", "naive"}
        How attenuations snap to the attenuator's step (no effect without a step).
    frame_rate_hz : float, optional
        Scene frame rate, checked against the rig's update rate.

    Raises
    ------
    ScheduleError
        If the scene's frame rate exceeds the rig's update rate or a mode is unknown.
    """
    limits = rig.limits
    if quantization not in QUANTIZATION_MODES:
        raise ScheduleError(f"quantization: unknown mode {quantization!r}; valid modes: "
                            f"{', '.join(QUANTIZATION_MODES)}")
    if frame_rate_hz is not None and frame_rate_hz > limits.update_rate_hz * (1 + 1e-9):
        raise ScheduleError(
            f"frame_rate_hz: the scene runs at {frame_rate_hz:g} Hz but rig {rig.name!r} "
            f"updates at most {limits.update_rate_hz:g} Hz (limits.update_rate_hz)"
        )
    array = radar.array
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
    sol = solve_weights(tracks.az_deg.ravel()[flat], tracks.el_deg.ravel()[flat], rig=rig,
                        array=array, method=method)
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
    angle_error = np.zeros((*shape, 2))
    clipped = np.zeros(shape, dtype=bool)
    responses = solver_plan(rig, array, method).responses
    for q in range(len(rig.quads)):  # per quad of the rig, vectorized over its entries
        sel = np.flatnonzero((quad.ravel() == q) & ok.ravel())
        if sel.size == 0:
            continue
        u, s = direction_cosines(np.radians(tracks.az_deg.ravel()[sel]),
                                 np.radians(tracks.el_deg.ravel()[sel]))
        resp = responses[q].evaluate(u, s)
        # A channel's calibration gain offset is part of its setting, so it is quantized too.
        offset = rig.cal_gain_db[rig.quads[q]][None, :]
        w, att, err, clip = _levels(resp, weight.reshape(-1, 4)[sel],
                                    single_db.ravel()[sel][:, None] + offset,
                                    array.n_elements, limits, quantization, u, s)
        clipped.ravel()[sel] = clip
        weight.reshape(-1, 4)[sel] = w
        attenuation.reshape(-1, 4)[sel] = att
        angle_error.reshape(-1, 2)[sel] = err
    # Quantization may switch an idle channel on (weakly) to hold the angle.
    active = ok[..., None] & (weight > 0.0)
    attenuation[~active] = np.nan
    status |= np.where(clipped, Status.ATTENUATION_CLIPPED, 0).astype(np.uint16)

    # Delays: the echo through FE q must arrive 2R/c0 after transmission.
    fe0 = np.maximum(fe, 0)
    exact_delay = (2.0 * tracks.range_m[..., None] / C0_MPS
                   - 2.0 * rig.distance_m[fe0] / C0_MPS - limits.latency_s
                   + rig.cal_delay_s[fe0])
    delay = exact_delay
    if limits.delay_step_s > 0.0:
        delay = np.round(exact_delay / limits.delay_step_s) * limits.delay_step_s
    too_close = (active & (delay < limits.delay_min_s - 1e-18)).any(axis=-1)
    status |= np.where(too_close, Status.TOO_CLOSE, 0).astype(np.uint16)
    # A quantized delay shifts the carrier phase: give it back in the channel phase.
    carrier_hz = C0_MPS / radar.wavelength_m
    phase = (np.radians(rig.cal_phase_deg[fe0]) + 2.0 * np.pi * carrier_hz * (exact_delay - delay))
    phase = np.mod(phase + np.pi, 2.0 * np.pi) - np.pi

    doppler = np.broadcast_to(tracks.doppler_hz[..., None], (*shape, 4)).copy()
    off_range = (tracks.doppler_hz < limits.doppler_min_hz) | (
        tracks.doppler_hz > limits.doppler_max_hz)
    status |= np.where(off_range & ok, Status.DOPPLER_OUT_OF_RANGE, 0).astype(np.uint16)

    status |= _echo_slots(fe, active & ((status & BLOCKING) == 0)[..., None], tracks,
                          limits.echoes_per_channel, rig.n_front_ends)

    emitted = ((status & BLOCKING) == 0)[..., None] & active
    nan = np.nan
    return Schedule(
        t_s=tracks.t_s, frame_index=np.arange(shape[0]), names=tracks.names,
        quad=np.where(emitted.any(-1), quad, -1), fe=np.where(emitted, fe, -1),
        weight=np.where(emitted, weight, 0.0),
        attenuation_db=np.where(emitted, attenuation, nan),
        delay_s=np.where(emitted, delay, nan), doppler_hz=np.where(emitted, doppler, nan),
        phase_rad=np.where(emitted, phase, nan), active=emitted, status=status,
        angle_error_deg=np.where(emitted.any(-1)[..., None], angle_error, nan),
    )


def predicted_angle_error(resp: NDArray[np.complex128], weights: FloatArray, u: FloatArray,
                          s: FloatArray) -> FloatArray:
    """Azimuth/elevation error (deg) of the beamformer peak of ``weights`` near ``(u, s)``.

    One Newton step on ``|B|^2 / 2`` from the set direction, with the exact response and its
    derivatives ``resp`` (shape (6, 4, N)); ``weights`` is ``(N, 4)`` or ``(N, C, 4)`` for C
    candidate weight sets. Returns ``(..., 2)``.
    """
    w = weights if weights.ndim == 3 else weights[:, None, :]
    g_u, g_s, h_uu, h_us, h_ss = power_curvature(*np.einsum("tqn,ncq->tnc", resp, w))
    det = h_uu * h_ss - h_us * h_us
    det = np.where(det > 0.0, det, np.inf)  # no maximum nearby: reported as no shift
    du = -(h_ss * g_u - h_us * g_s) / det
    dsv = -(h_uu * g_s - h_us * g_u) / det
    az0, el0 = angles_from_cosines(u, s)
    az1, el1 = angles_from_cosines(u[:, None] + du, s[:, None] + dsv)
    err = np.degrees(np.stack([az1 - az0[:, None], el1 - el0[:, None]], axis=-1))
    return err if weights.ndim == 3 else err[:, 0]


def _levels(resp: NDArray[np.complex128], weights: FloatArray, single_db: FloatArray,
            n_elements: int, limits: HardwareLimits, mode: str, u: FloatArray,
            s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """Weights, channel attenuations (N, 4), predicted angle errors (N, 2) and clipping (N,).

    Clipped: a channel needed less attenuation than the attenuator's minimum (the echo stays
    too weak), or every channel needed more than its maximum (too strong).


    ``single_db`` (N, 4) is each channel's attenuation for full weight (calibration included).
    With an attenuation step the settings snap to the attenuator's grid.
    """
    gain = np.abs(np.einsum("qn,nq->n", resp[0], weights)) / n_elements
    on = weights > 0.0
    full = single_db + 20.0 * np.log10(gain)[:, None]  # attenuation at weight 1
    with np.errstate(divide="ignore"):
        exact = np.where(on, full - 20.0 * np.log10(np.where(on, weights, 1.0)), np.inf)
    step = limits.attenuation_step_db
    grid = _Grid(limits.attenuation_min_db, step, limits.attenuation_max_db)
    # A channel that needs more attenuation than the attenuator has is switched off: its
    # weight is tiny, and playing it too loud would move the angle more than leaving it out.
    chosen = grid.nearest(exact) if step > 0.0 else np.where(
        exact <= grid.high + 1e-9, np.maximum(exact, grid.low), np.inf)
    if step > 0.0 and mode == "aware":
        # Blocks keep the (entries x candidates) temporaries in cache; a wider search follows
        # only where the narrow one leaves a noticeable error.
        for reach, above in zip(SEARCH_STEPS, SEARCH_ABOVE_DEG, strict=True):
            amps = np.where(np.isfinite(chosen), 10.0 ** (-(chosen - full) / 20.0), 0.0)
            err = predicted_angle_error(resp, amps, u, s)
            todo = np.flatnonzero(np.hypot(err[:, 0], err[:, 1]) > above)
            for start in range(0, todo.size, SEARCH_BLOCK):
                b = todo[start : start + SEARCH_BLOCK]
                chosen[b] = _search_grid(resp[:, :, b], weights[b], full[b], grid, u[b],
                                         s[b], chosen[b], reach)
    # A target too weak for every channel is played as weak as possible: its strongest channel
    # at the attenuator's maximum, the others kept in proportion where they fit (the caller
    # flags it as clipped).
    dark = on.any(axis=1) & ~np.isfinite(chosen).any(axis=1)
    if dark.any():
        lifted = exact[dark] - (exact[dark].min(axis=1, keepdims=True) - grid.high)
        chosen[dark] = grid.nearest(lifted) if step > 0.0 else np.where(
            lifted <= grid.high + 1e-9, lifted, np.inf)
    new_w = np.where(np.isfinite(chosen), 10.0 ** (-(chosen - full) / 20.0), 0.0)
    top = new_w.max(axis=1, keepdims=True)
    new_w = new_w / np.where(top > 0.0, top, 1.0)
    clipped = np.asarray(dark | (on & (exact < grid.low - 1e-9)).any(axis=1), dtype=bool)
    return (new_w, np.where(np.isfinite(chosen), chosen, np.nan),
            predicted_angle_error(resp, new_w, u, s), clipped)


@dataclass(frozen=True)
class _Grid:
    """The attenuator's settings: ``low + k * step`` up to ``high``; inf means off."""

    low: float
    step: float
    high: float

    def nearest(self, att: FloatArray) -> FloatArray:
        """Nearest setting (the minimum below it; off above the maximum)."""
        snapped = self.low + np.round((att - self.low) / self.step) * self.step
        snapped = np.maximum(snapped, self.low)
        return np.where(snapped <= self.high + 1e-9, snapped, np.inf)


def _search_grid(resp: NDArray[np.complex128], weights: FloatArray, full: FloatArray,
                 grid: _Grid, u: FloatArray, s: FloatArray, naive: FloatArray,
                 reach: int) -> FloatArray:
    """Grid settings whose synthesized angle is closest to the set one.

    A linear model predicts the peak shift caused by small changes of the channel amplitudes
    (``G``, 2 x 4 per entry, from the Newton step on the exact response). A common change of
    all channels only changes the level, so the strongest channel stays at its nearest grid
    value; the next two try ``reach`` steps either side of theirs; the weakest, whose steps
    move the angle least, takes the step count that best cancels what is left (solved, then
    the two nearest counts compared). A channel that is off may come on at the weak grid level
    that best cancels the rest. The best candidates by the linear model go to the exact
    prediction, which picks the final setting (the naive one competes too, so the search never
    does worse than rounding).
    """
    n = len(weights)
    rows = np.arange(n)
    sens = _sensitivity(resp, weights) * _degree_scale(u, s)[:, :, None]  # (N, 2, 4), deg
    # A channel beyond the attenuator's range is off; it may come back below (idle stage).
    on = np.isfinite(naive)
    fine = FINE_STEPS
    steps = np.arange(-fine, fine + 1)
    # Per channel and step count: the peak shift it causes (a step beyond the range: off).
    setting = naive[:, :, None] + steps * grid.step  # (N, 4, S)
    valid = on[:, :, None] & (setting >= grid.low - 1e-9) & (setting <= grid.high + 1e-9)
    amp = np.where(on, 10.0 ** (-(np.where(on, naive, 0.0) - full) / 20.0), 0.0)
    amp = np.where(valid, amp[:, :, None] * 10.0 ** (-steps * grid.step / 20.0), 0.0)
    shift = sens[:, :, :, None] * (amp - weights[:, :, None])[:, None]  # (N, 2, 4, S)
    shift = np.where(on[:, None, :, None], shift, 0.0)
    # Roles by weight: reference (fixed), two searched, the weakest solved.
    ranked = np.argsort(-weights, axis=1)
    ref, qa, qb, qc = ranked.T
    span = np.arange(fine - reach, fine + reach + 1)
    base = shift[rows, :, ref, fine][:, :, None, None]  # (N, 2, 1, 1)
    resid = (base + shift[rows, :, qa][:, :, span][:, :, :, None]
             + shift[rows, :, qb][:, :, span][:, :, None, :]).reshape(n, 2, -1)  # (N, 2, C)
    # Weakest channel: continuous step count along its per-step direction, then both neighbours.
    table_c = shift[rows, :, qc]  # (N, 2, S)
    direction = 0.5 * (table_c[:, :, fine + 1] - table_c[:, :, fine - 1])
    dd = np.maximum((direction * direction).sum(1), 1e-300)[:, None]
    t_star = -((resid + table_c[:, :, fine][:, :, None]) * direction[:, :, None]).sum(1) / dd
    lower = np.clip(np.floor(t_star), -fine, fine).astype(np.int64)
    upper = np.clip(lower + 1, -fine, fine)
    best_k = lower
    cost = None
    for k in (lower, upper):
        moved = resid + np.take_along_axis(table_c, (k + fine)[:, None, :].repeat(2, 1), axis=2)
        c = np.hypot(moved[:, 0], moved[:, 1])
        if cost is None:
            cost, final = c, moved
        else:
            take = c < cost
            cost = np.where(take, c, cost)
            best_k = np.where(take, k, best_k)
            final = np.where(take[:, None, :], moved, final)
    assert cost is not None
    # An idle channel may come on weakly to cancel what is left along its own direction.
    extra_q = np.full(cost.shape, -1)
    extra_att = np.zeros(cost.shape)
    for q in range(4):  # the four channels of a quad
        idle = np.flatnonzero(~on[:, q])
        if idle.size == 0:
            continue
        g = sens[idle, :, q]  # (I, 2)
        r = final[idle]  # (I, 2, C)
        a_star = -(g[:, :, None] * r).sum(1) / np.maximum((g * g).sum(-1), 1e-300)[:, None]
        with np.errstate(divide="ignore"):
            att = grid.nearest(full[idle, None, q] - 20.0 * np.log10(np.maximum(a_star, 0.0)))
        a = np.where(np.isfinite(att), 10.0 ** (-(att - full[idle, None, q]) / 20.0), 0.0)
        moved = r + a[:, None, :] * g[:, :, None]
        new_cost = np.hypot(moved[:, 0], moved[:, 1])
        better = (a > 0.0) & (new_cost < cost[idle])
        cost[idle] = np.where(better, new_cost, cost[idle])
        extra_q[idle] = np.where(better, q, extra_q[idle])
        extra_att[idle] = np.where(better, att, extra_att[idle])
    # The linear model shortlists; the exact prediction decides (the naive setting included).
    keep_n = min(SHORTLIST, cost.shape[1])
    shortlist = np.argpartition(cost, keep_n - 1, axis=1)[:, :keep_n]  # (N, S)
    ia, ib = np.unravel_index(shortlist, (span.size, span.size))
    counts = np.stack([np.zeros_like(ia), span[ia] - fine, span[ib] - fine,
                       np.take_along_axis(best_k, shortlist, axis=1)], axis=-1)  # per role
    chosen = np.repeat(naive[:, None, :], keep_n, axis=1)
    for role, q in enumerate((ref, qa, qb, qc)):
        col = q[:, None]
        chosen[rows[:, None], np.arange(keep_n)[None], col] = (
            naive[rows[:, None], col] + counts[..., role] * grid.step)
    chosen = np.where(on[:, None, :] & (chosen <= grid.high + 1e-9)
                      & (chosen >= grid.low - 1e-9), chosen, np.inf)
    picked = extra_q[rows[:, None], shortlist]
    n_idx, s_idx = np.nonzero(picked >= 0)
    chosen[n_idx, s_idx, picked[n_idx, s_idx]] = extra_att[n_idx, shortlist[n_idx, s_idx]]
    options = np.concatenate([naive[:, None, :], chosen], axis=1)
    amps = np.where(np.isfinite(options), 10.0 ** (-(options - full[:, None, :]) / 20.0), 0.0)
    err = predicted_angle_error(resp, amps, u, s)
    keep = np.argmin(np.hypot(err[..., 0], err[..., 1]), axis=1)
    return options[rows, keep]


def _sensitivity(resp: NDArray[np.complex128], weights: FloatArray) -> FloatArray:
    """Peak shift in (u, s) per unit change of each channel amplitude, shape (N, 2, 4)."""
    b, b_u, b_s, b_uu, b_us, b_ss = np.einsum("tqn,nq->tn", resp, weights)
    cb = np.conj(b)
    _, _, h_uu, h_us, h_ss = power_curvature(b, b_u, b_s, b_uu, b_us, b_ss)
    det = h_uu * h_ss - h_us * h_us
    det = np.where(det > 0.0, det, np.inf)
    # d(gradient)/dw_q at a stationary point: Re(conj(B) f_q,i).
    d_u = (cb[None] * resp[1]).real.T  # (N, 4)
    d_s = (cb[None] * resp[2]).real.T
    inv = np.stack([np.stack([h_ss, -h_us], -1), np.stack([-h_us, h_uu], -1)], -2) / det[:, None,
                                                                                           None]
    return -np.einsum("nij,njq->niq", inv, np.stack([d_u, d_s], axis=1))


def _degree_scale(u: FloatArray, s: FloatArray) -> FloatArray:
    """Local degrees per unit of u and s (azimuth and elevation), shape (N, 2)."""
    az, el = angles_from_cosines(u, s)
    return np.degrees(np.stack([1.0 / (np.cos(el) * np.cos(az)), 1.0 / np.cos(el)], axis=-1))


def _echo_slots(fe: IntArray, using: BoolArray, tracks: Tracks, per_channel: int,
                n_fe: int) -> NDArray[np.uint16]:
    """NO_ECHO_SLOT where a target is not among the ``per_channel`` nearest on one of its FEs."""
    n_frames, n_targets = tracks.range_m.shape
    frame = np.broadcast_to(np.arange(n_frames)[:, None, None], fe.shape)
    target = np.broadcast_to(np.arange(n_targets)[None, :, None], fe.shape)
    sel = using.ravel()
    # Usually every channel has slots enough: one count settles it.
    load = np.bincount(frame.ravel()[sel] * n_fe + fe.ravel()[sel], minlength=1)
    if load.max(initial=0) <= per_channel:
        return np.zeros((n_frames, n_targets), dtype=np.uint16)
    f, k, q = frame.ravel()[sel], target.ravel()[sel], fe.ravel()[sel]
    rng = tracks.range_m[f, k]
    rcs = tracks.rcs_dbsm[f, k]
    # Sort by (frame, FE, range, -rcs, target); the rank within each (frame, FE) group is the
    # number of more relevant targets on that FE.
    order = np.lexsort((k, -rcs, rng, q, f))
    group = f[order] * n_fe + q[order]
    first = np.r_[True, group[1:] != group[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(group.size), 0))
    rank = np.empty(group.size, dtype=np.int64)
    rank[order] = np.arange(group.size) - start
    over = np.zeros((n_frames, n_targets), dtype=bool)
    np.logical_or.at(over, (f, k), rank >= per_channel)
    return np.where(over, Status.NO_ECHO_SLOT, 0).astype(np.uint16)


__all__ = ["Schedule", "ScheduleError", "Status", "build_schedule", "predicted_angle_error"]
