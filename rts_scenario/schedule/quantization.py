"""Attenuator quantization that keeps the synthesized angle: choose grid settings, predict errors.

With an attenuation step, each channel's attenuation is set to the grid value below or above
the exact one, choosing the combination whose synthesized angle is closest to the set angle (a
Newton step on the exact beamformer response predicts the angle of every combination); the
predicted remaining error is kept per entry. Without a step only the attenuator's range applies.
With a phase step, each channel's phase goes on the step below or above its exact phase
(`phase_settings`); the response the attenuators are fitted with, and the predicted error,
are the channels' as those phases play them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import angles_from_cosines
from ..beamformer import hessian_step, newton_step, power_curvature
from ..rig import HardwareLimits
from ..solver.compiled import mode
from ..workers import start_parts

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

QUANTIZATION_MODES = ("aware", "naive")
# Settings are computed as ``low + k * step`` or from exact levels; comparisons against the
# attenuator's limits allow this much so that rounding (of order 1e-14 dB) never turns a
# reachable setting into an unreachable one. Far below any attenuator's resolution.
GRID_SLACK_DB = 1e-9
# A level off by half a step plus this is beyond rounding (`_relevel`): the response's level
# at the set direction, not quite the peak's, and the phase shifter's turns, differ by less.
LEVEL_SLACK_DB = 0.01
# Settings whose predicted angle errors differ by less than this (deg) are alike: the simpler
# one is kept (far below any error a radar reports, far above the predictions' rounding).
ANGLE_TIE_DEG = 1e-9
# Floor on squared norms before dividing by them: a channel whose steps do not move the angle
# at all gets no step instead of a division by zero (any real norm is far larger).
NORM_FLOOR = 1e-300
# Candidates ranked best by the linear model that the exact prediction then compares: the
# linear model is good enough to rank, the exact prediction (one Newton step per candidate) is
# what costs, so only a few go on. On 3,000 random entries of each shipped array on
# kit-table1, and of the AWR1843BOOST on the 3x5 grid, a shortlist of 3 chose as well as one of
# 4, 8 or 16: the same 90th and 99th percentiles and maximum of the predicted error, rms within
# 0.00001 deg (2 loses 0.0003 deg at the 99th percentile on the AWR1843BOOST);
# tests/test_quantization_kernel.py holds it to that.
SHORTLIST = 3
# The quantization-aware search moves two channels by up to SEARCH_STEPS grid steps either side
# of their nearest setting, on the entries whose current setting errs more than
# SEARCH_ABOVE_DEG (wider passes follow for what is left), and the weakest channel by up to
# FINE_STEPS. The candidate count grows with the square of the reach, so the narrow pass runs
# on most entries and the wide one only where an error well above the first threshold is left.
# The weakest channel moves the angle least per step, so it needs the widest range.
SEARCH_STEPS = (2, 4)
SEARCH_ABOVE_DEG = (0.005, 0.03)
FINE_STEPS = 8
# Entries go in blocks of SEARCH_BLOCK: the (entries x candidates) temporaries stay in cache.
SEARCH_BLOCK = 1024
# With numba installed, searches of at least this many entries run compiled (`compiled_search`):
# loading numba and the kernel costs about what the numpy search needs for 100,000 entries.
# RTS_SCENARIO_JIT=on compiles any search, off none (`rts_scenario.solver.compiled.mode`).
COMPILED_FROM = 20_000
# Entries per compiled call at most: parts run on threads, one per core, several parts per
# thread so that a core slowed by other work does not hold the others up.
COMPILED_PART = 2048
# Entries per block of the numpy phase search (`phase_settings`): its (6, entries, 27) complex
# temporaries stay in cache.
PHASE_BLOCK = 1024


def predicted_angle_error(resp: NDArray[np.complex128], weights: FloatArray, u: FloatArray,
                          s: FloatArray) -> FloatArray:
    """Azimuth/elevation error (deg) of the beamformer peak of ``weights`` near ``(u, s)``.

    One Newton step on ``|B|^2 / 2`` from the set direction (`rts_scenario.beamformer`), with
    the exact response and its derivatives ``resp`` (shape (6, 4, N)); where the response has
    no definite curvature nearby the error is reported as zero.

    Parameters
    ----------
    resp : ndarray of complex, shape (6, 4, N)
        ``f, f_u, f_s, f_uu, f_us, f_ss`` of the quad's four channels at the set directions.
    weights : ndarray, shape (N, 4) or (N, C, 4)
        Channel amplitudes, or C candidate amplitude sets per entry; complex where a channel
        is played off its exact phase (a phase shifter's rounding: `phase_rounding`).
    u, s : ndarray, shape (N,)
        Set directions in direction cosines.

    Returns
    -------
    ndarray, shape (N, 2) or (N, C, 2)
        Predicted azimuth and elevation error in degrees.
    """
    w = weights if weights.ndim == 3 else weights[:, None, :]
    err, _ = _beam_angle_error(np.einsum("tqn,ncq->tnc", resp, w), u, s)
    return err if weights.ndim == 3 else err[:, 0]


def peak_near(resp: NDArray[np.complex128], weights: NDArray[Any], u: FloatArray,
              s: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """`predicted_angle_error` of ``weights`` (N, 4) and whether a peak is near at all.

    The second is False where ``|B|^2`` does not curve down at the set direction (its
    Hessian is not negative definite): the settings play no peak near it, and the error the
    first gives there (zero) says nothing.
    """
    err, ok = _beam_angle_error(np.einsum("tqn,nq->tn", resp, weights)[:, :, None], u, s)
    return err[:, 0], ok[:, 0]


def _beam_angle_error(beam: NDArray[np.complex128], u: FloatArray, s: FloatArray
                      ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """`predicted_angle_error` from the beamformer output and its derivatives, (6, N, C).

    Also where a peak is near (`peak_near`), shape (N, C).
    """
    du, dsv, ok = newton_step(*beam)
    az0, el0 = angles_from_cosines(u, s)
    az1, el1 = angles_from_cosines(u[:, None] + du, s[:, None] + dsv)
    return np.degrees(np.stack([az1 - az0[:, None], el1 - el0[:, None]], axis=-1)), ok


def phase_settings(resp: NDArray[np.complex128], weights: FloatArray, phase: FloatArray,
                   limits: HardwareLimits, mode: str, u: FloatArray,
                   s: FloatArray) -> FloatArray:
    """Phase shifter settings (rad, on its steps) for the exact channel phases ``phase``.

    ``"naive"``: each channel's nearest step. ``"aware"``: the strongest channel's nearest step
    (a common turn of all four channels moves no angle), the others' nearest or the step
    below or above it, the combination whose synthesized angle with the solved ``weights`` is
    closest to the set one (the exact prediction, one Newton step per combination; the
    nearest steps compete and win ties; a combination that plays no peak near the set
    direction never wins). Large searches run compiled with numba (`compiled_phase_search`,
    as `compiled_search` for the attenuators). The schedule then fits the attenuators to these
    phases and to the nearest ones and keeps the better fit (`rts_scenario.schedule.build`).
    Without a step the phases are only wrapped.

    Parameters
    ----------
    resp : ndarray of complex, shape (6, 4, N)
        Exact response of the quad's channels and its derivatives at the set directions.
    weights : ndarray, shape (N, 4)
        Solved amplitude weights (0: channel off).
    phase : ndarray, shape (N, 4)
        The exact phase (rad) each channel needs.
    """
    nearest = limits.phase_setting(phase)
    step = limits.phase_step_deg
    if step <= 0.0 or mode != "aware" or len(phase) == 0:
        return nearest
    # A common turn moves no angle: the strongest channel keeps its nearest step, the other
    # three take every combination of the step below their nearest, it and the step above.
    # (Without that, all four a step up would tie with the nearest steps, to rounding.)
    others = _OTHER_CHANNELS[np.argmax(weights, axis=1)]  # (N, 3)
    rotation = phase_rounding(nearest, phase)
    turns = np.exp(1j * np.radians(step) * np.arange(-1.0, 2.0)) - 1.0
    kernel = compiled_phase_search() if _compile_phases(len(phase)) else None
    if kernel is not None:
        best = np.empty(len(phase), dtype=np.int64)
        args = [np.ascontiguousarray(a) for a in (resp, weights, rotation, turns.real,
                                                  turns.imag, u, s)]
        start_parts(lambda first: kernel(*args, ANGLE_TIE_DEG, best, first,
                                         min(first + COMPILED_PART, len(best))),
                    range(0, len(best), COMPILED_PART))()
    else:
        # Entries go in blocks: the (6, entries, 27) temporaries stay in cache.
        best = np.concatenate([
            _best_turns(resp[:, :, b], weights[b], rotation[b], others[b], turns, u[b], s[b])
            for b in (slice(i, i + PHASE_BLOCK) for i in range(0, len(phase), PHASE_BLOCK))])
    steps = np.stack(np.unravel_index(best, (3, 3, 3)), axis=1) - 1.0  # (N, 3)
    chosen = nearest.copy()
    np.put_along_axis(chosen, others, limits.phase_setting(
        np.take_along_axis(nearest, others, axis=1) + np.radians(step) * steps), axis=1)
    return chosen


def _best_turns(resp: NDArray[np.complex128], weights: FloatArray,
                rotation: NDArray[np.complex128], others: NDArray[np.intp],
                turns: NDArray[np.complex128], u: FloatArray, s: FloatArray) -> NDArray[np.intp]:
    """`phase_settings`' choice: the combination of turns (index into (3, 3, 3)) per entry.

    Each channel's share of the beamformer output at its nearest step (``rotation``); the
    combinations' outputs are the sums of the shares, ``others`` turned by ``turns`` (the
    factors ``exp(j k step) - 1``, k = -1, 0, 1), predicted one Newton step each.
    """
    n = np.arange(len(u))
    share = resp * (weights * rotation).T[None]  # (6, 4, N)
    beam = share.sum(axis=1)[:, :, None, None, None]
    for i in range(3):  # the three channels that may move
        moved = share[:, others[:, i], n][:, :, None] * turns  # (6, N, 3)
        beam = beam + moved.reshape(*moved.shape[:2], *np.roll([3, 1, 1], i))
    beam = beam.reshape(6, len(u), -1)
    err, has_peak = _beam_angle_error(beam, u, s)
    # Settings that play no peak near the set direction predict an error of zero, which says
    # nothing: they never win.
    cost = np.where(has_peak, np.hypot(err[..., 0], err[..., 1]), np.inf)
    centre = cost.shape[1] // 2  # no channel moved: the nearest steps
    best = np.argmin(cost, axis=1)
    return np.where(cost[n, best] < cost[:, centre] - ANGLE_TIE_DEG, best, centre)


def _compile_phases(entries: int) -> bool:
    """Whether the phase search of ``entries`` runs compiled (as `_compile` decides).

    With "auto", from `COMPILED_FROM` entries on, or once a compiled search is loaded.
    """
    chosen = mode()
    if chosen != "auto":
        return chosen == "on"
    return (entries >= COMPILED_FROM or compiled_phase_search.cache_info().currsize > 0
            or compiled_search.cache_info().currsize > 0)


@lru_cache(maxsize=1)
def compiled_phase_search() -> Callable[..., None] | None:
    """Return the compiled phase search (`_search_kernel.phase_search`), or None without numba.

    Loaded as `compiled_search` is: where numba is missing or cannot compile or cache, the
    numpy search runs (it chooses the same, tests/test_phase_search.py).
    """
    try:
        from ._search_kernel import phase_search

        one = np.ones((1, 4))
        phase_search(np.ones((6, 4, 1), dtype=complex), one, one + 0j, np.zeros(3),
                     np.zeros(3), np.zeros(1), np.zeros(1), ANGLE_TIE_DEG,
                     np.empty(1, dtype=np.int64), 0, 1)
    except Exception:  # noqa: BLE001 - numba is optional: the numpy search does the same
        return None
    kernel: Callable[..., None] = phase_search
    return kernel


# The channels of a quad other than channel q, row q.
_OTHER_CHANNELS = np.array([[c for c in range(4) if c != q] for q in range(4)])


def phase_rounding(settings: FloatArray, phase: FloatArray) -> NDArray[np.complex128]:
    """Return what the phase settings do to each channel's echo: ``exp(j (setting - exact))``."""
    return np.exp(1j * (settings - phase))


