"""Exact weights: true FE directions, exact array response, any layout (DESIGN.md section 5.3).

With coherent channels the Bartlett output of the superposition is
``B(u, s) = sum_q w_q f_q(u, s)``, ``f_q = a(u, s)^H a(u_q, s_q)``. Stationarity at the set
direction is linear in the weights. Working in direction cosines ``(u, s)`` rather than angles is
a change of variables with the same maxima, and stays well conditioned near el = +-90 deg.

On the bench the FEs' echoes are not plane waves: the plan can give each FE's modeled response
vector ``r_q`` (`rts_scenario.responses`), and then ``f_q = a(u, s)^H r_q`` (DESIGN.md 5.5b).

Centro-symmetric arrays with plane-wave FEs have a real ``f``: the two stationarity equations
leave a 2-D null space in which the weights that maximize the peak gain ``f . w / |w|`` with
``w >= 0`` are the projection of ``f`` onto it, or, when that has a negative entry, the
projection onto the boundary ray where one weight is zero. Other arrays and modeled responses
make ``f`` complex; the condition ``Re(conj(B) dB) = 0`` is
linear once ``conj(B)`` is frozen, and the same step, iterated, converges in a few passes.

Every solution is checked to be a local maximum of ``|B|`` (negative definite Hessian); the
driver checks that it is the global one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from ..arrays import SourceResponse, VirtualArray, _ExpPlan, direction_cosines
from ..beamformer import power_curvature
from ..errors import SolverError
from ..quads import EDGE_TOL_DEG, QuadGeometry
from ..rig import Rig
from . import compiled
from .reasons import Reason

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# A weight more negative than this (relative to the largest) is infeasible; smaller ones are 0.
_NEGATIVE_TOL = 1e-9
# A constraint row shorter than this (relative to its scale) is absent: the FE gradients vanish.
_RANK_TOL = 1e-12
_MAX_ITERATIONS = 60
# Phases a target may be infeasible at while its phase moves: at a phase off B's, weights
# exist only farther from the region's edge, so a target near an edge that is infeasible at
# the phase map's phase iterates on with its clipped weights; infeasible at its own phase, or
# at this many, or bound for a phase farther than _INFEASIBLE_PHASE (rad) from the map's (a
# phase of another solution, if any), it has no solution. Near the slanted column the two
# quads of lab-2x3 share, the awr1843boost's fixed point lies up to 0.03 rad from the map's.
_INFEASIBLE_STEPS = 3
_INFEASIBLE_PHASE = 0.1
# Converged when B's phase matches the frozen one to this (rad). The angle error it leaves is
# about 2.5 deg per rad of phase on the shipped arrays: ~2.5e-8 deg.
_PHASE_TOL = 1e-8
# The chosen weights must carry at least this share of |f| (else they are rounding residue).
_GAIN_TOL = 1e-8
# Stationarity must hold to this relative residual after clipping.
_RESIDUAL_TOL = 1e-9


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.einsum("qn,qn->n", a, b)


def max_gain_weights(
    f: FloatArray, r1: FloatArray, r2: FloatArray, row_scale: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Maximize ``f . w / |w|`` subject to ``r1 . w = 0``, ``r2 . w = 0`` and ``w >= 0``.

    All inputs have shape ``(4, N)`` (one column per target). Returns ``(w, ok)``: ``w``
    (unnormalized, >= 0, shape ``(4, N)``) and whether a solution with positive gain exists.
    Closed form, vectorized over N.
    """
    def unit(v: FloatArray) -> FloatArray:
        norm = np.sqrt(_dot(v, v))
        keep = norm > _RANK_TOL * row_scale
        return v * np.where(keep, 1.0 / np.where(keep, norm, 1.0), 0.0)

    e1 = unit(r1)
    e2 = unit(r2 - _dot(r2, e1) * e1)
    w = f - _dot(f, e1) * e1 - _dot(f, e2) * e2
    norm = np.sqrt(_dot(w, w))
    # A projection of f that is a rounding residue (f almost orthogonal to the null space)
    # has no meaningful direction: require a real share of the gain.
    gain_floor = _GAIN_TOL * np.sqrt(_dot(f, f))
    ok = (w.min(axis=0) >= -_NEGATIVE_TOL * norm) & (norm > gain_floor)
    fix = np.flatnonzero(~ok)
    if fix.size:
        w[:, fix], ok[fix] = _boundary_ray(
            f[:, fix], w[:, fix], e1[:, fix], e2[:, fix], gain_floor[fix]
        )
    w = np.maximum(w, 0.0)
    # Clipping rounding negatives must not break stationarity: verify it.
    w_norm = np.sqrt(_dot(w, w))
    for r in (r1, r2):
        # A row below the rank floor was dropped as zero: it is held to that floor.
        bound = np.maximum(_RESIDUAL_TOL * np.sqrt(_dot(r, r)), _RANK_TOL * row_scale)
        ok &= np.abs(_dot(r, w)) <= bound * w_norm
    return w, ok


