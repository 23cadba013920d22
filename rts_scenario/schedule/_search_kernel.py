"""Compiled quantization-aware search (numba): `quantization._search_grid`, entry by entry.

Imported only when numba is installed and the search first runs (`quantization`), so
``import rts_scenario`` never pays for it. Each step mirrors the numpy search: the linear model
of the peak shift per channel step, the reference channel fixed, two channels over ``reach``
steps, the weakest solved, an idle channel brought in weakly, the best ``shortlist`` by the
linear model, then the exact prediction (one Newton step on the response) picking among them
and the naive setting. tests/test_quantization_kernel.py compares the two.

Constants are arguments, not globals: numba freezes globals into its cached machine code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# An amplitude ratio of x dB is exp(x * DB_TO_NEPER): ln(10) / 20.
DB_TO_NEPER = math.log(10.0) / 20.0


@njit(cache=True, nogil=True, error_model="numpy")
def _nearest(att, low, step, high, slack):  # pragma: no cover
    """Nearest attenuator setting (the minimum below it; inf above the maximum)."""
    if not math.isfinite(att):
        return math.inf
    snapped = low + np.rint((att - low) / step) * step
    snapped = max(snapped, low)
    return snapped if snapped <= high + slack else math.inf


@njit(cache=True, nogil=True, error_model="numpy")
def _angles(u, s):  # pragma: no cover
    """`arrays.angles_from_cosines` for one direction: ``(az_rad, el_rad)``."""
    s = min(max(s, -1.0), 1.0)
    el = math.asin(s)
    cos_el = math.sqrt(1.0 - s * s)
    az = math.atan2(u, math.sqrt(max(cos_el * cos_el - u * u, 0.0)))
    return az, el


@njit(cache=True, nogil=True, error_model="numpy")
def _error(resp, i, amps, u, s, az0, el0):  # pragma: no cover
    """Predicted angle error (deg, norm of az and el) of channel amplitudes ``amps``.

    ``az0``, ``el0``: the set direction ``(u, s)`` as angles (rad).
    """
    a0, a1, a2, a3 = amps[0], amps[1], amps[2], amps[3]

    def beam(t):  # B or one of its derivatives: the channels' responses, weighted
        return (resp[i, t, 0] * a0 + resp[i, t, 1] * a1 + resp[i, t, 2] * a2
                + resp[i, t, 3] * a3)

    b, b_u, b_s, b_uu, b_us, b_ss = beam(0), beam(1), beam(2), beam(3), beam(4), beam(5)
    cb = b.conjugate()
    g_u = (cb * b_u).real
    g_s = (cb * b_s).real
    h_uu = (cb * b_uu).real + b_u.real * b_u.real + b_u.imag * b_u.imag
    h_us = (cb * b_us).real + (b_u.conjugate() * b_s).real
    h_ss = (cb * b_ss).real + b_s.real * b_s.real + b_s.imag * b_s.imag
    det = h_uu * h_ss - h_us * h_us
    du = ds = 0.0
    if det > 0.0:
        du = -(h_ss * g_u - h_us * g_s) / det
        ds = -(h_uu * g_s - h_us * g_u) / det
    az1, el1 = _angles(u + du, s + ds)
    return math.hypot(math.degrees(az1 - az0), math.degrees(el1 - el0))


@njit(cache=True, nogil=True, error_model="numpy")
def _sensitivity(resp, i, weights, az0, el0, out):  # pragma: no cover
    """`quantization._sensitivity` times `_degree_scale` for entry ``i`` into ``out`` (2, 4).

    The peak shift in degrees (azimuth, elevation) per unit change of each channel's amplitude,
    from the Newton step of the gradient's change at the solved weights.
    """
    w0, w1, w2, w3 = weights[i, 0], weights[i, 1], weights[i, 2], weights[i, 3]
    b = [resp[i, t, 0] * w0 + resp[i, t, 1] * w1 + resp[i, t, 2] * w2 + resp[i, t, 3] * w3
         for t in range(6)]
    cb = b[0].conjugate()
    h_uu = (cb * b[3]).real + b[1].real * b[1].real + b[1].imag * b[1].imag
    h_us = (cb * b[4]).real + (b[1].conjugate() * b[2]).real
    h_ss = (cb * b[5]).real + b[2].real * b[2].real + b[2].imag * b[2].imag
    det = h_uu * h_ss - h_us * h_us
    deg_u = math.degrees(1.0 / (math.cos(el0) * math.cos(az0)))
    deg_s = math.degrees(1.0 / math.cos(el0))
    for q in range(4):
        d_u = (cb * resp[i, 1, q]).real
        d_s = (cb * resp[i, 2, q]).real
        if det > 0.0:
            out[0, q] = -(h_ss * d_u - h_us * d_s) / det * deg_u
            out[1, q] = -(h_uu * d_s - h_us * d_u) / det * deg_s
        else:
            out[0, q] = 0.0
            out[1, q] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
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


@njit(cache=True, nogil=True, error_model="numpy")
def search(resp, weights, full, naive, u, s, reaches, aboves, low, step, high, slack, fine,
           shortlist, norm_floor, out, out_error):  # pragma: no cover
    """Write every entry's chosen settings and their predicted angle error.

    Pass p searches ``reaches[p]`` steps either side where the settings so far err by more
    than ``aboves[p]`` degrees (the first pass starts from ``naive``); the others keep them.
    ``out`` (N, 4) gets the settings (inf where off), ``out_error`` (N,) the error in degrees.
    ``resp`` (N, 6, 4) complex, ``weights``, ``full``, ``naive`` (N, 4), ``u``, ``s`` (N,).
    """
    n = weights.shape[0]
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
    taken = np.empty(most * most, dtype=np.bool_)
    option = np.empty(4)
    amps = np.empty(4)
    best = np.empty(4)
    sens = np.empty((2, 4))
    start = np.empty(4)
    for i in range(n):
        for q in range(4):
            best[q] = naive[i, q]
            amps[q] = (math.exp((full[i, q] - best[q]) * DB_TO_NEPER)
                       if math.isfinite(best[q]) else 0.0)
        az0, el0 = _angles(u[i], s[i])
        best_err = _error(resp, i, amps, u[i], s[i], az0, el0)
        have_sens = False
        for p in range(reaches.size):
            if not best_err > aboves[p]:  # close enough already (or not predictable): kept
                continue
            if not have_sens:  # it depends on the solved weights only
                _sensitivity(resp, i, weights, az0, el0, sens)
                have_sens = True
            reach = reaches[p]
            side = 2 * reach + 1
            n_cand = side * side
            # This pass starts from the settings so far.
            for q in range(4):
                on[q] = math.isfinite(best[q])
                amp[q] = math.exp((full[i, q] - best[q]) * DB_TO_NEPER) if on[q] else 0.0
                start[q] = best[q]
            # Roles by weight, strongest first (a stable sort, as numpy's for four entries).
            for q in range(4):
                order[q] = q
            for a in range(1, 4):
                j = a
                while j > 0 and -weights[i, order[j]] < -weights[i, order[j - 1]]:
                    order[j], order[j - 1] = order[j - 1], order[j]
                    j -= 1
            # Per role and step count: the peak shift it causes.
            for k in range(n_steps):
                for role in range(4):
                    q = order[role]
                    moves[role, k, 0], moves[role, k, 1] = _shift(
                        on[q], start[q], amp[q], per_step[k], weights[i, q], sens[0, q],
                        sens[1, q], (k - fine) * step, low, high, slack)
            for ia in range(side):
                for ib in range(side):
                    for axis in range(2):
                        resid[ia * side + ib, axis] = (moves[0, fine, axis]
                                                       + moves[1, fine - reach + ia, axis]
                                                       + moves[2, fine - reach + ib, axis])
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
            for q in range(4):
                if on[q]:
                    continue
                g0, g1 = sens[0, q], sens[1, q]
                gg = max(g0 * g0 + g1 * g1, norm_floor)
                for c in range(n_cand):
                    a_star = -(g0 * final[c, 0] + g1 * final[c, 1]) / gg
                    level = -math.inf if a_star <= 0.0 else math.log10(a_star)
                    att = _nearest(full[i, q] - 20.0 * level, low, step, high, slack)
                    a = math.exp((full[i, q] - att) * DB_TO_NEPER) if math.isfinite(att) else 0.0
                    m0, m1 = final[c, 0] + a * g0, final[c, 1] + a * g1
                    new_cost = m0 * m0 + m1 * m1
                    if a > 0.0 and new_cost < cost[c]:
                        cost[c] = new_cost
                        extra_q[c] = q
                        extra_att[c] = att
            # The linear model shortlists; the exact prediction decides (the naive one too).
            taken[:] = False
            for _ in range(min(shortlist, n_cand)):
                pick = -1
                for c in range(n_cand):
                    if not taken[c] and (pick < 0 or cost[c] < cost[pick]):
                        pick = c
                taken[pick] = True
                counts = (0, pick // side - reach, pick % side - reach, best_k[pick])
                for role in range(4):
                    q = order[role]
                    setting = start[q] + counts[role] * step
                    ok = on[q] and setting >= low - slack and setting <= high + slack
                    option[q] = setting if ok else math.inf
                if extra_q[pick] >= 0:
                    option[extra_q[pick]] = extra_att[pick]
                for q in range(4):
                    amps[q] = (math.exp((full[i, q] - option[q]) * DB_TO_NEPER)
                               if math.isfinite(option[q]) else 0.0)
                err = _error(resp, i, amps, u[i], s[i], az0, el0)
                if err < best_err:
                    best_err = err
                    for q in range(4):
                        best[q] = option[q]
        for q in range(4):
            out[i, q] = best[q]
        out_error[i] = best_err