def attenuator_settings(resp: NDArray[np.complex128], weights: FloatArray, full: FloatArray,
                        exact: FloatArray, limits: HardwareLimits, mode: str, u: FloatArray,
                        s: FloatArray) -> tuple[FloatArray, BoolArray]:
    """Attenuator settings for the exact channel attenuations, and where they clip.

    Parameters
    ----------
    resp : ndarray of complex, shape (6, 4, N)
        Exact response of the quad's channels and its derivatives at the set directions.
    weights : ndarray, shape (N, 4)
        Solved amplitude weights (0: channel off).
    full : ndarray, shape (N, 4)
        Each channel's attenuation (dB) at amplitude 1.
    exact : ndarray, shape (N, 4)
        The exact attenuation (dB) each channel needs; inf where it is off.
    limits : HardwareLimits
        The attenuator's range and step.
    mode : {"aware", "naive"}
        With a step: search the grid for the smallest predicted angle error, or round.
    u, s : ndarray, shape (N,)
        Set directions in direction cosines.

    Returns
    -------
    chosen : ndarray, shape (N, 4)
        Attenuation settings in dB; inf where the channel is off.
    clipped : ndarray of bool, shape (N,)
        A channel needed less attenuation than the attenuator's minimum (the echo stays too
        weak), or every channel needed more than its maximum (too strong).
    """
    return start_attenuator_settings(resp, weights, full, exact, limits, mode, u, s)()