def _boundary_ray(
    f: FloatArray, w: FloatArray, e1: FloatArray, e2: FloatArray, gain_floor: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Fast path of `_boundary_rays`: zero the single most negative weight.

    When that candidate is feasible it is the optimum (one active constraint, KKT); the rest
    go through the full search over every boundary ray.
    """
    k = np.argmin(w, axis=0)
    cols = np.arange(w.shape[1])
    e1k, e2k = e1[k, cols], e2[k, cols]
    p_k = -(e1 * e1k + e2 * e2k)
    p_k[k, cols] += 1.0  # P e_k
    p_kk = p_k[k, cols]
    usable = p_kk > 1e-12
    cand = w - p_k * (w[k, cols] / np.where(usable, p_kk, 1.0))
    norm = np.sqrt(_dot(cand, cand))
    good = usable & (cand.min(axis=0) >= -_NEGATIVE_TOL * norm) & (norm > gain_floor)
    rest = np.flatnonzero(~good)
    if rest.size:
        cand[:, rest], good[rest] = _boundary_rays(
            f[:, rest], w[:, rest], e1[:, rest], e2[:, rest], gain_floor[rest]
        )
    return cand, good


def _boundary_rays(
    f: FloatArray, w: FloatArray, e1: FloatArray, e2: FloatArray, gain_floor: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Best ray of the cone {w >= 0} in the null space when the projection of f leaves it.

    Candidate k also forces ``w_k = 0``: the projection of ``f`` onto that line is
    ``w - w_k / P_kk * P e_k`` (P the projector onto the null space; its row k is ``P e_k``).
    Each candidate is a projection of f, so its gain ``f . w / |w|`` equals ``|w|``.
    """
    proj = np.eye(4)[:, :, None] - e1[:, None, :] * e1[None, :, :] - e2[:, None, :] * e2[None]
    p_kk = np.einsum("kkn->kn", proj)
    usable = p_kk > 1e-12
    ratio = np.where(usable, w / np.where(usable, p_kk, 1.0), 0.0)
    candidates = w[None, :, :] - ratio[:, None, :] * proj  # [k, q, n]
    norm = np.sqrt(np.einsum("kqn,kqn->kn", candidates, candidates))
    valid = usable & (candidates.min(axis=1) >= -_NEGATIVE_TOL * norm)
    valid &= norm > gain_floor
    best = np.argmax(np.where(valid, norm, -1.0), axis=0)
    chosen = np.take_along_axis(candidates, best[None, None, :], axis=0)[0]
    return chosen, valid.any(axis=0)


@dataclass(frozen=True)
class ExactQuad:
    """Per-quad precomputation of the exact method: the FEs' response kernel.

    ``check_local_max`` is cleared by the solver's plan for quads where a grid of nodes shows a
    clearly negative definite Hessian everywhere, which saves the second derivatives.
    """

    response: SourceResponse
    centrosymmetric: bool
    row_scale: float
    check_local_max: bool = True
    phase_map: PhaseMap | None = None

    # The plan passes the FEs' modeled response vectors (`rts_scenario.responses`) to `build`.
    uses_response_vectors = True

    @classmethod
    def build(
        cls,
        rig: Rig,
        array: VirtualArray,
        fes: NDArray[np.int64],
        vectors: ComplexArray | None = None,
    ) -> ExactQuad:
        """Precompute the response of the quad's four FEs for ``array``.

        ``vectors`` (shape ``(M, 4)``): the FEs' response vectors on the array, when modeled;
        default their plane-wave steering vectors. Modeled vectors make ``f`` complex whatever
        the layout (a near-field wavefront is not symmetric about the centroid).
        """
        extent = max(np.ptp(array.y_m), np.ptp(array.z_m))
        if np.ptp(array.y_m) == 0.0 or np.ptp(array.z_m) == 0.0:
            raise SolverError(
                f"array {array.name!r}: a 2-D angle needs elements spread along y and along z; "
                f"this layout is a line"
            )
        u, s = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
        quad = cls(
            response=array.source_response(u, s, vectors),
            centrosymmetric=array.is_centrosymmetric and vectors is None,
            row_scale=array.wavenumber_rad_per_m * extent * array.n_elements,
        )
        if quad.centrosymmetric:
            return quad
        return replace(quad, phase_map=PhaseMap.build(quad, u, s))

    def solve(
        self, az_rad: FloatArray, el_rad: FloatArray
    ) -> tuple[FloatArray, NDArray[np.uint8]]:
        """Return ``(weights (N, 4), reason (N,))`` for targets in this quad."""
        w, reason, _ = self.solve_with_curvature(az_rad, el_rad, self.check_local_max)
        return w, reason

    def solve_with_curvature(
        self, az_rad: FloatArray, el_rad: FloatArray, curvature: bool
    ) -> tuple[FloatArray, NDArray[np.uint8], FloatArray | None]:
        """Solve; with ``curvature``, also test for a local maximum and return its margin.

        The margin is the Hessian eigenvalue of ``|B|^2 / 2`` closest to zero, relative to
        ``|B|^2``; negative at a strict local maximum. Runs the compiled kernel when it is
        available (`rts_scenario.solver.compiled`), else `solve_numpy`.
        """
        n = np.size(az_rad)
        # Counted by `solve_weights` (the driver) already, not again per quad.
        kernel = compiled.exact_kernel(0)
        if kernel is None:
            return self.solve_numpy(az_rad, el_rad, curvature)
        weights = np.empty((n, 4))
        reason = np.empty(n, dtype=np.uint8)
        margin = np.empty(n if curvature else 0)
        self._tables.solve(kernel, az_rad, el_rad, 1.0, np.zeros(n, dtype=np.int64), weights,
                           reason, margin, curvature=np.array([curvature]))
        return weights, reason, margin if curvature else None

    @cached_property
    def _tables(self) -> ExactTables:
        return ExactTables.of([self])

    def solve_numpy(
        self, az_rad: FloatArray, el_rad: FloatArray, curvature: bool
    ) -> tuple[FloatArray, NDArray[np.uint8], FloatArray | None]:
        """`solve_with_curvature` in numpy, vectorized over the targets (the reference)."""
        u, s = direction_cosines(az_rad, el_rad)
        # For complex responses, evaluate in the frame rotated by the expected phase of B, where
        # the solution is (nearly) the real one; |B| and the weights do not depend on the frame.
        phase = None if self.phase_map is None else self.phase_map(u, s)
        resp = self.response.evaluate(u, s, terms=6 if curvature else 3, phase=phase)
        f, f_u, f_s = resp[0], resp[1], resp[2]
        reason = np.full(u.shape, Reason.OK, dtype=np.uint8)
        if self.centrosymmetric:
            w, ok = max_gain_weights(f.real, f_u.real, f_s.real, self.row_scale)
        else:
            w, ok, converged = self._iterate(f, f_u, f_s)
            reason[~converged] = Reason.NOT_CONVERGED
        reason[~ok] = Reason.NO_SOLUTION
        margin = None
        if curvature:
            margin = _curvature_margin(w, resp)
            reason[(reason == Reason.OK) & ~(margin < 0.0)] = Reason.SPLIT
        top = w.max(axis=0)
        w = w / np.where(top > 0.0, top, 1.0)
        w[:, reason != Reason.OK] = 0.0
        return w.T, reason, margin

    def _iterate(
        self, f: ComplexArray, f_u: ComplexArray, f_s: ComplexArray
    ) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
        """Solve ``Re(conj(B) dB) = 0`` for complex responses, starting at phase 0.

        With the phase ``phi`` of ``B`` frozen the problem is the real one above, so the
        solution is a function ``w(phi)`` and only the scalar fixed point
        ``phi = arg(f . w(phi))`` remains; secant steps on it converge in a few passes, and in
        the frame of the quad's precomputed phase map the start is usually already converged.
        Feasibility is judged at the fixed point: a target infeasible at the map's phase (near
        the edge of the region the quad synthesizes, which moves with the phase) iterates on
        with its clipped weights, until it was infeasible at `_INFEASIBLE_STEPS` phases or is
        bound farther than `_INFEASIBLE_PHASE` from the map's.
        """
        phi = np.zeros(f.shape[1])
        w, ok = max_gain_weights(f.real, f_u.real, f_s.real, self.row_scale)
        residual = _phase_residual(f, w, phi)
        prev_phi, prev_res = phi, residual
        phi = phi + residual
        converged = np.abs(residual) <= _PHASE_TOL
        infeasible = (~ok).astype(np.int64)
        active = np.flatnonzero(~converged & (ok | (np.abs(phi) <= _INFEASIBLE_PHASE)))
        for _ in range(_MAX_ITERATIONS):
            if active.size == 0:
                break
            cos, sin = np.cos(phi[active]), np.sin(phi[active])

            def rotate(g: ComplexArray, c: FloatArray = cos, s: FloatArray = sin) -> FloatArray:
                return c * g.real + s * g.imag  # Re(exp(-j phi) g)

            fa = f[:, active]
            w_a, ok_a = max_gain_weights(
                rotate(fa), rotate(f_u[:, active]), rotate(f_s[:, active]), self.row_scale
            )
            w[:, active] = w_a
            ok[active] = ok_a
            res = _phase_residual(fa, w_a, phi[active])
            done = np.abs(res) <= _PHASE_TOL
            converged[active[done]] = True
            slope = (res - prev_res[active]) / (phi[active] - prev_phi[active] + 1e-300)
            # Secant step on g(phi) = arg(B(w(phi))) - phi; the fixed-point step if g is flat.
            secant = np.abs(slope) > 1e-3
            step = np.where(secant, -res / np.where(secant, slope, 1.0), res)
            prev_phi = prev_phi.copy()
            prev_res = prev_res.copy()
            prev_phi[active], prev_res[active] = phi[active], res
            phi = phi.copy()
            phi[active] += step
            infeasible[active] += ~ok_a
            stay = ok_a | ((infeasible[active] < _INFEASIBLE_STEPS)
                           & (np.abs(phi[active]) <= _INFEASIBLE_PHASE))
            active = active[~done & stay]
        return w, ok, converged | ~ok


@dataclass(frozen=True)
class PhaseMap:
    """Phase of ``B`` at the solution over a quad, tabulated for a close starting point.

    Bicubic interpolation on a regular grid in ``(u, s)`` over the quad's bounding box; the
    iteration only corrects what interpolation misses (at kinks where a weight reaches 0).
    """

    u0: float
    s0: float
    du: float
    ds: float
    table: FloatArray

    NODES = 129

    @classmethod
    def build(cls, quad: ExactQuad, fe_u: FloatArray, fe_s: FloatArray) -> PhaseMap:
        """Solve the quad's node grid from phase 0 and keep the converged phases."""
        def axis(values: FloatArray) -> FloatArray:
            # A quad collapsed along an axis still gets a (tiny) table extent.
            half = max(np.ptp(values) / 2, 1e-6)
            mid = (values.min() + values.max()) / 2
            return np.linspace(mid - half, mid + half, cls.NODES)

        gu, gs = axis(fe_u), axis(fe_s)
        u, s = (g.ravel() for g in np.meshgrid(gu, gs, indexing="ij"))
        resp = quad.response.evaluate(u, s, terms=3)
        w, ok, converged = quad._iterate(resp[0], resp[1], resp[2])
        phi = np.angle(np.einsum("qn,qn->n", resp[0], w))
        phi = np.where(ok & converged, phi, 0.0)
        return cls(u0=float(gu[0]), s0=float(gs[0]), du=float(gu[1] - gu[0]),
                   ds=float(gs[1] - gs[0]), table=phi.reshape(cls.NODES, cls.NODES))

    def __call__(self, u: FloatArray, s: FloatArray) -> FloatArray:
        """Interpolated phase at ``(u, s)`` (Catmull-Rom bicubic; clamped outside the box)."""
        last = self.NODES - 1
        x = np.clip((u - self.u0) / self.du, 0.0, last)
        y = np.clip((s - self.s0) / self.ds, 0.0, last)
        i = np.minimum(x.astype(np.int64), last - 1)
        j = np.minimum(y.astype(np.int64), last - 1)
        wx, wy = _catmull_rom(x - i), _catmull_rom(y - j)
        flat = self.table.ravel()
        cols = [np.clip(j + b - 1, 0, last) for b in range(4)]
        out = np.zeros(u.shape)
        for a in range(4):
            row = np.clip(i + a - 1, 0, last) * self.NODES
            out += wx[a] * sum(wy[b] * flat[row + cols[b]] for b in range(4))
        return out


@dataclass(frozen=True)
class ExactTables:
    """The exact quads of one array packed for the compiled kernel, one entry per quad.

    Attributes
    ----------
    tab_re, tab_im : ndarray, shape (Q, 24, M)
        ``SourceResponse.table`` of each quad as ``[term * 4 + fe, v]``, real and imaginary.
    phase_origin : ndarray, shape (Q, 4)
        ``u0, s0, du, ds`` of each quad's `PhaseMap`.
    phase_table : ndarray, shape (Q, n + 2, n + 2)
        Each quad's `PhaseMap` table with its edge nodes repeated once around it (the kernel
        then reads every target's 4 x 4 nodes without clamping); shape ``(Q, 0, 0)`` for real
        responses (no phase map).
    curvature : ndarray, shape (Q,), bool
        ``check_local_max`` of each quad.
    response : SourceResponse
        The first quad's response (the layout and exponential plans all quads share).
    centrosymmetric : bool
    row_scale : float
    y_indirect, z_indirect : ndarray of int
        Coordinates whose exponential is the conjugate of another's (see `arrays._ExpPlan`).
    fold_re, fold_im : ndarray, shape (Q, 12, H)
        For a centro-symmetric array, the real responses' rows (f, f_u, f_s) summed per place
        (elements at one position) and folded onto one place of each mirror pair: a place's
        look is the conjugate of its mirror's, so ``Re(t_v a_v + t_m a_m) = Re((t_v +
        conj(t_m)) a_v)`` and the kernel sums H (about M / 2) places instead of M elements
        (`_fold`). Shape ``(Q, 12, 0)`` otherwise.
    fold_iy, fold_iz : ndarray of int, shape (H,)
        The distinct-coordinate indices of the places kept.
    sep_y_re, sep_y_im : ndarray, shape (Q, 8, ny)
    sep_z_re, sep_z_im : ndarray, shape (Q, 8, nz)
        For a centro-symmetric grid, the real responses' factors over y and over z
        (`_grid_factors`): rows ``fe`` and ``4 + fe`` the FE's factor and its derivative,
        columns the distinct coordinates, folded as the places are. Shape ``(Q, 8, 0)``
        otherwise.
    rows : RowFactors
        For complex responses of plane-wave FEs on an array whose rows of equal z are each
        symmetric in y, the rows' factors (`RowFactors`, `_exact_kernel._row_sums`); none
        (``rows.z.size == 0``) otherwise.
    """

    tab_re: FloatArray
    tab_im: FloatArray
    phase_origin: FloatArray
    phase_table: FloatArray
    curvature: NDArray[np.bool_]
    response: SourceResponse
    centrosymmetric: bool
    row_scale: float
    y_indirect: NDArray[np.int64]
    z_indirect: NDArray[np.int64]
    fold_re: FloatArray
    fold_im: FloatArray
    fold_iy: NDArray[np.int64]
    fold_iz: NDArray[np.int64]
    sep_y_re: FloatArray
    sep_y_im: FloatArray
    sep_z_re: FloatArray
    sep_z_im: FloatArray
    rows: RowFactors

    @classmethod
    def of(cls, quads: Sequence[ExactQuad]) -> ExactTables:
        """Pack ``quads`` (built for the same array and kind of FE response)."""
        first = quads[0]
        if any(q.centrosymmetric != first.centrosymmetric or q.row_scale != first.row_scale
               or q.response.table.shape != first.response.table.shape for q in quads):
            raise SolverError("exact quads of different arrays cannot be packed together")
        # table[term, fe, v] -> [term * 4 + fe, v]
        tables = np.stack([q.response.table.reshape(-1, q.response.table.shape[-1])
                           for q in quads])
        maps = [q.phase_map for q in quads]
        if all(m is not None for m in maps):
            origin = np.array([[m.u0, m.s0, m.du, m.ds] for m in maps if m is not None])
            phase = np.stack([np.pad(m.table, 1, mode="edge") for m in maps if m is not None])
        else:
            origin, phase = np.zeros((len(quads), 4)), np.zeros((len(quads), 0, 0))
        resp = first.response
        if first.centrosymmetric:
            fold, fold_iy, fold_iz = _fold(resp, tables[:, :12])
        else:
            fold = np.zeros((len(quads), 12, 0), dtype=np.complex128)
            fold_iy = fold_iz = np.zeros(0, dtype=np.int64)
        factors = [_grid_factors(q.response) if first.centrosymmetric else None for q in quads]
        if all(f is not None for f in factors):
            sep_y = np.stack([f[0] for f in factors if f is not None])
            sep_z = np.stack([f[1] for f in factors if f is not None])
        else:
            sep_y = sep_z = np.zeros((len(quads), 8, 0), dtype=np.complex128)
        return cls(
            tab_re=np.ascontiguousarray(tables.real), tab_im=np.ascontiguousarray(tables.imag),
            phase_origin=origin, phase_table=np.ascontiguousarray(phase),
            curvature=np.array([q.check_local_max for q in quads]), response=first.response,
            centrosymmetric=first.centrosymmetric, row_scale=first.row_scale,
            y_indirect=first.response._y_plan.indirect,
            z_indirect=first.response._z_plan.indirect,
            fold_re=np.ascontiguousarray(fold.real), fold_im=np.ascontiguousarray(fold.imag),
            fold_iy=fold_iy, fold_iz=fold_iz,
            sep_y_re=np.ascontiguousarray(sep_y.real), sep_y_im=np.ascontiguousarray(sep_y.imag),
            sep_z_re=np.ascontiguousarray(sep_z.real), sep_z_im=np.ascontiguousarray(sep_z.imag),
            rows=(RowFactors.none(len(quads)) if first.centrosymmetric
                  else RowFactors.of([q.response for q in quads])),
        )

    def solve(
        self,
        kernel: ModuleType,
        az: FloatArray,
        el: FloatArray,
        scale: float,
        quad: NDArray[np.int64],
        weights: FloatArray,
        reason: NDArray[np.uint8],
        margin: FloatArray,
        curvature: NDArray[np.bool_] | None = None,
        geometry: QuadGeometry | None = None,
    ) -> None:
        """Solve the targets with ``quad >= 0`` in place (see `ExactQuad.solve_with_curvature`).

        ``az, el`` times ``scale`` are radians; ``quad`` indexes the packed quads;
        ``weights (N, 4)``, ``reason (N,)`` and ``margin`` (``(N,)``, or empty: not wanted)
        receive the results. ``curvature`` overrides the quads' local-maximum test. With the
        rig's ``geometry`` (``az, el`` in degrees, quads packed in the rig's order) ``quad`` is
        an output: each target's enclosing quad when it is the candidate cell of
        `rts_scenario.quads.candidate_quads`, else -1 (left unsolved: see
        `QuadGeometry.assign`).
        """
        resp = self.response
        y_plan, z_plan = resp._y_plan, resp._z_plan
        locate = geometry is not None
        if geometry is None:
            geometry = _NO_GEOMETRY
        kernel.solve_targets(
            np.ascontiguousarray(az, dtype=np.float64), np.ascontiguousarray(el, dtype=np.float64),
            scale, quad, self.tab_re, self.tab_im, resp.k, resp._iy, resp._iz,
            resp.y_distinct, y_plan.direct, self.y_indirect, y_plan.mirror, y_plan.progression,
            resp.z_distinct, z_plan.direct, self.z_indirect, z_plan.mirror, z_plan.progression,
            self.phase_origin, self.phase_table, self.centrosymmetric, self.fold_re,
            self.fold_im, self.fold_iy, self.fold_iz, self.sep_y_re, self.sep_y_im,
            self.sep_z_re, self.sep_z_im, self.row_scale,
            self.curvature if curvature is None else curvature, _TOLERANCES, _CODES,
            weights, reason, margin, locate,
            # Copies (tiny): one type for every geometry, so the kernel compiles once.
            *(np.array(a, dtype=np.float64, order="C") for a in (
                geometry.column_az_deg, geometry.row_el_deg, geometry.lines, geometry.boxes)),
            EDGE_TOL_DEG, geometry.raster, geometry.raster_frame,
            self.rows.z, self.rows.y, self.rows.centre, self.rows.offsets,
            self.rows.offset_step, self.rows.pair, self.rows.p_re, self.rows.p_im,
        )


# As `_exact_kernel.ROWS` and `_exact_kernel.OFFSETS` (that module loads numba).
ROWS, OFFSETS = 2, 4


@dataclass(frozen=True)
class RowFactors:
    """An array's rows of equal z, each symmetric in y, and FE factors over them (per quad).

    For plane-wave FEs the sum of FE ``q``'s response over row ``r`` is ``P_qr L_r(u, s)
    R_qr(u)`` with ``R_qr = centre_r + sum_i 2 count_ri cos(k offsets_i (u_q - u))`` real
    (`_exact_kernel._row_sums`): about half the multiply-adds of the sum element by element,
    and no per-element looks. The kernel's loops are unrolled for `ROWS` rows and up to
    `OFFSETS` offsets (the AWR1843BOOST's 2 and 4). Empty (``z.size == 0``) where the layout or
    the FE responses (modeled, not plane waves) do not factor so, or are of another size.

    Attributes
    ----------
    z, y : ndarray, shape (ROWS,)
        Each row's z and the y of its centre (metres).
    centre : ndarray, shape (ROWS,)
        Elements at the row's centre.
    count : ndarray of int, shape (ROWS, OFFSETS)
        Element pairs of the row at ``y +- offsets[i]``.
    offsets : ndarray, shape (OFFSETS,)
        The distinct offsets from a row's centre (> 0, increasing) over all rows, padded with
        zeros (no pair there).
    offset_step : float
        Their common difference when they form a progression of 3 or more, else 0.0.
    pair : ndarray, shape (Q, 4, ROWS, OFFSETS, 4)
        Per quad and FE: ``2 count cos(k d u_q)``, ``2 count sin(k d u_q)`` and the two times
        ``k d`` (``d = offsets[i]``).
    p_re, p_im : ndarray, shape (Q, 4, ROWS)
        ``P_qr = exp(j k (y_r u_q + z_r s_q))``.
    """

    z: FloatArray
    y: FloatArray
    centre: FloatArray
    count: NDArray[np.int64]
    offsets: FloatArray
    offset_step: float
    pair: FloatArray
    p_re: FloatArray
    p_im: FloatArray

    @classmethod
    def none(cls, n_quads: int) -> RowFactors:
        """Return no rows: the kernel then sums element by element."""
        empty = np.zeros(0)
        return cls(z=empty, y=empty, centre=empty, count=np.zeros((0, 0), dtype=np.int64),
                   offsets=empty, offset_step=0.0,
                   pair=np.zeros((n_quads, 4, ROWS, OFFSETS, 4)),
                   p_re=np.zeros((n_quads, 4, ROWS)), p_im=np.zeros((n_quads, 4, ROWS)))

    @classmethod
    def of(cls, responses: Sequence[SourceResponse]) -> RowFactors:
        """Find the rows of the responses' layout and each quad's factors, else `none`."""
        first = responses[0]
        tol = 1e-9 * 2 * np.pi / first.k  # as `SourceResponse` merges coordinates
        y = first.y_distinct[first._iy]
        z = first.z_distinct[first._iz]
        rows_z, rows_y, centres, halves = [], [], [], []
        for iz in range(first.z_distinct.size):
            ys = np.sort(y[first._iz == iz])
            if ys.size == 0:
                continue
            mid = (ys[0] + ys[-1]) / 2
            if not np.all(np.abs((ys - mid) + (ys - mid)[::-1]) <= tol):
                return cls.none(len(responses))  # this row is not symmetric in y
            offsets = ys - mid
            rows_z.append(first.z_distinct[iz])
            rows_y.append(mid)
            centres.append(float(np.sum(np.abs(offsets) <= tol)))
            halves.append(offsets[offsets > tol])
        every = np.sort(np.concatenate(halves))  # a row each: the array has elements
        distinct = every[np.concatenate([[True], np.diff(every) > tol])] if every.size else every
        if len(rows_z) != ROWS or distinct.size > OFFSETS:
            return cls.none(len(responses))  # the kernel's loops are unrolled for this size
        count = np.zeros((ROWS, OFFSETS), dtype=np.int64)
        for r, half in enumerate(halves):
            for d in half:
                count[r, np.abs(distinct - d).argmin()] += 1
        steps = np.diff(distinct)
        step = float(steps[0]) if distinct.size >= 3 and np.all(
            np.abs(steps - steps[0]) <= tol) else 0.0
        distinct = np.concatenate([distinct, np.zeros(OFFSETS - distinct.size)])
        k = first.k
        rz, ry = np.array(rows_z), np.array(rows_y)
        pairs, p_all = [], []
        for resp in responses:
            u_q, s_q = resp.source_u, resp.source_s
            # The factors hold only for plane-wave FEs: compare with the table's f rows.
            p = np.exp(1j * k * (np.outer(u_q, ry) + np.outer(s_q, rz)))  # (4, nr)
            r_of = np.searchsorted(rz, z)
            wave = p[:, r_of] * np.exp(1j * k * np.outer(u_q, y - ry[r_of]))
            if not np.allclose(wave, resp.table[0], rtol=0, atol=1e-13 * y.size):
                return cls.none(len(responses))
            cos = 2 * count[None] * np.cos(k * np.outer(u_q, distinct))[:, None, :]
            sin = 2 * count[None] * np.sin(k * np.outer(u_q, distinct))[:, None, :]
            kd = k * distinct
            pairs.append(np.stack([cos, sin, kd * cos, kd * sin], axis=-1))
            p_all.append(p)
        p_stack = np.stack(p_all)
        return cls(z=rz, y=ry, centre=np.array(centres), count=count, offsets=distinct,
                   offset_step=step, pair=np.ascontiguousarray(np.stack(pairs)),
                   p_re=np.ascontiguousarray(p_stack.real),
                   p_im=np.ascontiguousarray(p_stack.imag))


# The largest phase per unit direction cosine whose exponential is taken as real: it differs
# from its conjugate by rounding (2e-15 at most).
_REAL_PHASE = 1e-15


def _fold(
    resp: SourceResponse, rows: ComplexArray
) -> tuple[ComplexArray, NDArray[np.int64], NDArray[np.int64]]:
    """Fold the rows ``(Q, 12, M)`` for the real responses' sums: ``(fold, iy, iz)``.

    An element's look depends only on its distinct-coordinate indices ``(iy, iz)``: elements at
    one place (duplicated positions) are summed first, one column per place. Then each place
    whose look the kernel gets as the exact conjugate of another's (`_conjugate_looks`: the
    exponential plans conjugate mirrored coordinates) is folded onto that one, ``Re(t_v a_v +
    t_m conj(a_v)) = Re((t_v + conj(t_m)) a_v)``; a place without such a partner (the centre,
    or a coordinate within the tolerance of its mirror but not conjugated) is kept as it is.
    The sum over the columns kept equals the real part of the full sum whatever the layout.
    """
    places = resp._iy * resp.z_distinct.size + resp._iz
    unique, column = np.unique(places, return_inverse=True)
    cell_y, cell_z = unique // resp.z_distinct.size, unique % resp.z_distinct.size
    summed = rows @ (column[:, None] == np.arange(unique.size)[None, :]).astype(np.float64)
    conj_y = _conjugate_looks(resp.k * resp.y_distinct, resp._y_plan)
    conj_z = _conjugate_looks(resp.k * resp.z_distinct, resp._z_plan)
    partner = conj_y[cell_y[:, None], cell_y[None, :]] & conj_z[cell_z[:, None], cell_z[None, :]]
    np.fill_diagonal(partner, False)
    kept: list[int] = []
    columns: list[ComplexArray] = []
    used = np.zeros(unique.size, dtype=bool)
    for c in range(unique.size):
        if used[c]:
            continue
        used[c] = True
        kept.append(c)
        match = np.flatnonzero(partner[c] & ~used)
        if match.size:
            used[match[0]] = True
            columns.append(summed[:, :, c] + np.conj(summed[:, :, match[0]]))
        else:
            columns.append(summed[:, :, c])
    index = np.array(kept, dtype=np.int64)
    return (np.stack(columns, axis=-1), np.ascontiguousarray(cell_y[index], dtype=np.int64),
            np.ascontiguousarray(cell_z[index], dtype=np.int64))


def _grid_factors(resp: SourceResponse) -> tuple[ComplexArray, ComplexArray] | None:
    """Factor a grid's real responses into products of a factor over y and one over z.

    Returns ``(y, z)``, shapes ``(8, ny)`` and ``(8, nz)`` (rows ``fe``: the FE's plane wave
    along the axis, ``4 + fe``: times ``-j k`` times the coordinate; columns the distinct
    coordinates), or ``None``. When every place of the ``ny x nz`` grid holds the same number
    of elements and each element's table entries (``f, f_u, f_s``) are, to rounding, the
    products of its y's and its z's factors, ``f = Y Z``, ``f_u = Y' Z`` and ``f_s = Y Z'``
    with ``Y = sum_i y[fe, i] e_y[i]`` over the distinct y (and so on). A factor is real when
    each of its axis' coordinates is exactly 0 or the exact negative of one whose exponential
    the kernel conjugates (`arrays._ExpPlan`); with one of the two real (the paper array's z:
    its y differ from their mirrors' negatives by rounding), ``Re(Y Z) = Re(Y) Re(Z)``, and
    each axis is folded onto its coordinates computed, ``Re(a e + b conj(e)) = Re((a +
    conj(b)) e)``. ``None`` when the responses do not factor so.
    """
    ny, nz = resp.y_distinct.size, resp.z_distinct.size
    counts = np.bincount(resp._iy * nz + resp._iz, minlength=ny * nz)
    if counts.min() != counts.max():
        return None
    k = resp.k
    axes = []
    for coords, source in ((resp.y_distinct, resp.source_u), (resp.z_distinct, resp.source_s)):
        wave = np.exp(1j * k * np.outer(source, coords))
        axes.append(np.concatenate([wave, -1j * k * coords * wave]))
    y, z = axes
    iy, iz = resp._iy, resp._iz
    products = np.stack([y[:4, iy] * z[:4, iz], y[4:, iy] * z[:4, iz], y[:4, iy] * z[4:, iz]])
    table = resp.table[:3]
    scale = np.abs(table).max(axis=(1, 2), keepdims=True)
    if not np.all(np.abs(products - table) <= 1e-13 * scale):
        return None
    y = y * counts[0]  # the elements at each place
    folded, real = [], []
    for factor, coords, plan in ((y, resp.y_distinct, resp._y_plan),
                                 (z, resp.z_distinct, resp._z_plan)):
        out = np.zeros_like(factor)
        out[:, plan.direct] = factor[:, plan.direct]
        exact = np.zeros(coords.size, dtype=bool)
        exact[plan.direct] = coords[plan.direct] == 0.0
        for j in plan.indirect:
            m = plan.mirror[j]
            out[:, m] += np.conj(factor[:, j])
            exact[m] = coords[j] == -coords[m]
        folded.append(out)
        real.append(bool(np.all(exact[plan.direct])))
    return (folded[0], folded[1]) if any(real) else None


def _conjugate_looks(phases: FloatArray, plan: _ExpPlan) -> NDArray[np.bool_]:
    """Return ``[a, b]``: whether `arrays._exp_rows` gives row ``b`` as the conjugate of ``a``.

    ``phases``: the coordinates times the wavenumber. A coordinate not computed is exactly the
    conjugate of its mirror's row (`arrays._ExpPlan`); a coordinate 0 to rounding (the centre,
    re-centred: phase at most `_REAL_PHASE`), computed by ``exp`` as the plan's first, is real.
    A coordinate within the tolerance of its own mirror but farther from 0 (up to 1e-9
    wavelength) is no one's conjugate, not even its own: its place is not folded.
    """
    n = phases.size
    root = np.arange(n)
    negated = np.zeros(n, dtype=bool)
    indirect = plan.indirect
    root[indirect] = plan.mirror[indirect]
    negated[indirect] = True
    real = np.zeros(n, dtype=bool)
    real[plan.direct[0]] = abs(phases[plan.direct[0]]) <= _REAL_PHASE
    same = root[:, None] == root[None, :]
    return same & ((negated[:, None] != negated[None, :]) | real[root][:, None])


# Stands in for the geometry when the quads are given (same types, never read).
_NO_GEOMETRY = QuadGeometry(
    polygons=np.zeros((1, 4, 2)), lines=np.zeros((1, 4, 3)), boxes=np.zeros((1, 4)),
    degenerate=np.zeros(1, dtype=bool), column_az_deg=np.zeros(2), row_el_deg=np.zeros(2),
)
# The kernel's constants, in the order it reads them.
_TOLERANCES = np.array([_NEGATIVE_TOL, _RANK_TOL, _GAIN_TOL, _RESIDUAL_TOL, _PHASE_TOL,
                        _MAX_ITERATIONS, _INFEASIBLE_STEPS, _INFEASIBLE_PHASE],
                       dtype=np.float64)
_CODES = np.array([Reason.OK, Reason.NO_SOLUTION, Reason.NOT_CONVERGED, Reason.SPLIT],
                  dtype=np.uint8)


def _catmull_rom(t: FloatArray) -> list[FloatArray]:
    t2, t3 = t * t, t * t * t
    return [0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2),
            0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2)]


def _phase_residual(f: ComplexArray, w: FloatArray, phi: FloatArray) -> FloatArray:
    """``arg(f . w) - phi`` wrapped to (-pi, pi]."""
    b = np.einsum("qn,qn->n", f, w)
    return np.angle(b * np.exp(-1j * phi))


def _curvature_margin(w: FloatArray, resp: ComplexArray) -> FloatArray:
    """Largest Hessian eigenvalue of ``|B|^2 / 2`` over ``|B|^2`` (< 0: strict local maximum)."""
    b, b_u, b_s, b_uu, b_us, b_ss = np.einsum("tqn,qn->tn", resp, w)
    _, _, h_uu, h_us, h_ss = power_curvature(b, b_u, b_s, b_uu, b_us, b_ss)
    largest = 0.5 * (h_uu + h_ss) + np.sqrt(0.25 * (h_uu - h_ss) ** 2 + h_us**2)
    power = np.abs(b) ** 2
    return largest / np.where(power > 0.0, power, 1.0)
