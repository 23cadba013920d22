"""Compiled quantization-aware search (numba): `quantization._search_grid`, entry by entry.

Imported only when numba is installed and the search first runs (`quantization`), so
``import rts_scenario`` never pays for it. Each step mirrors the numpy search: the linear model
of the peak shift per channel step, the reference channel fixed, two channels over ``reach``
steps, the weakest solved, an idle channel brought in weakly, the best ``shortlist`` by the
linear model, then the exact prediction (one Newton step on the response) picking among them
and the naive setting. tests/test_quantization_kernel.py compares the two.

It skips only work whose outcome is known, so it chooses as the numpy search does: an idle
channel is priced only for candidates that could then enter the shortlist (its best
continuous level is a bound); an option already predicted is not predicted again; a pass whose
candidates are the last pass's, from the same settings, is not run. Amplitudes of grid
settings come from tables, and the angle changes from the sines of the differences.

`phase_search` is the phase shifter's search (`quantization.phase_settings`): the 27
combinations of turns, each predicted in real arithmetic from partial sums of the channels'
shares; it chooses as the numpy search does where the predictions do not tie to rounding
(tests/test_phase_search.py).

Constants are arguments, not globals: numba freezes globals into its cached machine code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# An amplitude ratio of x dB is exp(x * DB_TO_NEPER): ln(10) / 20.
DB_TO_NEPER = math.log(10.0) / 20.0


@njit(cache=True, nogil=True, error_model="numpy")
def _angles(u, s):  # pragma: no cover
    """`arrays.angles_from_cosines` for one direction: ``(az_rad, el_rad)``."""
    s = min(max(s, -1.0), 1.0)
    el = math.asin(s)
    cos_el = math.sqrt(1.0 - s * s)
    az = math.atan2(u, math.sqrt(max(cos_el * cos_el - u * u, 0.0)))
    return az, el


@njit(cache=True, nogil=True, error_model="numpy")
def _asin_small(x):  # pragma: no cover
    """``asin x``: its series where ``|x| <= 0.02`` (the next term is 1e-22 of it), else libm."""
    if not abs(x) <= 0.02:
        return math.asin(x)
    x2 = x * x
    return x * (1.0 + x2 * (1.0 / 6.0 + x2 * (3.0 / 40.0 + x2 * (5.0 / 112.0 + x2 * (
        35.0 / 1152.0 + x2 * (63.0 / 2816.0))))))


@njit(cache=True, nogil=True, error_model="numpy")
def _direction(u, s):  # pragma: no cover
    """Return the set direction for `_error`: az, el (rad), sin and cos of both."""
    az, el = _angles(u, s)
    cos_el = math.sqrt(1.0 - s * s)
    sin_az = u / cos_el
    return az, el, sin_az, math.sqrt(1.0 - sin_az * sin_az), s, cos_el


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _beam(resp, i, t, a0, a1, a2, a3):  # pragma: no cover
    """``(Re, Im)`` of B (``t = 0``) or one of its derivatives: the responses, weighted.

    Real arithmetic (the amplitudes are real): a third of a complex product's work, the same
    values. Inlined by numba.
    """
    r0, r1, r2, r3 = resp[t, 0, i], resp[t, 1, i], resp[t, 2, i], resp[t, 3, i]
    return (r0.real * a0 + r1.real * a1 + r2.real * a2 + r3.real * a3,
            r0.imag * a0 + r1.imag * a1 + r2.imag * a2 + r3.imag * a3)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _curvature(resp, i, a0, a1, a2, a3):  # pragma: no cover
    """B, its first derivatives and the Hessian of ``|B|^2 / 2`` for amplitudes ``a0..a3``.

    ``(b, b_u, b_s, h_uu, h_us, h_ss)`` with ``b, b_u, b_s`` as ``(Re, Im)`` pairs.
    """
    b = _beam(resp, i, 0, a0, a1, a2, a3)
    b_u = _beam(resp, i, 1, a0, a1, a2, a3)
    b_s = _beam(resp, i, 2, a0, a1, a2, a3)
    b_uu = _beam(resp, i, 3, a0, a1, a2, a3)
    b_us = _beam(resp, i, 4, a0, a1, a2, a3)
    b_ss = _beam(resp, i, 5, a0, a1, a2, a3)
    # Re(conj(x) y) = x.re y.re + x.im y.im
    h_uu = (b[0] * b_uu[0] + b[1] * b_uu[1]) + b_u[0] * b_u[0] + b_u[1] * b_u[1]
    h_us = (b[0] * b_us[0] + b[1] * b_us[1]) + (b_u[0] * b_s[0] + b_u[1] * b_s[1])
    h_ss = (b[0] * b_ss[0] + b[1] * b_ss[1]) + b_s[0] * b_s[0] + b_s[1] * b_s[1]
    return b, b_u, b_s, h_uu, h_us, h_ss


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _error(resp, i, amps, u, s, direction):  # pragma: no cover
    """Predicted angle error (deg, norm of az and el) of channel amplitudes ``amps``.

    ``direction``: `_direction` of the set direction ``(u, s)``. The angles' changes come
    from the sines of the differences (``sin(a1 - a0) = sin a1 cos a0 - cos a1 sin a0``): no
    arcsine or arctangent of the angles themselves, the same values to rounding.
    """
    b, b_u, b_s, h_uu, h_us, h_ss = _curvature(resp, i, amps[0], amps[1], amps[2], amps[3])
    g_u = b[0] * b_u[0] + b[1] * b_u[1]
    g_s = b[0] * b_s[0] + b[1] * b_s[1]
    det = h_uu * h_ss - h_us * h_us
    du = ds = 0.0
    if det > 0.0:
        du = -(h_ss * g_u - h_us * g_s) / det
        ds = -(h_uu * g_s - h_us * g_u) / det
    az0, el0, sin_az0, cos_az0, sin_el0, cos_el0 = direction
    s1 = s + ds
    u1 = u + du
    cos_el1 = math.sqrt(1.0 - s1 * s1)  # NaN beyond the sphere: the exact path below
    sin_az1 = u1 / cos_el1
    cos_az1 = math.sqrt(1.0 - sin_az1 * sin_az1)
    d_el = _asin_small(s1 * cos_el0 - cos_el1 * sin_el0)
    d_az = _asin_small(sin_az1 * cos_az0 - cos_az1 * sin_az0)
    if not (abs(d_el) <= 0.02 and abs(d_az) <= 0.02):  # far off (or beyond the sphere)
        az1, el1 = _angles(u1, s1)
        d_az, d_el = az1 - az0, el1 - el0
    return math.degrees(math.sqrt(d_az * d_az + d_el * d_el))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sensitivity(resp, i, weights, direction, out):  # pragma: no cover
    """`quantization._sensitivity` times `_degree_scale` for entry ``i`` into ``out`` (2, 4).

    The peak shift in degrees (azimuth, elevation) per unit change of each channel's amplitude,
    from the Newton step of the gradient's change at the solved weights. ``direction``:
    `_direction` of the set direction.
    """
    b, _, _, h_uu, h_us, h_ss = _curvature(resp, i, weights[i, 0], weights[i, 1],
                                           weights[i, 2], weights[i, 3])
    det = h_uu * h_ss - h_us * h_us
    cos_az, cos_el = direction[3], direction[5]
    deg_u = math.degrees(1.0 / (cos_el * cos_az))
    deg_s = math.degrees(1.0 / cos_el)
    for q in range(4):
        d_u = b[0] * resp[1, q, i].real + b[1] * resp[1, q, i].imag  # Re(conj(B) f_u,q)
        d_s = b[0] * resp[2, q, i].real + b[1] * resp[2, q, i].imag
        if det > 0.0:
            out[0, q] = -(h_ss * d_u - h_us * d_s) / det * deg_u
            out[1, q] = -(h_uu * d_s - h_us * d_u) / det * deg_s
        else:
            out[0, q] = 0.0
            out[1, q] = 0.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _shift(on, naive, amp, factor, weight, sens_u, sens_s, offset, low, high,
           slack):  # pragma: no cover
    """Peak shift of one channel moved ``offset`` dB from its naive setting.

    Beyond the attenuator's range the channel goes off; a channel that is off stays so.
    """
    if not on:
        return 0.0, 0.0
    setting = naive + offset
    valid = setting >= low - slack and setting <= high + slack
    change = (amp * factor if valid else 0.0) - weight
    return sens_u * change, sens_s * change


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _same(a, b):  # pragma: no cover
    return a[0] == b[0] and a[1] == b[1] and a[2] == b[2] and a[3] == b[3]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _kth_smallest(cost, n, k, top):  # pragma: no cover
    """Write the indices of the ``k`` smallest of ``cost[:n]`` into ``top[:k]``, smallest first.

    Returns the k-th smallest cost (inf when ``n < k``). Ties keep the lower index first; NaN
    counts as infinite (last, as numpy's partition puts it), so it never takes a place from a
    number.
    """
    filled = 0
    for c in range(n):
        value = cost[c] if cost[c] == cost[c] else math.inf
        if filled == k and not value < _finite_or_inf(cost[top[k - 1]]):
            continue
        j = filled if filled < k else k - 1
        while j > 0 and value < _finite_or_inf(cost[top[j - 1]]):
            top[j] = top[j - 1]
            j -= 1
        top[j] = c
        if filled < k:
            filled += 1
    return _finite_or_inf(cost[top[k - 1]]) if filled == k else math.inf


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _finite_or_inf(x):  # pragma: no cover
    """``x``, or inf for NaN (the ordering `_kth_smallest` uses)."""
    return x if x == x else math.inf


@njit(cache=True, nogil=True, error_model="numpy")
def search(resp, weights, full, naive, u, s, reaches, aboves, low, step, high, slack, fine,
           shortlist, norm_floor, out, out_error, first, stop):  # pragma: no cover
    """Write every entry's chosen settings and their predicted angle error.

    Pass p searches ``reaches[p]`` steps either side where the settings so far err by more
    than ``aboves[p]`` degrees (the first pass starts from ``naive``); the others keep them.
    ``out`` (N, 4) gets the settings (inf where off), ``out_error`` (N,) the error in degrees.
    ``resp`` (6, 4, N) complex (as `SourceResponse.evaluate` gives it), ``weights``, ``full``,
    ``naive`` (N, 4), ``u``, ``s`` (N,). Entries ``first <= i < stop`` are searched (a part of
    the arrays, without copying or slicing them).
    """
    n_steps = 2 * fine + 1
    most = 2 * reaches.max() + 1
    per_step = np.empty(n_steps)
    for k in range(n_steps):
        per_step[k] = 10.0 ** (-(k - fine) * step / 20.0)
    on = np.empty(4, dtype=np.bool_)
    amp = np.empty(4)
    order = np.empty(4, dtype=np.int64)
    resid = np.empty((most * most, 2))
    moves = np.empty((4, n_steps, 2))
    cost = np.empty(most * most)
    final = np.empty((most * most, 2))
    best_k = np.empty(most * most, dtype=np.int64)
    extra_q = np.empty(most * most, dtype=np.int64)
    extra_att = np.empty(most * most)
    extra_amp = np.empty(most * most)
    top = np.empty(shortlist, dtype=np.int64)
    tried = np.empty((shortlist * reaches.size, 4))
    best_amp = np.empty(4)
    prev_start = np.empty(4)
    dn = step * DB_TO_NEPER
    n_levels = int(math.floor((high - low) / step + 1e-6)) + 2
    level_amp = np.empty(n_levels)
    for k in range(n_levels):
        level_amp[k] = math.exp(-k * dn)
    option = np.empty(4)
    amps = np.empty(4)
    best = np.empty(4)
    sens = np.empty((2, 4))
    start = np.empty(4)
    for i in range(first, stop):
        for q in range(4):
            best[q] = naive[i, q]
            best_amp[q] = (math.exp((full[i, q] - best[q]) * DB_TO_NEPER)
                           if math.isfinite(best[q]) else 0.0)
        direction = _direction(u[i], s[i])
        best_err = _error(resp, i, best_amp, u[i], s[i], direction)
        have_sens = False
        n_tried = 0  # options predicted so far (none is predicted twice)
        single = False  # the last pass had one candidate per searched channel
        for p in range(reaches.size):
            if not best_err > aboves[p]:  # close enough already (or not predictable): kept
                continue
            if not have_sens:  # sensitivities and roles depend on the solved weights only
                _sensitivity(resp, i, weights, direction, sens)
                have_sens = True
                # Roles by weight, strongest first (a stable sort, as numpy's for four entries).
                for q in range(4):
                    order[q] = q
                for a in range(1, 4):
                    j = a
                    while j > 0 and -weights[i, order[j]] < -weights[i, order[j - 1]]:
                        order[j], order[j - 1] = order[j - 1], order[j]
                        j -= 1
            reach = reaches[p]
            # This pass starts from the settings so far.
            for q in range(4):
                on[q] = math.isfinite(best[q])
                amp[q] = best_amp[q]
                start[q] = best[q]
            # A searched channel that is off stays off: one candidate for it, not 2 reach + 1.
            reach_a = reach if on[order[1]] else 0
            reach_b = reach if on[order[2]] else 0
            side_b = 2 * reach_b + 1
            n_cand = (2 * reach_a + 1) * side_b
            if n_cand == 1 and single and _same(start, prev_start):
                continue  # the last pass's candidates from the same settings: nothing new
            single = n_cand == 1
            for q in range(4):
                prev_start[q] = start[q]
            # Per role and step count: the peak shift it causes (where a candidate uses it).
            for role in range(4):
                q = order[role]
                span = (0, reach_a, reach_b, fine)[role]
                for k in range(fine - span, fine + span + 1):
                    moves[role, k, 0], moves[role, k, 1] = _shift(
                        on[q], start[q], amp[q], per_step[k], weights[i, q], sens[0, q],
                        sens[1, q], (k - fine) * step, low, high, slack)
            for ia in range(2 * reach_a + 1):
                for ib in range(side_b):
                    for axis in range(2):
                        resid[ia * side_b + ib, axis] = (moves[0, fine, axis]
                                                         + moves[1, fine - reach_a + ia, axis]
                                                         + moves[2, fine - reach_b + ib, axis])
            table = moves[3]
            d0 = 0.5 * (table[fine + 1, 0] - table[fine - 1, 0])
            d1 = 0.5 * (table[fine + 1, 1] - table[fine - 1, 1])
            dd = max(d0 * d0 + d1 * d1, norm_floor)
            for c in range(n_cand):
                t_star = -((resid[c, 0] + table[fine, 0]) * d0
                           + (resid[c, 1] + table[fine, 1]) * d1) / dd
                lower = int(min(max(np.floor(t_star), -fine), fine))  # a float until clipped
                upper = min(max(lower + 1, -fine), fine)
                m0 = resid[c, 0] + table[lower + fine, 0]
                m1 = resid[c, 1] + table[lower + fine, 1]
                cost[c] = m0 * m0 + m1 * m1  # squared: compared, never reported
                final[c, 0], final[c, 1] = m0, m1
                best_k[c] = lower
                m0 = resid[c, 0] + table[upper + fine, 0]
                m1 = resid[c, 1] + table[upper + fine, 1]
                if m0 * m0 + m1 * m1 < cost[c]:
                    cost[c] = m0 * m0 + m1 * m1
                    final[c, 0], final[c, 1] = m0, m1
                    best_k[c] = upper
                extra_q[c] = -1
                extra_att[c] = 0.0
            # An idle channel may come on weakly to cancel what is left along its own direction.
            # Only candidates that could then enter the shortlist are priced: at best the
            # channel cancels the residual's component along its direction (``bound``), so a
            # candidate whose bound is no better than the shortlist's worst keeps its cost.
            for q in range(4):
                if on[q]:
                    continue
                g0, g1 = sens[0, q], sens[1, q]
                gg = max(g0 * g0 + g1 * g1, norm_floor)
                worst = _kth_smallest(cost, n_cand, shortlist, top)
                # The grid level nearest (in dB) to amplitude a: k = rint(base - ln(a) / dn).
                base = (full[i, q] - low) / step
                a_low = math.exp((full[i, q] - low) * DB_TO_NEPER)
                for c in range(n_cand):
                    along = g0 * final[c, 0] + g1 * final[c, 1]
                    if along >= 0.0 or cost[c] - along * along / gg >= worst:
                        continue
                    a_star = -along / gg
                    k = np.rint(base - math.log(a_star) / dn)
                    k = max(k, 0.0)
                    if low + k * step > high + slack:
                        continue
                    a = a_low * level_amp[int(k)]
                    m0, m1 = final[c, 0] + a * g0, final[c, 1] + a * g1
                    new_cost = m0 * m0 + m1 * m1
                    if new_cost < cost[c]:
                        cost[c] = new_cost
                        extra_q[c] = q
                        extra_att[c] = low + k * step
                        extra_amp[c] = a
            # The linear model shortlists; the exact prediction decides (the naive one too).
            n_short = min(shortlist, n_cand)
            _kth_smallest(cost, n_cand, n_short, top)
            for j in range(n_short):
                pick = top[j]
                counts = (0, pick // side_b - reach_a, pick % side_b - reach_b, best_k[pick])
                for role in range(4):
                    q = order[role]
                    setting = start[q] + counts[role] * step
                    ok = on[q] and setting >= low - slack and setting <= high + slack
                    option[q] = setting if ok else math.inf
                    amps[q] = amp[q] * per_step[counts[role] + fine] if ok else 0.0
                if extra_q[pick] >= 0:
                    option[extra_q[pick]] = extra_att[pick]
                    amps[extra_q[pick]] = extra_amp[pick]
                # The settings this pass started from (their error is known), or an option
                # already predicted (off channels make candidates alike): skipped.
                seen = _same(option, start)
                for prev in range(n_tried):
                    seen = seen or _same(option, tried[prev])
                if seen:
                    continue
                for q in range(4):
                    tried[n_tried, q] = option[q]
                n_tried += 1
                err = _error(resp, i, amps, u[i], s[i], direction)
                if err < best_err:
                    best_err = err
                    for q in range(4):
                        best[q] = option[q]
                        best_amp[q] = amps[q]
        for q in range(4):
            out[i, q] = best[q]
        out_error[i] = best_err


@njit(cache=True, nogil=True, error_model="numpy")
def phase_search(resp, weights, rotation, turns_re, turns_im, u, s, tie, out,
                 first, stop):  # pragma: no cover
    """`quantization.phase_settings`' choice, entry by entry: ``out[i]`` the combination.

    ``rotation`` (N, 4) complex: each channel's turn at its nearest step,
    ``exp(j (nearest - exact))``; ``turns_re``, ``turns_im`` (3,): ``exp(j k step) - 1`` for
    ``k = -1, 0, 1``. ``out`` (N,) gets the index of the chosen combination of the three
    channels other than the strongest (``(k_a + 1) * 9 + (k_b + 1) * 3 + k_c + 1``, 13: the
    nearest steps). Each combination's beam is the nearest steps' beam plus the turned
    channels' shares, in real arithmetic; its predicted error is `_error`'s (one Newton step,
    the angle change from the sines of the differences), inf where it plays no peak.
    """
    share_re = np.empty((6, 4))
    share_im = np.empty((6, 4))
    moved_re = np.empty((3, 6, 3))
    moved_im = np.empty((3, 6, 3))
    beam_re = np.empty(6)
    beam_im = np.empty(6)
    part_re = np.empty((3, 6))
    part_im = np.empty((3, 6))
    others = np.empty(3, dtype=np.int64)
    du = np.empty(27)
    ds = np.empty(27)
    peak = np.empty(27, dtype=np.bool_)
    near = np.empty(27, dtype=np.bool_)
    cost = np.empty(27)
    for i in range(first, stop):
        strong = 0
        for q in range(1, 4):
            if weights[i, q] > weights[i, strong]:
                strong = q
        j = 0
        for q in range(4):
            if q != strong:
                others[j] = q
                j += 1
        for q in range(4):
            rot = rotation[i, q] * weights[i, q]
            for t in range(6):
                v = resp[t, q, i] * rot
                share_re[t, q] = v.real
                share_im[t, q] = v.imag
        for t in range(6):
            beam_re[t] = share_re[t, 0] + share_re[t, 1] + share_re[t, 2] + share_re[t, 3]
            beam_im[t] = share_im[t, 0] + share_im[t, 1] + share_im[t, 2] + share_im[t, 3]
        for a in range(3):
            q = others[a]
            for t in range(6):
                for k in range(3):
                    moved_re[a, t, k] = share_re[t, q] * turns_re[k] - share_im[t, q] * turns_im[k]
                    moved_im[a, t, k] = share_re[t, q] * turns_im[k] + share_im[t, q] * turns_re[k]
        # Each combination's Newton step (the sums in the order ((beam + a) + b) + c).
        for ka in range(3):
            for t in range(6):
                part_re[0, t] = beam_re[t] + moved_re[0, t, ka]
                part_im[0, t] = beam_im[t] + moved_im[0, t, ka]
            for kb in range(3):
                for t in range(6):
                    part_re[1, t] = part_re[0, t] + moved_re[1, t, kb]
                    part_im[1, t] = part_im[0, t] + moved_im[1, t, kb]
                for kc in range(3):
                    for t in range(6):
                        part_re[2, t] = part_re[1, t] + moved_re[2, t, kc]
                        part_im[2, t] = part_im[1, t] + moved_im[2, t, kc]
                    _newton(part_re, part_im, ka * 9 + kb * 3 + kc, du, ds, peak)
        # The angle changes of all 27 (branch-free: numba vectorizes it), the sines of the
        # differences through `_asin_small`'s series; beyond its range the exact path.
        direction = _direction(u[i], s[i])
        az0, el0, sin_az0, cos_az0, sin_el0, cos_el0 = direction
        for c in range(27):
            s1 = s[i] + ds[c]
            u1 = u[i] + du[c]
            cos_el1 = math.sqrt(1.0 - s1 * s1)
            sin_az1 = u1 / cos_el1
            cos_az1 = math.sqrt(1.0 - sin_az1 * sin_az1)
            x_el = s1 * cos_el0 - cos_el1 * sin_el0
            x_az = sin_az1 * cos_az0 - cos_az1 * sin_az0
            d_el = _series_asin(x_el)
            d_az = _series_asin(x_az)
            near[c] = ((abs(x_el) <= 0.02) & (abs(x_az) <= 0.02) & (abs(d_el) <= 0.02)
                       & (abs(d_az) <= 0.02))  # False for NaN
            cost[c] = d_az * d_az + d_el * d_el
        best = 13
        best_cost = math.inf
        centre_cost = math.inf
        for c in range(27):
            h = math.inf
            if peak[c]:
                h = cost[c]
                if not near[c]:  # far off (or beyond the sphere)
                    h = _far_error(u[i] + du[c], s[i] + ds[c], direction)
            if c == 13:
                centre_cost = h
            if h < best_cost:
                best_cost = h
                best = c
        best_deg = math.degrees(math.sqrt(best_cost))
        out[i] = best if best_deg < math.degrees(math.sqrt(centre_cost)) - tie else 13


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _newton(re, im, c, du, ds, peak):  # pragma: no cover
    """Newton step of the beam ``re[2] + j im[2]`` (B and its derivatives) into ``du[c], ds[c]``.

    ``peak[c]``: whether ``|B|^2`` curves down there (else the step says nothing).
    """
    r0, r1, r2, r3, r4, r5 = re[2, 0], re[2, 1], re[2, 2], re[2, 3], re[2, 4], re[2, 5]
    i0, i1, i2, i3, i4, i5 = im[2, 0], im[2, 1], im[2, 2], im[2, 3], im[2, 4], im[2, 5]
    g_u = r0 * r1 + i0 * i1
    g_s = r0 * r2 + i0 * i2
    h_uu = (r0 * r3 + i0 * i3) + (r1 * r1 + i1 * i1)
    h_us = (r0 * r4 + i0 * i4) + (r1 * r2 + i1 * i2)
    h_ss = (r0 * r5 + i0 * i5) + (r2 * r2 + i2 * i2)
    det = h_uu * h_ss - h_us * h_us
    peak[c] = det > 0.0 and h_uu < 0.0
    du[c] = -(h_ss * g_u - h_us * g_s) / det
    ds[c] = -(h_uu * g_s - h_us * g_u) / det


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _series_asin(x):  # pragma: no cover
    """`_asin_small`'s series for ``|x| <= 0.02`` (the caller checks the range)."""
    x2 = x * x
    return x * (1.0 + x2 * (1.0 / 6.0 + x2 * (3.0 / 40.0 + x2 * (5.0 / 112.0 + x2 * (
        35.0 / 1152.0 + x2 * (63.0 / 2816.0))))))


@njit(cache=True, nogil=True, error_model="numpy")
def _far_error(u1, s1, direction):  # pragma: no cover
    """Squared angle change (rad^2) to ``(u1, s1)`` where the series does not apply: `_error`."""
    az0, el0, sin_az0, cos_az0, sin_el0, cos_el0 = direction
    cos_el1 = math.sqrt(1.0 - s1 * s1)
    sin_az1 = u1 / cos_el1
    cos_az1 = math.sqrt(1.0 - sin_az1 * sin_az1)
    d_el = _asin_small(s1 * cos_el0 - cos_el1 * sin_el0)
    d_az = _asin_small(sin_az1 * cos_az0 - cos_az1 * sin_az0)
    if not (abs(d_el) <= 0.02 and abs(d_az) <= 0.02):
        az1, el1 = _angles(u1, s1)
        d_az, d_el = az1 - az0, el1 - el0
    return d_az * d_az + d_el * d_el