def start_attenuator_settings(
    resp: NDArray[np.complex128], weights: FloatArray, full: FloatArray, exact: FloatArray,
    limits: HardwareLimits, mode: str, u: FloatArray, s: FloatArray,
) -> Callable[[], tuple[FloatArray, BoolArray]]:
    """Start `attenuator_settings`; return the function that waits for it and returns its result.

    The compiled search runs on the worker threads while the caller goes on (the schedule
    prepares the next quad meanwhile); without it everything is done before this returns.
    """
    on = weights > 0.0
    step = limits.attenuation_step_db
    grid = _Grid(limits.attenuation_min_db, step, limits.attenuation_max_db)
    # A channel that needs more attenuation than the attenuator has is switched off: its
    # weight is tiny, and playing it too loud would move the angle more than leaving it out.
    chosen = grid.nearest(exact) if step > 0.0 else np.where(
        exact <= grid.high + GRID_SLACK_DB, np.maximum(exact, grid.low), np.inf)
    searched: Callable[[], None] | None = None
    rounded = chosen.copy()  # each channel on its nearest setting: the level within rounding
    if step > 0.0 and mode == "aware":
        # A wider search follows only where the narrow one leaves a noticeable error.
        kernel = compiled_search() if _compile(len(weights)) else None
        if kernel is not None:  # every entry: it predicts, keeps or searches each itself
            chosen, searched = _start_search_compiled(kernel, resp, weights, full, grid, u, s,
                                                      chosen)
        for reach, above in zip(SEARCH_STEPS, SEARCH_ABOVE_DEG, strict=True):
            if kernel is not None:
                break
            amps = np.where(np.isfinite(chosen), 10.0 ** (-(chosen - full) / 20.0), 0.0)
            err = predicted_angle_error(resp, amps, u, s)
            todo = np.flatnonzero(np.hypot(err[:, 0], err[:, 1]) > above)
            for start in range(0, todo.size, SEARCH_BLOCK):
                b = todo[start : start + SEARCH_BLOCK]
                chosen[b] = _search_grid(resp[:, :, b], weights[b], full[b], grid, u[b],
                                         s[b], chosen[b], reach)

    def finish() -> tuple[FloatArray, BoolArray]:
        if searched is not None:
            searched()
        # Off the level wanted by more than rounding where the range held the shift back.
        off_level = np.zeros(len(weights), dtype=bool)
        if step > 0.0 and mode == "aware":
            # Only where the search moved a setting: rounding alone leaves half a step at most.
            moved = chosen != rounded  # inf (off) equals inf
            rows = np.flatnonzero(moved[:, 0] | moved[:, 1] | moved[:, 2] | moved[:, 3])
            part = chosen[rows]
            off_level[rows] = _relevel(resp[0][:, rows], weights[rows], part, full[rows], grid)
            chosen[rows] = part
        # A target too weak for every channel is played as weak as possible: its strongest
        # channel at the attenuator's maximum, the others kept in proportion where they fit
        # (flagged as clipped).
        dark = on.any(axis=1) & ~np.isfinite(chosen).any(axis=1)
        if dark.any():
            lifted = exact[dark] - (exact[dark].min(axis=1, keepdims=True) - grid.high)
            chosen[dark] = grid.nearest(lifted) if step > 0.0 else np.where(
                lifted <= grid.high + GRID_SLACK_DB, lifted, np.inf)
        # Louder than the attenuator's minimum by more than its rounding (half a step): a
        # shortfall within it is the rounding every setting has, not a clipped level.
        short = grid.low - step / 2.0 - GRID_SLACK_DB
        clipped = np.asarray(dark | off_level | (on & (exact < short)).any(axis=1), dtype=bool)
        return chosen, clipped

    return finish


