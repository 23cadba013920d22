"""Compiled per-target kernel of the exact method (numba), the same algorithm as `exact`.

Imported only through `rts_scenario.solver.compiled`, which compiles it on first use (and
caches the machine code on disk), so neither ``import rts_scenario`` nor a machine without
numba pays for it. Every function mirrors a numpy function of `rts_scenario.solver.exact` and
`rts_scenario.arrays` step for step (same tests, same order of operations where it matters), so
weights agree with the numpy path to rounding and reasons are identical
(tests/test_solver_kernel.py). The weights' feasibility and stationarity tests are compared in
squares (no square roots), which can differ only for a value within rounding of its bound.
Two sums differ in form, not in value: a centro-symmetric array's real responses are summed
over one place of each mirror pair, with the table entries of the elements there and at the
mirror folded into one (`exact.ExactTables`), half the multiply-adds of the full sum; and on a
full grid (the paper array) they are products of a sum over y and one over z (`_grid_sums`),
equal to rounding. Likewise on complex responses an exponential over z takes the phase map's
rotation into its argument where the numpy code multiplies by it, and where the array is two
rows each symmetric in y and the FEs are plane waves (the AWR1843BOOST), the complex responses
are summed row by row (`_row_sums`): a real sum over each row's mirror pairs times one
exponential per row, about half the multiply-adds and no per-element looks.

Targets go in blocks of `_BLOCK`: sines and cosines (polynomials with Cody-Waite reduction,
~1.5 ulp, instead of libm's ~20 ns calls), exponentials, response sums and the weights up to the
boundary's fast path run as loops over the block that compile to vector instructions, and so
do the phase map's cells and weights (its table reads stay a scalar loop: they do not
vectorize here). Targets whose phase iterates are gathered
per quad and iterate together, in vector loops as well. The rest (every boundary ray, the
curvature test) runs per target on 4-tuples held in registers. No temporaries: the scratch
arrays are allocated once per call.

Constants and reason codes are arguments, not globals: numba freezes globals into the cached
machine code, and its cache only watches this file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# nogil: the solver's thread pool runs chunks in parallel. IEEE division (no zero check) keeps
# the loops over a block free of branches, so they compile to vector instructions; every
# division by a possible zero is guarded by a select, as in the numpy code. "contract" allows
# fused multiply-adds (one rounding instead of two; no reordering of sums).
_jit = njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
# Inlined by numba: helpers of the loops over a block (LLVM alone does not inline some, and a
# call keeps a loop from vectorizing), and the block's stages (a call counts the references to
# its arrays atomically, on entry and exit: per block, 1-3 % of the kernel).
_inline = njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"},
               inline="always")

# Indices into the ``tol`` argument.
_NEGATIVE, _RANK, _GAIN, _RESIDUAL, _PHASE, _ITERATIONS, _INFEASIBLE, _FAR = range(8)
# Indices into the ``codes`` argument.
_OK, _NO_SOLUTION, _NOT_CONVERGED, _SPLIT = range(4)


# pi/2 in three parts (the first two with trailing zero bits, so n * part is exact for the
# n < 2^20 quadrants reached here) and 2/pi, for the argument reduction of `_sincos`.
_PIO2_HI = 1.5707963267341256
_PIO2_MID = 6.077100506303966e-11
_PIO2_LO = 2.0222662487959506e-21
_TWO_OVER_PI = 0.6366197723675814
# sin r = r + r^3 (S1 + S2 z + ... + S6 z^5) and cos r = 1 + z (C1 + C2 z + ... + C7 z^6),
# z = r^2, on |r| <= pi/4: least-squares fits of the relative error on Chebyshev nodes
# (50-digit arithmetic, then rounded), 0.04 and 0.006 ulp from sin and cos there. Degree 13 and
# 14 are the lowest that stay well below an ulp (degree 11 and 12 leave 47 and 0.9 ulp).
_S1, _S2, _S3, _S4, _S5, _S6 = (
    -0.1666666666666663, 0.008333333333321907, -0.0001984126982945215, 2.755731358092586e-06,
    -2.5050742218107683e-08, 1.5895942777506503e-10)
_C1, _C2, _C3, _C4, _C5, _C6, _C7 = (
    -0.5, 0.04166666666666659, -0.0013888888888872505, 2.4801587288553474e-05,
    -2.755731410293323e-07, 2.087569147896855e-09, -1.1358093382445256e-11)


@_jit
def _sincos(x):  # pragma: no cover
    """``(sin x, cos x)`` within 1.6 ulp for |x| <= 1e3, several times faster than libm's pair.

    0.9 ulp on |r| <= pi/4, 2.4 up to |x| = 1e5: the reduction's rounding, not the polynomials
    (measured against long-double sin and cos on 1.6e7 points). The solver's phases reach a
    few hundred radians at most (k times the aperture).
    """
    n = round(x * _TWO_OVER_PI)
    r = ((x - n * _PIO2_HI) - n * _PIO2_MID) - n * _PIO2_LO
    z = r * r
    sin_r = _S6 * z + _S5
    sin_r = (((sin_r * z + _S4) * z + _S3) * z + _S2) * z + _S1
    sin_r = r + r * z * sin_r
    cos_r = _C7 * z + _C6
    cos_r = ((((cos_r * z + _C5) * z + _C4) * z + _C3) * z + _C2) * z + _C1
    cos_r = 1.0 + z * cos_r
    # x = r + quadrant pi/2: rotate by quadrants without branches (random quadrants mispredict).
    quadrant = int(n)
    odd = quadrant & 1
    sin_x = cos_r if odd else sin_r
    cos_x = sin_r if odd else cos_r
    return sin_x * (1 - (quadrant & 2)), cos_x * (1 - ((quadrant + 1) & 2))


@_jit
def _atan_small(y, x):  # pragma: no cover
    """``atan2(y, x)`` by its series where ``|y| <= 1e-3 x`` (exact to rounding), else NaN.

    Branch-free, so a block of converged phase residuals is one vector loop.
    """
    t = y / x
    t2 = t * t
    series = t * (1.0 - t2 * (1.0 / 3.0 - t2 * (0.2 - t2 * (1.0 / 7.0 - t2 / 9.0))))
    return series if (x > 0.0) & (abs(y) <= 1e-3 * x) else np.nan


@_jit
def _atan2(y, x):  # pragma: no cover
    small = _atan_small(y, x)
    return small if small == small else math.atan2(y, x)


@_jit
def _exp_rows(out_re, out_im, step_re, step_im, k, coords, direct, indirect, mirror,
              progression, x, nb):  # pragma: no cover
    """``exp(-j k c x[b])`` for every coordinate ``c`` and target ``b < nb`` (`arrays._exp_rows`).

    ``out_re, out_im``: shape ``(len(coords), B)``; ``step_re, step_im``: scratch ``(B,)``.
    """
    if progression:
        first = direct[0]
        phase = -k * coords[first]
        step = -k * (coords[direct[1]] - coords[first])
        for b in range(nb):
            sin_t, cos_t = _sincos(phase * x[b])
            out_re[first, b] = cos_t
            out_im[first, b] = sin_t
            sin_t, cos_t = _sincos(step * x[b])
            step_re[b] = cos_t
            step_im[b] = sin_t
        for i in range(1, direct.size):
            prev, cur = direct[i - 1], direct[i]
            for b in range(nb):
                re, im = out_re[prev, b], out_im[prev, b]
                out_re[cur, b] = re * step_re[b] - im * step_im[b]
                out_im[cur, b] = re * step_im[b] + im * step_re[b]
    else:
        for i in direct:
            phase = -k * coords[i]
            if phase == 0.0:  # a centre coordinate (the paper array's middle row): exp(0) = 1
                for b in range(nb):
                    out_re[i, b] = 1.0
                    out_im[i, b] = 0.0
                continue
            for b in range(nb):
                sin_t, cos_t = _sincos(phase * x[b])
                out_re[i, b] = cos_t
                out_im[i, b] = sin_t
    for i in indirect:
        m = mirror[i]
        for b in range(nb):
            out_re[i, b] = out_re[m, b]
            out_im[i, b] = -out_im[m, b]


@_jit
def _catmull_rom(t):  # pragma: no cover
    t2 = t * t
    t3 = t * t * t
    return (0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2),
            0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2))


@_inline
def _phase_block(us, ss, u0, s0, du, ds, flat, stride, out, patch, nb):  # pragma: no cover
    """Bicubic phase map (`exact.PhaseMap.__call__`) of targets ``b < nb`` into ``out``.

    ``flat``: the map's table with its edge nodes repeated once around it (``stride`` nodes a
    side), flattened, so a target's 4 x 4 nodes are one patch at fixed offsets, with no
    clamping. Flattened by the caller once per quad: a reshape here (per block) cost a
    reference count and a call. The cells and weights are
    one vector loop over the block (into ``patch``, shape ``(9, B)``), the table reads one
    scalar loop (they do not vectorize here), with fused multiply-adds and unsigned offsets (no
    checks for negative indices); equal to the map's per-target sums to rounding.
    """
    last = float(stride - 3)  # the last node of the map itself
    for b in range(nb):
        x = (us[b] - u0) / du
        x = 0.0 if x < 0.0 else (last if x > last else x)
        y = (ss[b] - s0) / ds
        y = 0.0 if y < 0.0 else (last if y > last else y)
        i = min(np.floor(x), last - 1.0)
        j = min(np.floor(y), last - 1.0)
        wx = _catmull_rom(x - i)
        wy = _catmull_rom(y - j)
        # Node (i - 1, j - 1) of the map is (i, j) of the padded table.
        patch[0, b] = i * stride + j
        for a in range(4):
            patch[1 + a, b] = wx[a]
            patch[5 + a, b] = wy[a]
    one, two, three, step = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(stride)
    for b in range(nb):
        row = np.uint64(patch[0, b])
        w5, w6, w7, w8 = patch[5, b], patch[6, b], patch[7, b], patch[8, b]
        total = 0.0
        for a in range(4):
            inner = w5 * flat[row] + w6 * flat[row + one] + w7 * flat[row + two] \
                + w8 * flat[row + three]
            total += patch[1 + a, b] * inner
            row += step
        out[b] = total


# The per-target algebra works on 4-tuples (one entry per FE): they stay in registers.


@_jit
def _dot(a, b):  # pragma: no cover
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


@_jit
def _sub_scaled(y, a, x):  # pragma: no cover
    """``y - a * x``."""
    return (y[0] - a * x[0], y[1] - a * x[1], y[2] - a * x[2], y[3] - a * x[3])


@_jit
def _unit(v, floor):  # pragma: no cover
    norm = math.sqrt(_dot(v, v))
    scale = 1.0 / norm if norm > floor else 0.0
    return (v[0] * scale, v[1] * scale, v[2] * scale, v[3] * scale)


@_jit
def _smaller(a, b):  # pragma: no cover
    return a if a < b else b


@_jit
def _accept(cand, gain_floor2, negative_tol):  # pragma: no cover
    """Squared norm of a candidate, and whether it is feasible (no weight clearly below 0, gain).

    `exact.max_gain_weights`'s tests compared in squares (``gain_floor2`` is its
    ``gain_floor`` squared): no square roots, the same outcome but within rounding of a bound.
    With `_finish` likewise, the weights of a block take two square roots per target, not
    seven: 1.03x on the paper array, 1.01x on the AWR1843BOOST (measured on the whole kernel).
    """
    norm2 = _dot(cand, cand)
    low = _smaller(_smaller(cand[0], cand[1]), _smaller(cand[2], cand[3]))
    low_ok = (low >= 0.0) | (low * low <= negative_tol * negative_tol * norm2)
    return norm2, low_ok & (norm2 > gain_floor2)


@_jit
def _ray(w, e1, e2, k, p_kk):  # pragma: no cover
    """``w - w_k / P_kk * P e_k``: the projection with weight ``k`` forced to 0."""
    ratio = w[k] / p_kk
    p = (-(e1[0] * e1[k] + e2[0] * e2[k]), -(e1[1] * e1[k] + e2[1] * e2[k]),
         -(e1[2] * e1[k] + e2[2] * e2[k]), -(e1[3] * e1[k] + e2[3] * e2[k]))
    return (w[0] - (p[0] + (k == 0)) * ratio, w[1] - (p[1] + (k == 1)) * ratio,
            w[2] - (p[2] + (k == 2)) * ratio, w[3] - (p[3] + (k == 3)) * ratio)


@_jit
def _boundary(w, e1, e2, gain_floor2, negative_tol):  # pragma: no cover
    """`exact._boundary_ray` then, if needed, `exact._boundary_rays`: ``(w, feasible)``."""
    cand, good = _first_ray(w, e1, e2, gain_floor2, negative_tol)
    if good:
        return cand, True
    return _boundary_rays(w, e1, e2, gain_floor2, negative_tol)


@_jit
def _boundary_rays(w, e1, e2, gain_floor2, negative_tol):  # pragma: no cover
    """`exact._boundary_rays`: ``(w, feasible)`` of every boundary ray.

    The feasible one of largest norm (gain) wins, the first on ties.
    """
    best = w
    best_score = -2.0
    found = False
    for k in range(4):
        p_kk = 1.0 - e1[k] * e1[k] - e2[k] * e2[k]
        usable = p_kk > 1e-12
        cand = _ray(w, e1, e2, k, p_kk) if usable else w
        norm2, good = _accept(cand, gain_floor2, negative_tol)
        valid = usable and good
        score = norm2 if valid else -1.0
        if score > best_score:
            best, best_score = cand, score
        found = found or valid
    return best, found


# Inlined by numba: LLVM alone does not inline it, and the call would keep the loop over a
# block from being vectorized.
@_inline
def _project(f, r1, r2, rank_floor, gain_tol, negative_tol):  # pragma: no cover
    """Projection of ``f`` onto the null space of ``r1, r2``: ``(w, e1, e2, gain_floor2, ok)``.

    ``gain_floor2``: the square of `exact.max_gain_weights`'s ``gain_floor``.
    """
    e1 = _unit(r1, rank_floor)
    e2 = _unit(_sub_scaled(r2, _dot(r2, e1), e1), rank_floor)
    w = _sub_scaled(_sub_scaled(f, _dot(f, e1), e1), _dot(f, e2), e2)
    gain_floor2 = gain_tol * gain_tol * _dot(f, f)
    _, ok = _accept(w, gain_floor2, negative_tol)
    return w, e1, e2, gain_floor2, ok


@_jit
def _finish(w, ok, r1, r2, rank_floor, residual_tol):  # pragma: no cover
    """Clip rounding negatives and check that stationarity still holds (in squares: `_accept`)."""
    w = (_larger(w[0], 0.0), _larger(w[1], 0.0), _larger(w[2], 0.0), _larger(w[3], 0.0))
    w_norm2 = _dot(w, w)
    tol2, floor2 = residual_tol * residual_tol, rank_floor * rank_floor
    r1w, r2w = _dot(r1, w), _dot(r2, w)
    ok = ok & (r1w * r1w <= _larger(tol2 * _dot(r1, r1), floor2) * w_norm2)
    return w, ok & (r2w * r2w <= _larger(tol2 * _dot(r2, r2), floor2) * w_norm2)


@_jit
def _larger(a, b):  # pragma: no cover
    return a if a > b else b


@_jit
def _max_gain_weights(f, r1, r2, row_scale, tol):  # pragma: no cover
    """`exact.max_gain_weights` for one target: ``(w >= 0, whether it is a solution)``."""
    rank_floor = tol[_RANK] * row_scale
    w, e1, e2, gain_floor2, ok = _project(f, r1, r2, rank_floor, tol[_GAIN], tol[_NEGATIVE])
    if not ok:
        w, ok = _boundary(w, e1, e2, gain_floor2, tol[_NEGATIVE])
    return _finish(w, ok, r1, r2, rank_floor, tol[_RESIDUAL])


@_inline
def _first_ray(w, e1, e2, gain_floor2, negative_tol):  # pragma: no cover
    """`exact._boundary_ray` without branches: ``(candidate, whether it is the solution)``.

    The most negative weight (the first on ties) forced to 0 by selects, not indexing, so a
    loop over a block of targets stays one vector loop.
    """
    k1 = w[1] < w[0]
    low = w[1] if k1 else w[0]
    k2 = w[2] < low
    low = w[2] if k2 else low
    k3 = w[3] < low
    k = 3 if k3 else (2 if k2 else (1 if k1 else 0))
    e1k = e1[3] if k == 3 else (e1[2] if k == 2 else (e1[1] if k == 1 else e1[0]))
    e2k = e2[3] if k == 3 else (e2[2] if k == 2 else (e2[1] if k == 1 else e2[0]))
    wk = w[3] if k == 3 else (w[2] if k == 2 else (w[1] if k == 1 else w[0]))
    p_kk = -(e1k * e1k + e2k * e2k) + 1.0
    ratio = wk / p_kk  # as `_ray`; unused where p_kk is not usable
    cand = (w[0] - (-(e1[0] * e1k + e2[0] * e2k) + (k == 0)) * ratio,
            w[1] - (-(e1[1] * e1k + e2[1] * e2k) + (k == 1)) * ratio,
            w[2] - (-(e1[2] * e1k + e2[2] * e2k) + (k == 2)) * ratio,
            w[3] - (-(e1[3] * e1k + e2[3] * e2k) + (k == 3)) * ratio)
    _, good = _accept(cand, gain_floor2, negative_tol)
    return cand, good & (p_kk > 1e-12)


@_jit
def _max_gain_weights_block(acc_re, nb, row_scale, tol, work):  # pragma: no cover
    """`_max_gain_weights` of the unrotated responses of a block of targets, into ``work``.

    Rows of ``work``: 0-3 ``w``, 4 ``ok`` (1.0 or 0.0), 5 left to the caller, 6 scratch. The
    projection, the boundary's fast path and the final checks run over the whole block (vector
    instructions: scalar constants, selects, no branches, and ``work`` only written); the few
    targets whose fast path fails search every boundary ray, one by one.
    """
    rank_floor = tol[_RANK] * row_scale
    gain_tol, negative_tol, residual_tol = tol[_GAIN], tol[_NEGATIVE], tol[_RESIDUAL]
    for b in range(nb):
        r1, r2 = _row(acc_re, 4, b), _row(acc_re, 8, b)
        w, e1, e2, gain_floor2, ok = _project(_row(acc_re, 0, b), r1, r2, rank_floor, gain_tol,
                                             negative_tol)
        cand, good = _first_ray(w, e1, e2, gain_floor2, negative_tol)
        w = (w[0] if ok else cand[0], w[1] if ok else cand[1], w[2] if ok else cand[2],
             w[3] if ok else cand[3])
        w, done = _finish(w, ok | good, r1, r2, rank_floor, residual_tol)
        for q in range(4):
            work[q, b] = w[q]
        work[4, b] = 1.0 if done else 0.0
        work[6, b] = 0.0 if ok | good else 1.0
    for b in range(nb):
        if work[6, b] != 0.0:  # every boundary ray (the fast path's failed)
            r1, r2 = _row(acc_re, 4, b), _row(acc_re, 8, b)
            w, e1, e2, gain_floor2, _ = _project(_row(acc_re, 0, b), r1, r2, rank_floor,
                                                gain_tol, negative_tol)
            w, ok = _boundary_rays(w, e1, e2, gain_floor2, negative_tol)
            w, ok = _finish(w, ok, r1, r2, rank_floor, residual_tol)
            for q in range(4):
                work[q, b] = w[q]
            work[4, b] = 1.0 if ok else 0.0


@_jit
def _row(acc, first, b):  # pragma: no cover
    return (acc[first, b], acc[first + 1, b], acc[first + 2, b], acc[first + 3, b])


@_jit
def _rotated(acc_re, acc_im, first, b, c, s):  # pragma: no cover
    """``Re(exp(-j phi) g)`` of the response rows ``first..first+3`` (c, s: cos, sin phi)."""
    return (c * acc_re[first, b] + s * acc_im[first, b],
            c * acc_re[first + 1, b] + s * acc_im[first + 1, b],
            c * acc_re[first + 2, b] + s * acc_im[first + 2, b],
            c * acc_re[first + 3, b] + s * acc_im[first + 3, b])


@_jit
def _phase_residual(f_re, f_im, w, c, s):  # pragma: no cover
    """``arg(f . w exp(-j phi))`` with ``c, s = cos(phi), sin(phi)`` (`exact._phase_residual`)."""
    b_re = _dot(f_re, w)
    b_im = _dot(f_im, w)
    return _atan2(b_im * c - b_re * s, b_re * c + b_im * s)


@_jit
def _locate(az, el, column_az, row_el, lines, boxes, slack, raster, frame,
            quad):  # pragma: no cover
    """`quads.candidate_quads`, kept where `quads.inside_quads` holds, else -1.

    On a grid with a `quads.locate_raster` (``raster, frame``) the answer is the raster's where
    its cell is certain, and the test runs only for targets in cells that are not.
    """
    columns, rows = column_az.size, row_el.size
    if columns == 2 and rows == 2:  # one quad (four FEs): its constants hoisted, a vector loop
        a_lo, a_hi = boxes[0, 0] - slack, boxes[0, 1] + slack
        e_lo, e_hi = boxes[0, 2] - slack, boxes[0, 3] + slack
        l00, l01, l02 = lines[0, 0, 0], lines[0, 0, 1], lines[0, 0, 2]
        l10, l11, l12 = lines[0, 1, 0], lines[0, 1, 1], lines[0, 1, 2]
        l20, l21, l22 = lines[0, 2, 0], lines[0, 2, 1], lines[0, 2, 2]
        l30, l31, l32 = lines[0, 3, 0], lines[0, 3, 1], lines[0, 3, 2]
        for n in range(az.size):
            a, e = az[n], el[n]
            inside = (a >= a_lo) & (a <= a_hi) & (e >= e_lo) & (e <= e_hi)
            inside &= l00 * a + l01 * e + l02 >= -slack
            inside &= l10 * a + l11 * e + l12 >= -slack
            inside &= l20 * a + l21 * e + l22 >= -slack
            inside &= l30 * a + l31 * e + l32 >= -slack
            quad[n] = 0 if inside else -1
        return
    if not raster.size:  # `quads.QuadGeometry` gives every grid of quads its raster
        raise ValueError("_locate: a grid of quads needs its raster")
    _locate_by_raster(az, el, column_az, row_el, lines, boxes, slack, raster, frame, quad)


@_jit
def _locate_by_raster(az, el, column_az, row_el, lines, boxes, slack, raster, frame,
                      quad):  # pragma: no cover
    """`_locate` on a grid by its raster: one look-up per target, the test where uncertain.

    The look-up is a loop of its own (no branches but the raster's bounds); the few targets in
    cells the raster leaves open (-2) take the candidate's test one by one. On the wide-3x5
    grid (8 quads) the kernel ran 1.07x faster so (46.1 against 43.0 ns per target, one
    thread) than testing every quad over chunks of 256 targets, which took 4.5 ns per target.
    """
    az0, el0, per_az, per_el = frame[0], frame[1], frame[2], frame[3]
    width, height = frame[4], frame[5]
    stride = np.int64(width)
    for n in range(az.size):
        x = (az[n] - az0) * per_az
        y = (el[n] - el0) * per_el
        # Outside the raster (NaN included): outside every quad.
        if (x >= 0.0) & (x < width) & (y >= 0.0) & (y < height):
            quad[n] = raster[np.int64(y) * stride + np.int64(x)]
        else:
            quad[n] = -1
    last_col, last_row = column_az.size - 2, row_el.size - 2
    for n in range(az.size):
        if quad[n] != -2:
            continue
        a, e = az[n], el[n]
        col, row = -1, -1
        for i in range(column_az.size):
            col += 1 if column_az[i] < a else 0
        for i in range(row_el.size):
            row += 1 if row_el[i] < e else 0
        q = min(max(row, 0), last_row) * (last_col + 1) + min(max(col, 0), last_col)
        inside = (a >= boxes[q, 0] - slack) & (a <= boxes[q, 1] + slack) \
            & (e >= boxes[q, 2] - slack) & (e <= boxes[q, 3] + slack)
        for i in range(4):
            inside &= lines[q, i, 0] * a + lines[q, i, 1] * e + lines[q, i, 2] >= -slack
        quad[n] = q if inside else -1


@_inline
def _four(a, r, v):  # pragma: no cover
    """``a[r, v:v + 4]`` as a tuple."""
    return a[r, v], a[r, v + 1], a[r, v + 2], a[r, v + 3]


@_inline
def _three(a, r, v):  # pragma: no cover
    """``a[r, v:v + 3]`` as a tuple."""
    return a[r, v], a[r, v + 1], a[r, v + 2]


@_inline
def _down3(a, v, b):  # pragma: no cover
    """``a[v:v + 3, b]`` as a tuple."""
    return a[v, b], a[v + 1, b], a[v + 2, b]


@_inline
def _down4(a, v, b):  # pragma: no cover
    """``a[v:v + 4, b]`` as a tuple."""
    return a[v, b], a[v + 1, b], a[v + 2, b], a[v + 3, b]


@_inline
def _re_mac(x, tr, ti, lr, li):  # pragma: no cover
    """``x + Re(t l)`` as two fused multiply-adds."""
    x = x + tr * lr
    return x - ti * li


@_inline
def _im_mac(y, tr, ti, lr, li):  # pragma: no cover
    """``y + Im(t l)`` as two fused multiply-adds."""
    y = y + tr * li
    return y + ti * lr


@_jit
def _complex_sums(acc_re, acc_im, table_re, table_im, look_re, look_im, first, stop,
                  n_elements, nb):  # pragma: no cover
    """``acc[r, b] = sum_v table[r, v] look[v, b]`` (complex) for rows ``first <= r < stop``.

    Rows in pairs and elements in fours: each pass over the block loads and stores a row's
    sums once per four elements, not once per element, and each term is two fused
    multiply-adds into the sum, so the loop is bound by its multiply-adds (1.7x the speed of
    row pairs element by element, measured on 12 rows of 12 elements). Every sum adds its
    terms in element order.
    """
    if (stop - first) % 2:  # the pairs would reach past the rows asked for (no bounds checks)
        raise ValueError("_complex_sums: an even number of rows is required")
    for r0 in range(first, stop, 2):
        r1 = r0 + 1
        for b in range(nb):
            acc_re[r0, b] = 0.0
            acc_im[r0, b] = 0.0
            acc_re[r1, b] = 0.0
            acc_im[r1, b] = 0.0
        v = 0
        while v + 3 < n_elements:
            p, q = _four(table_re, r0, v), _four(table_im, r0, v)
            s, t = _four(table_re, r1, v), _four(table_im, r1, v)
            for b in range(nb):
                lr, li = _down4(look_re, v, b), _down4(look_im, v, b)
                x, y = acc_re[r0, b], acc_im[r0, b]
                for i in range(4):
                    x = _re_mac(x, p[i], q[i], lr[i], li[i])
                    y = _im_mac(y, p[i], q[i], lr[i], li[i])
                acc_re[r0, b], acc_im[r0, b] = x, y
                x, y = acc_re[r1, b], acc_im[r1, b]
                for i in range(4):
                    x = _re_mac(x, s[i], t[i], lr[i], li[i])
                    y = _im_mac(y, s[i], t[i], lr[i], li[i])
                acc_re[r1, b], acc_im[r1, b] = x, y
            v += 4
        for u in range(v, n_elements):
            p0, q0, s0, t0 = table_re[r0, u], table_im[r0, u], table_re[r1, u], table_im[r1, u]
            for b in range(nb):
                lr, li = look_re[u, b], look_im[u, b]
                acc_re[r0, b] = _re_mac(acc_re[r0, b], p0, q0, lr, li)
                acc_im[r0, b] = _im_mac(acc_im[r0, b], p0, q0, lr, li)
                acc_re[r1, b] = _re_mac(acc_re[r1, b], s0, t0, lr, li)
                acc_im[r1, b] = _im_mac(acc_im[r1, b], s0, t0, lr, li)


@_jit
def _real_sums(acc_re, table_re, table_im, look_re, look_im, first, stop, n_elements,
               nb):  # pragma: no cover
    """``acc_re[r, b] = Re(sum_v table[r, v] look[v, b])`` for rows ``first <= r < stop``.

    Rows in fours and elements in threes (as `_complex_sums`; 1.9x the speed of row fours
    element by element, measured on 12 rows of 12 elements). Every sum adds its terms in
    element order.
    """
    if (stop - first) % 4:  # the fours would reach past the rows asked for (no bounds checks)
        raise ValueError("_real_sums: a multiple of 4 rows is required")
    for r0 in range(first, stop, 4):
        for r in range(r0, r0 + 4):
            for b in range(nb):
                acc_re[r, b] = 0.0
        v = 0
        while v + 2 < n_elements:
            p0, q0 = _three(table_re, r0, v), _three(table_im, r0, v)
            p1, q1 = _three(table_re, r0 + 1, v), _three(table_im, r0 + 1, v)
            p2, q2 = _three(table_re, r0 + 2, v), _three(table_im, r0 + 2, v)
            p3, q3 = _three(table_re, r0 + 3, v), _three(table_im, r0 + 3, v)
            for b in range(nb):
                lr, li = _down3(look_re, v, b), _down3(look_im, v, b)
                x0, x1 = acc_re[r0, b], acc_re[r0 + 1, b]
                x2, x3 = acc_re[r0 + 2, b], acc_re[r0 + 3, b]
                for i in range(3):
                    x0 = _re_mac(x0, p0[i], q0[i], lr[i], li[i])
                    x1 = _re_mac(x1, p1[i], q1[i], lr[i], li[i])
                    x2 = _re_mac(x2, p2[i], q2[i], lr[i], li[i])
                    x3 = _re_mac(x3, p3[i], q3[i], lr[i], li[i])
                acc_re[r0, b], acc_re[r0 + 1, b] = x0, x1
                acc_re[r0 + 2, b], acc_re[r0 + 3, b] = x2, x3
            v += 3
        for u in range(v, n_elements):
            for r in range(r0, r0 + 4):
                tr, ti = table_re[r, u], table_im[r, u]
                for b in range(nb):
                    acc_re[r, b] = _re_mac(acc_re[r, b], tr, ti, look_re[u, b], look_im[u, b])


@_jit
def _axis_rows(out, tab_re, tab_im, e_re, e_im, direct, nb):  # pragma: no cover
    """``out[r, b] = Re(sum_i tab[r, i] e[i, b])`` for rows ``r < 8``, over ``i`` in ``direct``.

    All eight rows at once and coordinates in pairs, the sums held in registers (one pass over
    the block per pair, not one per row and coordinate: the paper array's grid sums took 6.2 ns
    per target row by row, 4.2 so); the first pair starts the sums.
    """
    n = 0
    while n < direct.size:
        i = direct[n]
        j = direct[n + 1] if n + 1 < direct.size else i
        # A lone last coordinate is paired with itself at a zero weight.
        lone = 0.0 if n + 1 < direct.size else 1.0
        p = (tab_re[0, i], tab_re[1, i], tab_re[2, i], tab_re[3, i], tab_re[4, i],
             tab_re[5, i], tab_re[6, i], tab_re[7, i])
        q = (tab_im[0, i], tab_im[1, i], tab_im[2, i], tab_im[3, i], tab_im[4, i],
             tab_im[5, i], tab_im[6, i], tab_im[7, i])
        pj = ((1.0 - lone) * tab_re[0, j], (1.0 - lone) * tab_re[1, j],
              (1.0 - lone) * tab_re[2, j], (1.0 - lone) * tab_re[3, j],
              (1.0 - lone) * tab_re[4, j], (1.0 - lone) * tab_re[5, j],
              (1.0 - lone) * tab_re[6, j], (1.0 - lone) * tab_re[7, j])
        qj = ((1.0 - lone) * tab_im[0, j], (1.0 - lone) * tab_im[1, j],
              (1.0 - lone) * tab_im[2, j], (1.0 - lone) * tab_im[3, j],
              (1.0 - lone) * tab_im[4, j], (1.0 - lone) * tab_im[5, j],
              (1.0 - lone) * tab_im[6, j], (1.0 - lone) * tab_im[7, j])
        if n == 0:
            for b in range(nb):
                ar, ai, br, bi = e_re[i, b], e_im[i, b], e_re[j, b], e_im[j, b]
                for r in range(8):
                    out[r, b] = _re_mac(p[r] * ar - q[r] * ai, pj[r], qj[r], br, bi)
        else:
            for b in range(nb):
                ar, ai, br, bi = e_re[i, b], e_im[i, b], e_re[j, b], e_im[j, b]
                for r in range(8):
                    x = _re_mac(out[r, b], p[r], q[r], ar, ai)
                    out[r, b] = _re_mac(x, pj[r], qj[r], br, bi)
        n += 2


@_jit
def _grid_sums(acc_re, scratch, y_re, y_im, ey_re, ey_im, y_direct, z_re, z_im, ez_re, ez_im,
               z_direct, nb):  # pragma: no cover
    """Sum a grid's real rows 0-11 as products of a sum over y and one over z.

    On a full grid of plane-wave elements (`exact.ExactTables`: ``sep_*``) every element's
    table entry is a factor of its y times one of its z, so ``f_q = Y_q Z_q``,
    ``f_u,q = Y'_q Z_q`` and ``f_s,q = Y_q Z'_q``, each factor real (a sum over one axis,
    folded onto the coordinates computed). The paper array's 12 elements: 4 sums of 2 terms per
    axis and FE instead of 12 rows of 6 folded places and their 6 looks (less than half the
    multiply-adds; 4.2 ns per target instead of 9, 1.15x on the whole kernel). ``scratch``:
    rows 0-7 are overwritten. Fusing the products into the pass over z gained 0.5 %: not done.
    """
    _axis_rows(acc_re, y_re, y_im, ey_re, ey_im, y_direct, nb)  # Y (rows 0-3), Y' (4-7)
    _axis_rows(scratch, z_re, z_im, ez_re, ez_im, z_direct, nb)  # Z (rows 0-3), Z' (4-7)
    for q in range(4):
        for b in range(nb):
            y0, y1, z0, z1 = acc_re[q, b], acc_re[4 + q, b], scratch[q, b], scratch[4 + q, b]
            acc_re[q, b] = y0 * z0
            acc_re[4 + q, b] = y1 * z0
            acc_re[8 + q, b] = y0 * z1


# Targets evaluated together: each loop over a block amortizes its set-up (alias checks,
# remainders) over more targets, and the targets whose phase iterates go in batches of up to
# a block. 128 ran 1.2-1.4x faster than 32; with the batched iteration 256 ran 5-8 % faster
# than 128 on the AWR1843BOOST and equal on the paper array (64 to 512 measured, one thread,
# alternating in one process). The block's scratch rows then live in L2, not L1.
# `_row_sums`' layout: rows and offsets per row, at most (fewer are padded with zeros). Fixed,
# so that the loops over them unroll inside the vector loop over the block.
ROWS, OFFSETS = 2, 4


@_inline
def _row_sums(acc_re, acc_im, us, ss, phi, k, row_z, row_yc, row_center, deltas, delta_step,
              pair, p_re, p_im, trig, nb):  # pragma: no cover
    """Responses ``f, f_u, f_s`` of plane-wave FEs (all 12 rows complex), row by row.

    The elements of row ``r`` share ``z_r`` and lie symmetric about ``y_r`` (`exact.RowFactors`),
    so FE ``q``'s sum over them is ``P_qr L_r R_qr(u)``: ``P_qr = exp(j k (y_r u_q + z_r s_q))``
    (the table ``p_re, p_im``), ``L_r = exp(-j (k (y_r u + z_r s) + phi))`` per target (``phi``
    the phase map's rotation) and a real ``R_qr = c_r + sum_i 2 m_ri cos(k d_i (u_q - u))`` over
    the pairs at offsets ``+-d_i``, ``c_r`` elements at the centre. With ``M = P L``:
    ``f = sum_r M R``, ``f_u = sum_r M (R' - j k y_r R)``, ``f_s = sum_r -j k z_r M R``. ``R``
    and ``R'`` are sums of ``cos(k d_i u)`` and ``sin(k d_i u)`` times the table ``pair``
    ``(4, ROWS, OFFSETS, 4)``: ``2 m cos(k d u_q)``, ``2 m sin(k d u_q)`` and those times
    ``k d`` (zero where a row has no pair at ``d_i``). The same sums as the element-by-element
    table's in another order: equal to rounding, with about half the multiply-adds and no
    per-element looks.

    ``delta_step``: the offsets' common difference (0.0: none; the cosines and sines then come
    from the first and that step by rotation). Scratch: ``trig`` ``(2 OFFSETS + 2 ROWS, B)``,
    the cosines, the sines, then ``L`` (real and imaginary parts): one array, so that the
    vector loops need few checks that it does not overlap the sums.
    """
    if delta_step != 0.0:
        first, step = k * deltas[0], k * delta_step
        for b in range(nb):
            sin_t, cos_t = _sincos(first * us[b])
            sin_d, cos_d = _sincos(step * us[b])
            trig[0, b], trig[OFFSETS, b] = cos_t, sin_t
            for i in range(1, OFFSETS):
                cos_t, sin_t = cos_t * cos_d - sin_t * sin_d, sin_t * cos_d + cos_t * sin_d
                trig[i, b], trig[OFFSETS + i, b] = cos_t, sin_t
    else:
        for i in range(OFFSETS):
            phase = k * deltas[i]
            for b in range(nb):
                sin_t, cos_t = _sincos(phase * us[b])
                trig[i, b], trig[OFFSETS + i, b] = cos_t, sin_t
    for r in range(ROWS):
        ky, kz = k * row_yc[r], k * row_z[r]
        for b in range(nb):
            sin_t, cos_t = _sincos(-(ky * us[b] + kz * ss[b]) - phi[b])
            trig[2 * OFFSETS + r, b], trig[2 * OFFSETS + ROWS + r, b] = cos_t, sin_t
    ky0, kz0, ky1, kz1 = k * row_yc[0], k * row_z[0], k * row_yc[1], k * row_z[1]
    c0, c1 = row_center[0], row_center[1]
    for q in range(4):
        t = pair[q]
        a0, a1, a2, a3 = t[0, 0, 0], t[0, 1, 0], t[0, 2, 0], t[0, 3, 0]
        b0, b1, b2, b3 = t[0, 0, 1], t[0, 1, 1], t[0, 2, 1], t[0, 3, 1]
        g0, g1, g2, g3 = t[0, 0, 2], t[0, 1, 2], t[0, 2, 2], t[0, 3, 2]
        h0, h1, h2, h3 = t[0, 0, 3], t[0, 1, 3], t[0, 2, 3], t[0, 3, 3]
        d0, d1, d2, d3 = t[1, 0, 0], t[1, 1, 0], t[1, 2, 0], t[1, 3, 0]
        e0, e1, e2, e3 = t[1, 0, 1], t[1, 1, 1], t[1, 2, 1], t[1, 3, 1]
        m0, m1, m2, m3 = t[1, 0, 2], t[1, 1, 2], t[1, 2, 2], t[1, 3, 2]
        n0, n1, n2, n3 = t[1, 0, 3], t[1, 1, 3], t[1, 2, 3], t[1, 3, 3]
        pr0, pi0, pr1, pi1 = p_re[q, 0], p_im[q, 0], p_re[q, 1], p_im[q, 1]
        for b in range(nb):
            x0, x1, x2, x3 = trig[0, b], trig[1, b], trig[2, b], trig[3, b]
            y0, y1, y2, y3 = trig[4, b], trig[5, b], trig[6, b], trig[7, b]
            big0 = c0 + a0 * x0 + b0 * y0 + a1 * x1 + b1 * y1 + a2 * x2 + b2 * y2 + a3 * x3 \
                + b3 * y3
            slope0 = h0 * x0 - g0 * y0 + h1 * x1 - g1 * y1 + h2 * x2 - g2 * y2 + h3 * x3 \
                - g3 * y3
            big1 = c1 + d0 * x0 + e0 * y0 + d1 * x1 + e1 * y1 + d2 * x2 + e2 * y2 + d3 * x3 \
                + e3 * y3
            slope1 = n0 * x0 - m0 * y0 + n1 * x1 - m1 * y1 + n2 * x2 - m2 * y2 + n3 * x3 \
                - m3 * y3
            lr, li = trig[8, b], trig[10, b]
            mr0, mi0 = pr0 * lr - pi0 * li, pr0 * li + pi0 * lr
            lr, li = trig[9, b], trig[11, b]
            mr1, mi1 = pr1 * lr - pi1 * li, pr1 * li + pi1 * lr
            nr0, ni0, nr1, ni1 = mr0 * big0, mi0 * big0, mr1 * big1, mi1 * big1
            acc_re[q, b] = nr0 + nr1
            acc_im[q, b] = ni0 + ni1
            acc_re[4 + q, b] = mr0 * slope0 + ky0 * ni0 + mr1 * slope1 + ky1 * ni1
            acc_im[4 + q, b] = mi0 * slope0 - ky0 * nr0 + mi1 * slope1 - ky1 * nr1
            acc_re[8 + q, b] = kz0 * ni0 + kz1 * ni1
            acc_im[8 + q, b] = -(kz0 * nr0 + kz1 * nr1)


_BLOCK = 256
# Targets sorted by quad at a time (their angles, quads, order and weights come to about
# 1 MiB, this machine's L2 per core), so that on a grid each quad's share fills fuller
# batches: 16,384 ran 7-9 % faster than 4,096 on the wide-3x5 grid, equal on one quad
# (4,096 to 32,768 measured as above).
_SPAN = 16384


@_jit
def solve_targets(  # pragma: no cover
    angle, other, scale, quad, tab_re, tab_im, k, iy, iz,
    y_coords, y_direct, y_indirect, y_mirror, y_progression,
    z_coords, z_direct, z_indirect, z_mirror, z_progression,
    phase_origin, phase_table, centrosymmetric, fold_re, fold_im, fold_iy, fold_iz,
    sep_y_re, sep_y_im, sep_z_re, sep_z_im, row_scale, curvature, tol, codes, weights, reason,
    margin, locate, column_az, row_el, lines, boxes, edge_tol, raster, raster_frame,
    row_z, row_yc, row_center, deltas, delta_step, pair, row_p_re, row_p_im,
):
    """Solve every target whose ``quad`` is >= 0; other rows are left as they are.

    With ``locate`` the quads are found first (``angle, other`` in degrees): the candidate
    quad from the grid's mean ``column_az`` and ``row_el`` when the target lies in it
    (``lines, boxes, edge_tol`` as `quads.inside_quads`), else -1 (`quads.QuadGeometry.assign`
    scans the others for those few); ``raster, raster_frame``: `quads.locate_raster`'s (empty:
    none).

    ``angle, other``: azimuth and elevation (times ``scale`` gives radians), shape ``(N,)``.
    ``tab_re, tab_im``: per quad, the response table (`arrays.SourceResponse.table`) as
    ``(Q, 24, M)``, row ``term * 4 + fe``, column element ``v``; ``iy, iz`` the elements'
    distinct-coordinate indices, and the exponential plans of both coordinates. Per quad:
    ``phase_origin`` ``(Q, 4)`` (u0, s0, du, ds) and ``phase_table`` ``(Q, n + 2, n + 2)`` of
    the phase map, padded (`exact.ExactTables`; ``phase_table.shape[1] == 0``: none),
    ``curvature`` ``(Q,)`` whether to test for a local maximum. ``fold_re, fold_im``
    ``(Q, 12, H)`` and ``fold_iy, fold_iz`` ``(H,)``: a centro-symmetric array's real rows
    folded onto one element of each mirror pair (`exact.ExactTables`), summed over the ``H``
    elements kept where only the real part is needed. ``sep_y_re, sep_y_im`` ``(Q, 8, ny)``
    and ``sep_z_re, sep_z_im`` ``(Q, 8, nz)``: on a grid, the real rows' factors over y and z
    (`exact.ExactTables`; ``nz == 0``: none), used instead of the fold. ``row_z ... row_p_im``:
    the array's rows of equal z, each symmetric in y about its centre (`exact.RowFactors`;
    ``row_z.size == 0``: none), from which complex responses of plane-wave FEs are summed
    (`_row_sums`) where no curvature is tested. Writes ``weights``
    ``(N, 4)`` (normalized, 0 unless OK), ``reason`` and, where tested, ``margin`` (NaN
    elsewhere; an empty ``margin``: not wanted).

    Targets are taken quad by quad (a counting sort) in blocks: the exponentials and the
    response sums and the weights run over a block at once (vector instructions); targets
    whose phase iterates are solved in batches per quad (`_iterate_batch`).
    """
    n_quads = tab_re.shape[0]
    n_elements = iy.size
    phase_tol = tol[_PHASE]
    if locate:
        _locate(angle, other, column_az, row_el, lines, boxes, edge_tol, raster, raster_frame,
                quad)
    has_phase = phase_table.shape[1] > 0
    stride = phase_table.shape[2]
    phase_flat = phase_table.reshape(n_quads, -1)
    separable = sep_z_re.shape[2] > 0
    us = np.empty(_BLOCK)
    ss = np.empty(_BLOCK)
    step_re = np.empty(_BLOCK)
    step_im = np.empty(_BLOCK)
    ey_re = np.empty((y_coords.size, _BLOCK))
    ey_im = np.empty((y_coords.size, _BLOCK))
    ez_re = np.empty((z_coords.size, _BLOCK))
    ez_im = np.empty((z_coords.size, _BLOCK))
    look_re = np.empty((n_elements, _BLOCK))
    look_im = np.empty((n_elements, _BLOCK))
    acc_re = np.zeros((24, _BLOCK))
    acc_im = np.zeros((24, _BLOCK))
    work = np.empty((7, _BLOCK))
    out = np.empty((4, _BLOCK))
    code = np.empty(_BLOCK, dtype=np.uint8)
    ok_code, fail_code = codes[_OK], codes[_NO_SOLUTION]
    patch = np.empty((9, _BLOCK))
    # Targets whose phase iterates, gathered per quad and solved together (`_iterate_batch`):
    # their index, looks, and weights, ok and phase residual at the map's phase.
    pend_n = np.empty(_BLOCK, dtype=np.int64)
    pend_look_re = np.empty((n_elements, _BLOCK))
    pend_look_im = np.empty((n_elements, _BLOCK))
    pend_state = np.empty((6, _BLOCK))
    batch = np.empty((5, 12, _BLOCK))
    by_rows = row_z.size > 0
    row_trig = np.empty((2 * OFFSETS + 2 * ROWS, _BLOCK))
    # Spans of targets small enough for the caches; in each, a counting sort by quad (each
    # quad's table is then read for whole blocks).
    count = np.zeros(n_quads + 1, dtype=np.int64)
    fill = np.zeros(n_quads, dtype=np.int64)
    order = np.empty(min(_SPAN, angle.size), dtype=np.int64)
    for span in range(0, angle.size, _SPAN):
        end = min(span + _SPAN, angle.size)
        count[:] = 0
        for n in range(span, end):
            if quad[n] >= 0:
                count[quad[n] + 1] += 1
        for q in range(n_quads):
            count[q + 1] += count[q]
        fill[:] = count[:n_quads]
        for n in range(span, end):
            if quad[n] >= 0:
                order[fill[quad[n]]] = n
                fill[quad[n]] += 1
        for qd in range(n_quads):
            test = curvature[qd]
            # Real-valued responses need only the real part (centro-symmetric, no curvature).
            real_only = centrosymmetric and not test
            table_re = tab_re[qd]
            table_im = tab_im[qd]
            # The quad's views taken here, not per block: each view is a reference count (an
            # atomic the threads contend for) and their blocks' calls more.
            pair_q, p_re_q, p_im_q = pair[qd], row_p_re[qd], row_p_im[qd]
            if has_phase:
                # Evaluate in the frame rotated by the expected phase of B (see `exact`).
                origin = phase_origin[qd]
                u0, s0, du, ds = origin[0], origin[1], origin[2], origin[3]
                table = phase_flat[qd]
            pending = 0
            for start in range(count[qd], count[qd + 1], _BLOCK):
                nb = min(_BLOCK, count[qd + 1] - start)
                # Gather the block's angles first: the sines and cosines then vectorize.
                for b in range(nb):
                    n = order[start + b]
                    us[b] = angle[n] * scale
                    ss[b] = other[n] * scale
                for b in range(nb):
                    sin_az, _ = _sincos(us[b])
                    sin_el, cos_el = _sincos(ss[b])
                    us[b] = cos_el * sin_az
                    ss[b] = sin_el
                rows = by_rows and not test and not centrosymmetric
                if rows:
                    # Complex responses of plane-wave FEs, row by row: no looks, half the
                    # multiply-adds (`_row_sums`); every row complex (their phase may iterate).
                    if has_phase:
                        _phase_block(us, ss, u0, s0, du, ds, table, stride, step_re, patch, nb)
                    else:
                        step_re[:nb] = 0.0
                    _row_sums(acc_re, acc_im, us, ss, step_re, k, row_z, row_yc, row_center,
                              deltas, delta_step, pair_q, p_re_q, p_im_q, row_trig,
                              nb)
                else:
                    _exp_rows(ey_re, ey_im, step_re, step_im, k, y_coords, y_direct,
                              y_indirect, y_mirror, y_progression, us, nb)
                if rows:
                    pass
                elif has_phase and z_direct.size == z_coords.size and not z_progression:
                    # exp(-j (k z s + phase)) in one: a sine and cosine per coordinate, not one
                    # more per target and a product per coordinate (the AWR1843BOOST's two z:
                    # 1.02-1.03x). Coordinates taken as conjugates or by steps keep the product.
                    _phase_block(us, ss, u0, s0, du, ds, table, stride, step_re, patch, nb)
                    for i in range(z_coords.size):
                        phase = -k * z_coords[i]
                        for b in range(nb):
                            sin_t, cos_t = _sincos(phase * ss[b] - step_re[b])
                            ez_re[i, b] = cos_t
                            ez_im[i, b] = sin_t
                elif has_phase:
                    _exp_rows(ez_re, ez_im, step_re, step_im, k, z_coords, z_direct, z_indirect,
                              z_mirror, z_progression, ss, nb)
                    _phase_block(us, ss, u0, s0, du, ds, table, stride, step_re, patch, nb)
                    for b in range(nb):  # apart from the table look-ups: vectorizes
                        sin_p, cos_p = _sincos(step_re[b])
                        step_re[b] = cos_p
                        step_im[b] = -sin_p
                    for i in range(z_coords.size):
                        for b in range(nb):
                            re, im = ez_re[i, b], ez_im[i, b]
                            ez_re[i, b] = re * step_re[b] - im * step_im[b]
                            ez_im[i, b] = re * step_im[b] + im * step_re[b]
                else:
                    _exp_rows(ez_re, ez_im, step_re, step_im, k, z_coords, z_direct, z_indirect,
                              z_mirror, z_progression, ss, nb)
                # Real responses: the looks of the folded elements only (their mirrors' are
                # their conjugates, folded into the table); on a grid, or by rows, none.
                n_looks = fold_iy.size if real_only else n_elements
                if (real_only and separable) or rows:
                    n_looks = 0
                look_y = fold_iy if real_only else iy
                look_z = fold_iz if real_only else iz
                for v in range(n_looks):
                    jy, jz = look_y[v], look_z[v]
                    for b in range(nb):
                        yr, yi, zr, zi = ey_re[jy, b], ey_im[jy, b], ez_re[jz, b], ez_im[jz, b]
                        look_re[v, b] = yr * zr - yi * zi
                        look_im[v, b] = yr * zi + yi * zr
                if rows:
                    pass
                elif real_only and separable:
                    # Products of sums over y and over z (acc_im: scratch).
                    _grid_sums(acc_re, acc_im, sep_y_re[qd], sep_y_im[qd], ey_re, ey_im,
                               y_direct, sep_z_re[qd], sep_z_im[qd], ez_re, ez_im, z_direct, nb)
                elif real_only:
                    _real_sums(acc_re, fold_re[qd], fold_im[qd], look_re, look_im, 0, 12,
                               n_looks, nb)
                elif test:
                    _complex_sums(acc_re, acc_im, table_re, table_im, look_re, look_im, 0, 24,
                                  n_elements, nb)
                else:
                    # f complex (its phase residual), the derivatives' real parts only (the
                    # weights); `_iterate_batch` sums every row complex again for the targets
                    # whose phase iterates (acc_im's rows 4-11 are not written here).
                    _complex_sums(acc_re, acc_im, table_re, table_im, look_re, look_im, 0, 4,
                                  n_elements, nb)
                    _real_sums(acc_re, table_re, table_im, look_re, look_im, 4, 12, n_elements,
                               nb)
                _max_gain_weights_block(acc_re, nb, row_scale, tol, work)
                if not centrosymmetric:
                    # Phase residual at phase 0; NaN where the series does not apply.
                    for b in range(nb):
                        w = _row(work, 0, b)
                        work[5, b] = _atan_small(_dot(_row(acc_im, 0, b), w),
                                                 _dot(_row(acc_re, 0, b), w))
                if test:
                    for b in range(nb):
                        _solve_one(order[start + b], acc_re, acc_im, b, _row(work, 0, b),
                                   work[4, b] != 0.0, work[5, b], centrosymmetric, test,
                                   row_scale, tol, codes, weights, reason, margin)
                    continue
                # Solved at phase 0 (or not at all), no curvature test: the common case. What
                # `_store` writes, for every target at once (a vector loop), then written out;
                # targets whose phase iterates are overwritten when their batch is solved.
                for b in range(nb):
                    ok = work[4, b] != 0.0
                    w = _row(work, 0, b)
                    top = _larger(_larger(w[0], w[1]), _larger(w[2], w[3]))
                    top = top if top > 0.0 else 1.0
                    for q in range(4):
                        out[q, b] = w[q] / top if ok else 0.0
                    code[b] = ok_code if ok else fail_code
                for b in range(nb):
                    n = order[start + b]
                    for q in range(4):
                        weights[n, q] = out[q, b]
                    reason[n] = code[b]
                if margin.size:
                    for b in range(nb):
                        margin[order[start + b]] = np.nan
                if centrosymmetric:
                    continue
                for b in range(nb):
                    if not abs(work[5, b]) <= phase_tol:
                        # The phase iterates (feasible or not at the map's phase: feasibility
                        # is judged at the fixed point), with the quad's other such targets.
                        if pending == _BLOCK:
                            _iterate_batch(pend_n, pend_look_re, pend_look_im, pend_state,
                                           pending, table_re, table_im, n_elements, batch,
                                           row_scale, tol, codes, weights, reason, margin,
                                           rows)
                            pending = 0
                        pend_n[pending] = order[start + b]
                        if rows:  # their sums, every row complex (`_iterate_batch`)
                            for r in range(12):
                                batch[0, r, pending] = acc_re[r, b]
                                batch[1, r, pending] = acc_im[r, b]
                        else:
                            for v in range(n_elements):
                                pend_look_re[v, pending] = look_re[v, b]
                                pend_look_im[v, pending] = look_im[v, b]
                        for i in range(6):
                            pend_state[i, pending] = work[i, b]
                        pending += 1
            if pending:
                _iterate_batch(pend_n, pend_look_re, pend_look_im, pend_state, pending,
                               table_re, table_im, n_elements, batch, row_scale, tol, codes,
                               weights, reason, margin, by_rows and not test)


@_jit
def _iterate_batch(pend_n, look_re, look_im, state, m, table_re, table_im, n_elements, batch,
                   row_scale, tol, codes, weights, reason, margin,
                   summed):  # pragma: no cover
    """`_solve_one` (no curvature test) of ``m`` targets of one quad, together.

    ``pend_n`` the targets' indices, ``look_re, look_im`` their looks (columns ``< m``),
    ``state`` rows 0-3 their weights, 4 ok (1.0 or 0.0) and 5 their phase residual at the
    map's phase (NaN: not computed). A target infeasible at ``tol[_INFEASIBLE]`` phases, at
    a converged one or bound farther than ``tol[_FAR]`` from the map's leaves without a
    solution (`exact.ExactQuad._iterate`). Their responses are summed again from the looks (all 12
    rows complex), and each secant step runs over the targets still iterating as vector loops
    (rotation, `_max_gain_weights_block`, phase residual); a target leaves (and is stored) when
    `_solve_one` would leave, and the rest move down to keep the columns contiguous. Same steps
    and same results as `_solve_one` target by target, which ran one scalar step after
    another: on the AWR1843BOOST (6 % of targets iterate) the iteration and the stores took
    14 ns per target that way and 5.8 so (measured by running that part twice), less since
    targets that stay in place are not moved by a call (`_move`).

    ``batch``: scratch ``(5, 12, B)``; with ``summed`` its first two hold the targets'
    responses already (all 12 rows complex, `_row_sums`), and the looks are not read.
    """
    f_re, f_im, rot, work, per = batch[0], batch[1], batch[2], batch[3], batch[4]
    phi, prev_phi, prev_res, cos_phi, sin_phi, y, x, bad = (per[0], per[1], per[2], per[3],
                                                            per[4], per[5], per[6], per[7])
    infeasible_steps, far = tol[_INFEASIBLE], tol[_FAR]
    phase_tol = tol[_PHASE]
    if not summed:
        _complex_sums(f_re, f_im, table_re, table_im, look_re, look_im, 0, 12, n_elements, m)
    # The start, as `_solve_one`: targets converged once their residual is computed leave.
    active = 0
    for j in range(m):
        w = _row(state, 0, j)
        res = state[5, j]
        if res != res:
            res = _phase_residual(_row(f_re, 0, j), _row(f_im, 0, j), w, 1.0, 0.0)
        if abs(res) <= phase_tol or (state[4, j] == 0.0 and not abs(res) <= far):
            _leave(pend_n[j], w, state[4, j] != 0.0, True, codes, weights, reason, margin)
            continue
        bad[active] = 0.0 if state[4, j] != 0.0 else 1.0
        if j != active:  # not called to stay in place: see `_move`
            _move(f_re, f_im, state, j, active, pend_n)
        prev_phi[active] = 0.0
        prev_res[active] = res
        phi[active] = res
        for q in range(4):
            work[q, active] = w[q]
        active += 1
    for _ in range(int(tol[_ITERATIONS])):
        if active == 0:
            return
        for k in range(active):  # vector loops over the targets still iterating
            sin_p, cos_p = _sincos(phi[k])
            cos_phi[k], sin_phi[k] = cos_p, sin_p
        # Row by row: rotating the twelve rows in the loop above, target by target, took 120 ns
        # per iterating target, this 3 (measured on a batch of the AWR1843BOOST's).
        for r in range(12):
            for k in range(active):
                rot[r, k] = cos_phi[k] * f_re[r, k] + sin_phi[k] * f_im[r, k]
        _max_gain_weights_block(rot, active, row_scale, tol, work)
        for k in range(active):
            w = _row(work, 0, k)
            b_re, b_im = _dot(_row(f_re, 0, k), w), _dot(_row(f_im, 0, k), w)
            c, sn = cos_phi[k], sin_phi[k]
            y[k] = b_im * c - b_re * sn
            x[k] = b_re * c + b_im * sn
            work[5, k] = _atan_small(y[k], x[k])
        kept = 0
        for k in range(active):
            res = work[5, k]
            if res != res:
                res = math.atan2(y[k], x[k])
            ok = work[4, k] != 0.0
            done = abs(res) <= phase_tol
            infeasible = bad[k] if ok else bad[k] + 1.0
            slope = (res - prev_res[k]) / (phi[k] - prev_phi[k] + 1e-300)
            # Secant step on g(phi) = arg(B(w(phi))) - phi; fixed-point step if flat.
            step = -res / slope if abs(slope) > 1e-3 else res
            if done or not (ok or (infeasible < infeasible_steps
                                   and abs(phi[k] + step) <= far)):  # as `_solve_one` breaks
                _leave(pend_n[k], _row(work, 0, k), ok, done, codes, weights, reason, margin)
                continue
            prev_phi[kept], prev_res[kept], phi[kept] = phi[k], res, phi[k] + step
            bad[kept] = infeasible
            if k != kept:
                _move(f_re, f_im, work, k, kept, pend_n)
            kept += 1
        active = kept
    for k in range(active):  # out of iterations: not converged (or no solution)
        _leave(pend_n[k], _row(work, 0, k), work[4, k] != 0.0, False, codes, weights, reason,
               margin)


@_jit
def _move(f_re, f_im, state, src, dst, pend_n):  # pragma: no cover
    """Column ``src`` of ``f_re, f_im``, ``state[:5]`` (weights, ok) and ``pend_n`` to ``dst``.

    Callers skip the call where ``src == dst``: numba counts the references to a call's arrays
    atomically, on entry and exit, and a call for every iterating target (most stay in place)
    took 4 % of the kernel on the AWR1843BOOST and 7 % on the wide-3x5 grid.
    """
    if src != dst:
        for r in range(f_re.shape[0]):
            f_re[r, dst] = f_re[r, src]
            f_im[r, dst] = f_im[r, src]
        for q in range(5):
            state[q, dst] = state[q, src]
        pend_n[dst] = pend_n[src]


@_jit
def _leave(n, w, ok, converged, codes, weights, reason, margin):  # pragma: no cover
    """Store target ``n`` as `_solve_one` does without a curvature test."""
    code = codes[_OK]
    if not (converged or not ok):
        code = codes[_NOT_CONVERGED]
    if not ok:
        code = codes[_NO_SOLUTION]
    _store(n, w, code, codes[_OK], weights, reason)
    if margin.size:
        margin[n] = np.nan


@_jit
def _solve_one(n, acc_re, acc_im, b, w, ok, res, centrosymmetric, test, row_scale, tol, codes,
               weights, reason, margin):  # pragma: no cover
    """Weights of target ``n`` from column ``b`` of its responses (rows ``term * 4 + fe``).

    ``w, ok``: `_max_gain_weights` of its unrotated responses; ``res`` their phase residual
    (NaN: not computed yet).
    """
    converged = True
    if not centrosymmetric:
        # `exact.ExactQuad._iterate`: secant steps on the phase fixed point.
        f_re, f_im = _row(acc_re, 0, b), _row(acc_im, 0, b)
        if res != res:
            res = _phase_residual(f_re, f_im, w, 1.0, 0.0)
        prev_phi = 0.0
        prev_res = res
        phi = res
        converged = abs(res) <= tol[_PHASE]
        bad = 0.0 if ok else 1.0
        if not converged and (ok or abs(phi) <= tol[_FAR]):
            for _ in range(int(tol[_ITERATIONS])):
                sn, c = _sincos(phi)
                w, ok = _max_gain_weights(_rotated(acc_re, acc_im, 0, b, c, sn),
                                          _rotated(acc_re, acc_im, 4, b, c, sn),
                                          _rotated(acc_re, acc_im, 8, b, c, sn), row_scale, tol)
                res = _phase_residual(f_re, f_im, w, c, sn)
                done = abs(res) <= tol[_PHASE]
                if done:
                    converged = True
                slope = (res - prev_res) / (phi - prev_phi + 1e-300)
                # Secant step on g(phi) = arg(B(w(phi))) - phi; fixed-point step if flat.
                step = -res / slope if abs(slope) > 1e-3 else res
                prev_phi = phi
                prev_res = res
                phi += step
                bad = bad if ok else bad + 1.0
                if done or not (ok or (bad < tol[_INFEASIBLE] and abs(phi) <= tol[_FAR])):
                    break
        converged = converged or not ok
    code = codes[_OK]
    if not converged:
        code = codes[_NOT_CONVERGED]
    if not ok:
        code = codes[_NO_SOLUTION]
    if test:
        # `exact._curvature_margin`: largest Hessian eigenvalue of |B|^2 / 2 over |B|^2.
        b0, b_u, b_s = _term(acc_re, acc_im, 0, b, w), _term(acc_re, acc_im, 1, b, w), \
            _term(acc_re, acc_im, 2, b, w)
        b_uu, b_us, b_ss = _term(acc_re, acc_im, 3, b, w), _term(acc_re, acc_im, 4, b, w), \
            _term(acc_re, acc_im, 5, b, w)
        cb = b0.conjugate()
        h_uu = (cb * b_uu).real + abs(b_u) ** 2
        h_us = (cb * b_us).real + (b_u.conjugate() * b_s).real
        h_ss = (cb * b_ss).real + abs(b_s) ** 2
        largest = 0.5 * (h_uu + h_ss) + math.sqrt(0.25 * (h_uu - h_ss) ** 2 + h_us**2)
        power = abs(b0) ** 2
        value = largest / (power if power > 0.0 else 1.0)
        if margin.size:
            margin[n] = value
        if code == codes[_OK] and not (value < 0.0):
            code = codes[_SPLIT]
    elif margin.size:
        margin[n] = np.nan
    _store(n, w, code, codes[_OK], weights, reason)


@_jit
def _term(acc_re, acc_im, term, b, w):  # pragma: no cover
    """``sum_q w_q`` times response ``term`` (f, f_u, f_s, f_uu, f_us, f_ss) of column ``b``."""
    return complex(_dot(_row(acc_re, 4 * term, b), w), _dot(_row(acc_im, 4 * term, b), w))


@_jit
def _store(n, w, code, ok_code, weights, reason):  # pragma: no cover
    """Write target ``n``: its reason and weights scaled to a largest of 1 (0 unless OK)."""
    reason[n] = code
    if code == ok_code:
        top = _larger(_larger(w[0], w[1]), _larger(w[2], w[3]))
        top = top if top > 0.0 else 1.0
        for q in range(4):
            weights[n, q] = w[q] / top
    else:
        for q in range(4):
            weights[n, q] = 0.0