def _relevel(f: NDArray[np.complex128], weights: FloatArray, chosen: FloatArray,
             full: FloatArray, grid: _Grid) -> BoolArray:
    """Shift each entry's settings by whole steps, all alike, to the level its weights give.

    The search (`_search_grid`) holds the angle, and its settings may play the peak several
    steps louder or weaker than wanted (the others' changes move the level too). A common
    change of every channel leaves the angle as it is and moves the level by the same steps:
    taken as far as the attenuator's range allows, it leaves at most half a step, as rounding
    each channel does. ``f`` (4, N): the channels' responses at the set directions; ``chosen``
    is changed in place. Returns the entries the range kept more than half a step off the level
    (a channel at the attenuator's minimum or maximum held the shift back).
    """
    on = np.isfinite(chosen)
    amps = np.exp((full - chosen) * (np.log(10.0) / 20.0))  # 0 where off (inf)
    played = np.abs(np.einsum("qn,nq->n", f, amps))
    wanted = np.abs(np.einsum("qn,nq->n", f, weights))
    fine = (played > 0.0) & (wanted > 0.0)
    level_db = 20.0 * np.log10(np.where(fine, played, 1.0) / np.where(fine, wanted, 1.0))
    steps = np.round(level_db / grid.step)
    # Every channel that plays stays within the attenuator's range (per column: a reduction
    # over rows of four is several times slower).
    high, low = np.where(on, chosen, -np.inf).T, np.where(on, chosen, np.inf).T
    top = np.maximum(np.maximum(high[0], high[1]), np.maximum(high[2], high[3]))
    bottom = np.minimum(np.minimum(low[0], low[1]), np.minimum(low[2], low[3]))
    most = np.floor((grid.high + GRID_SLACK_DB - top) / grid.step)
    least = np.ceil((grid.low - GRID_SLACK_DB - bottom) / grid.step)
    shift = np.where(fine, np.clip(steps, np.minimum(least, 0.0), np.maximum(most, 0.0)), 0.0)
    chosen += np.where(on, shift[:, None] * grid.step, 0.0)
    left_db = np.abs(level_db - shift * grid.step)
    return np.asarray(fine & (left_db > grid.step / 2.0 + LEVEL_SLACK_DB), dtype=bool)


@dataclass(frozen=True)
class _Grid:
    """The attenuator's settings: ``low + k * step`` up to ``high``; inf means off."""

    low: float
    step: float
    high: float

    def nearest(self, att: FloatArray) -> FloatArray:
        """Nearest setting (the minimum below it; off above the maximum).

        Where the range is not a whole number of steps, its top setting is the last step below
        the maximum, and a level up to the maximum, or within half a step of that setting,
        plays there (not off: a channel a little too loud moves the angle less than none).
        """
        top = self.low + np.floor((self.high - self.low) / self.step + 1e-9) * self.step
        snapped = self.low + np.round((att - self.low) / self.step) * self.step
        snapped = np.maximum(snapped, self.low)
        within = att <= max(top + self.step / 2.0, self.high) + GRID_SLACK_DB
        return np.where(within, np.minimum(snapped, top), np.inf)

    def holds(self, att: FloatArray) -> BoolArray:
        """Return where the settings lie within the attenuator's range."""
        return np.asarray((att >= self.low - GRID_SLACK_DB) & (att <= self.high + GRID_SLACK_DB),
                          dtype=bool)


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
    per_step = 10.0 ** (-steps * grid.step / 20.0)  # amplitude factor of k steps
    amp = np.where(on, 10.0 ** (-(np.where(on, naive, 0.0) - full) / 20.0), 0.0)
    # Roles by weight: reference (fixed), two searched, the weakest solved.
    ranked = np.argsort(-weights, axis=1)
    ref, qa, qb, qc = ranked.T

    def shifts(q: NDArray[np.int64], k: NDArray[np.int64]) -> FloatArray:
        """Peak shift (N, 2, len(k)) of channel q moved k steps (beyond the range: off)."""
        setting = naive[rows, q][:, None] + steps[k] * grid.step
        valid = on[rows, q][:, None] & grid.holds(setting)
        moved = np.where(valid, amp[rows, q][:, None] * per_step[k], 0.0)
        change = np.where(on[rows, q][:, None], moved - weights[rows, q][:, None], 0.0)
        return sens[rows, :, q][:, :, None] * change[:, None, :]

    span = np.arange(fine - reach, fine + reach + 1)
    base = shifts(ref, np.array([fine]))[:, :, :, None]  # (N, 2, 1, 1)
    resid = (base + shifts(qa, span)[:, :, :, None]
             + shifts(qb, span)[:, :, None, :]).reshape(n, 2, -1)  # (N, 2, C)
    # Weakest channel: continuous step count along its per-step direction, then both neighbours.
    table_c = shifts(qc, np.arange(steps.size))  # (N, 2, S)
    direction = 0.5 * (table_c[:, :, fine + 1] - table_c[:, :, fine - 1])
    dd = np.maximum((direction * direction).sum(1), NORM_FLOOR)[:, None]
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
        a_star = -(g[:, :, None] * r).sum(1) / np.maximum((g * g).sum(-1), NORM_FLOOR)[:, None]
        with np.errstate(divide="ignore"):
            att = grid.nearest(full[idle, None, q] - 20.0 * np.log10(np.maximum(a_star, 0.0)))
        a = np.where(np.isfinite(att), 10.0 ** (-(att - full[idle, None, q]) / 20.0), 0.0)
        moved = r + a[:, None, :] * g[:, :, None]
        new_cost = np.hypot(moved[:, 0], moved[:, 1])
        better = (a > 0.0) & (new_cost < cost[idle])
        cost[idle] = np.where(better, new_cost, cost[idle])
        extra_q[idle] = np.where(better, q, extra_q[idle])
        extra_att[idle] = np.where(better, att, extra_att[idle])
    # A searched channel that is off stays off: its candidates are all alike, so only its
    # centre one competes (the shortlist then holds distinct settings).
    ia_all, ib_all = np.unravel_index(np.arange(cost.shape[1]), (span.size, span.size))
    centre = span.size // 2
    cost[(~on[rows, qa])[:, None] & (ia_all != centre)[None, :]] = np.inf
    cost[(~on[rows, qb])[:, None] & (ib_all != centre)[None, :]] = np.inf
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
    chosen = np.where(on[:, None, :] & grid.holds(chosen), chosen, np.inf)
    picked = extra_q[rows[:, None], shortlist]
    n_idx, s_idx = np.nonzero(picked >= 0)
    chosen[n_idx, s_idx, picked[n_idx, s_idx]] = extra_att[n_idx, shortlist[n_idx, s_idx]]
    options = np.concatenate([naive[:, None, :], chosen], axis=1)
    amps = np.where(np.isfinite(options), 10.0 ** (-(options - full[:, None, :]) / 20.0), 0.0)
    err = predicted_angle_error(resp, amps, u, s)
    keep = np.argmin(np.hypot(err[..., 0], err[..., 1]), axis=1)
    return options[rows, keep]


_searched = [0]  # entries this process has searched, towards COMPILED_FROM


def _compile(entries: int) -> bool:
    """Whether a search of ``entries`` runs compiled (``RTS_SCENARIO_JIT``, the searches so far).

    With "auto", once the process has searched `COMPILED_FROM` entries (or loaded the kernel).
    """
    chosen = mode()
    if chosen != "auto":
        return chosen == "on"
    _searched[0] += entries
    return _searched[0] >= COMPILED_FROM or compiled_search.cache_info().currsize > 0


@lru_cache(maxsize=1)
def compiled_search() -> Callable[..., None] | None:
    """Return the compiled search (`_search_kernel.search`), or None without numba.

    Loaded on first use; numba caches the machine code on disk, so later processes skip the
    compilation. Where numba is missing or cannot compile or cache, the numpy search runs.
    """
    try:
        from ._search_kernel import search

        # Compile (or load from numba's cache) now, on one entry: a machine where numba
        # cannot compile or cache keeps the numpy search instead of failing a run.
        one = np.zeros((1, 4))
        search(np.ones((6, 4, 1), dtype=complex), one + 1.0, one, one, np.zeros(1),
               np.zeros(1), np.array([1]), np.array([0.0]), 0.0, 0.5, 60.0, GRID_SLACK_DB,
               FINE_STEPS, SHORTLIST, NORM_FLOOR, np.empty((1, 4)), np.empty(1), 0, 1)
    except Exception:  # noqa: BLE001 - numba is optional: the numpy search does the same
        return None
    kernel: Callable[..., None] = search
    return kernel


def _start_search_compiled(
    kernel: Callable[..., None], resp: NDArray[np.complex128], weights: FloatArray,
    full: FloatArray, grid: _Grid, u: FloatArray, s: FloatArray, naive: FloatArray,
) -> tuple[FloatArray, Callable[[], None]]:
    """Start both passes of `_search_grid`, compiled, entry by entry (parts on threads).

    Returns the array the settings are written into and the function that waits for them.
    """
    out = np.empty_like(naive)
    error = np.empty(len(naive))
    # resp stays as it is, (6, 4, N): the kernel reads each entry's 24 values from 24 rows.
    args = [np.ascontiguousarray(a) for a in (resp, weights, full, naive, u, s)]
    reaches = np.array(SEARCH_STEPS, dtype=np.int64)
    aboves = np.array(SEARCH_ABOVE_DEG, dtype=np.float64)

    def run(first: int) -> None:  # the kernel releases the GIL: parts run on all cores
        kernel(*args, reaches, aboves, grid.low, grid.step, grid.high, GRID_SLACK_DB,
               FINE_STEPS, SHORTLIST, NORM_FLOOR, out, error, first,
               min(first + COMPILED_PART, len(out)))

    return out, start_parts(run, range(0, len(out), COMPILED_PART))


def _sensitivity(resp: NDArray[np.complex128], weights: FloatArray) -> FloatArray:
    """Peak shift in (u, s) per unit change of each channel amplitude, shape (N, 2, 4)."""
    b, b_u, b_s, b_uu, b_us, b_ss = np.einsum("tqn,nq->tn", resp, weights)
    cb = np.conj(b)
    _, _, h_uu, h_us, h_ss = power_curvature(b, b_u, b_s, b_uu, b_us, b_ss)
    # d(gradient)/dw_q at a stationary point: Re(conj(B) f_q,i); the peak moves by the Newton
    # step of that gradient change.
    d_u = (cb[None] * resp[1]).real.T  # (N, 4)
    d_s = (cb[None] * resp[2]).real.T
    du, ds, _ = hessian_step(d_u, d_s, h_uu[:, None], h_us[:, None], h_ss[:, None])
    return np.stack([du, ds], axis=1)


def _degree_scale(u: FloatArray, s: FloatArray) -> FloatArray:
    """Local degrees per unit of u and s (azimuth and elevation), shape (N, 2)."""
    az, el = angles_from_cosines(u, s)
    return np.degrees(np.stack([1.0 / (np.cos(el) * np.cos(az)), 1.0 / np.cos(el)], axis=-1))


__all__ = ["QUANTIZATION_MODES", "attenuator_settings", "phase_rounding", "phase_settings",
           "predicted_angle_error", "start_attenuator_settings"]
