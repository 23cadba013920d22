"""Exact weights: true FE directions, exact array response, any layout (DESIGN.md section 5.3).

With coherent channels the Bartlett output of the superposition is
``B(u, s) = sum_q w_q f_q(u, s)``, ``f_q = a(u, s)^H a(u_q, s_q)``. Stationarity at the set
direction is linear in the weights. Working in direction cosines ``(u, s)`` rather than angles is
a change of variables with the same maxima, and stays well conditioned near el = +-90 deg.

Centro-symmetric arrays have a real ``f``: the two stationarity equations leave a 2-D null space
in which the weights that maximize the peak gain ``f . w / |w|`` with ``w >= 0`` are the projection
of ``f`` onto it, or, when that has a negative entry, the projection onto the boundary ray where
one weight is zero. Other arrays make ``f`` complex; the condition ``Re(conj(B) dB) = 0`` is
linear once ``conj(B)`` is frozen, and the same step, iterated, converges in a few passes.

Every solution is checked to be a local maximum of ``|B|`` (negative definite Hessian); the
driver checks that it is the global one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..arrays import SourceResponse, VirtualArray, direction_cosines
from ..errors import SolverError
from ..rig import Rig
from .reasons import Reason

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# A weight more negative than this (relative to the largest) is infeasible; smaller ones are 0.
_NEGATIVE_TOL = 1e-9
# A constraint row shorter than this (relative to its scale) is absent: the FE gradients vanish.
_RANK_TOL = 1e-12
_MAX_ITERATIONS = 60
_CONVERGED = 1e-13


def max_gain_weights(
    f: FloatArray, r1: FloatArray, r2: FloatArray, row_scale: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Maximize ``f . w / |w|`` subject to ``r1 . w = 0``, ``r2 . w = 0`` and ``w >= 0``.

    All inputs have shape ``(N, 4)``. Returns ``(w, ok)``: ``w`` (unnormalized, >= 0) and whether
    a solution with positive gain exists. Closed form, vectorized over N.
    """
    def unit(v: FloatArray) -> FloatArray:
        norm = np.sqrt(np.einsum("nq,nq->n", v, v))
        keep = norm > _RANK_TOL * row_scale
        return np.where(keep[:, None], v / np.where(keep, norm, 1.0)[:, None], 0.0)

    e1 = unit(r1)
    e2 = unit(r2 - np.einsum("nq,nq->n", r2, e1)[:, None] * e1)
    w = f - np.einsum("nq,nq->n", f, e1)[:, None] * e1 - np.einsum("nq,nq->n", f, e2)[:, None] * e2

    # Boundary rays: also force w_k = 0. Row k of the projector P is P e_k.
    proj = np.eye(4) - e1[:, :, None] * e1[:, None, :] - e2[:, :, None] * e2[:, None, :]
    p_kk = np.einsum("nkk->nk", proj)
    usable = p_kk > 1e-12
    ratio = np.where(usable, w / np.where(usable, p_kk, 1.0), 0.0)
    candidates = np.concatenate([w[:, None, :], w[:, None, :] - ratio[:, :, None] * proj], axis=1)
    gain2 = np.einsum("nkq,nq->nk", candidates, f)
    norm = np.sqrt(np.einsum("nkq,nkq->nk", candidates, candidates))
    valid = np.concatenate([np.ones((len(f), 1), bool), usable], axis=1)
    valid &= candidates.min(axis=2) >= -_NEGATIVE_TOL * norm
    valid &= gain2 > 0.0
    # Every valid candidate is a projection of f, so its gain f.w/|w| equals |w|.
    best = np.argmax(np.where(valid, norm, -1.0), axis=1)
    chosen = np.take_along_axis(candidates, best[:, None, None], axis=1)[:, 0, :]
    return np.maximum(chosen, 0.0), valid.any(axis=1)


@dataclass(frozen=True)
class ExactQuad:
    """Per-quad precomputation of the exact method: the FEs' response kernel."""

    response: SourceResponse
    centrosymmetric: bool
    row_scale: float

    @classmethod
    def build(cls, rig: Rig, array: VirtualArray, fes: NDArray[np.int64]) -> ExactQuad:
        """Precompute the response of the quad's four FEs for ``array``."""
        extent = max(np.ptp(array.y_m), np.ptp(array.z_m))
        if np.ptp(array.y_m) == 0.0 or np.ptp(array.z_m) == 0.0:
            raise SolverError(
                f"array {array.name!r}: a 2-D angle needs elements spread along y and along z; "
                f"this layout is a line"
            )
        u, s = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
        return cls(
            response=array.source_response(u, s),
            centrosymmetric=array.is_centrosymmetric,
            row_scale=array.wavenumber_rad_per_m * extent * array.n_elements,
        )

    def solve(self, az_rad: FloatArray, el_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(weights (N, 4), reason (N,))`` for targets in this quad."""
        u, s = direction_cosines(az_rad, el_rad)
        f, f_u, f_s, f_uu, f_us, f_ss = self.response.evaluate(u, s)
        reason = np.full(u.shape, Reason.OK, dtype=np.uint8)
        if self.centrosymmetric:
            w, ok = max_gain_weights(f.real, f_u.real, f_s.real, self.row_scale)
        else:
            w, ok, converged = self._iterate(f, f_u, f_s)
            reason[~converged] = Reason.NOT_CONVERGED
        reason[~ok] = Reason.NO_SOLUTION
        reason[(reason == Reason.OK) & ~_local_maximum(w, f, f_u, f_s, f_uu, f_us, f_ss)] = (
            Reason.SPLIT
        )
        top = w.max(axis=1)
        w = w / np.where(top > 0.0, top, 1.0)[:, None]
        w[reason != Reason.OK] = 0.0
        return w, reason

    def _iterate(
        self, f: ComplexArray, f_u: ComplexArray, f_s: ComplexArray
    ) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
        # Start from the real parts: positions are centred, so f is nearly real near the FEs.
        w, ok = max_gain_weights(f.real, f_u.real, f_s.real, self.row_scale)
        converged = np.zeros(len(f), dtype=bool)
        active = np.arange(len(f))
        for _ in range(_MAX_ITERATIONS):
            fa, wa = f[active], w[active]
            b = np.einsum("nq,nq->n", fa, wa)
            phase = np.conj(b) / np.where(b != 0, np.abs(b), 1.0)
            rot = phase[:, None]
            w_new, ok_new = max_gain_weights(
                (rot * fa).real, (rot * f_u[active]).real, (rot * f_s[active]).real,
                self.row_scale,
            )
            scale = np.maximum(np.abs(w_new).max(axis=1), 1e-300)
            done = np.abs(w_new - wa).max(axis=1) <= _CONVERGED * scale
            w[active] = w_new
            ok[active] = ok_new
            converged[active[done]] = True
            active = active[~done & ok_new]
            if active.size == 0:
                break
        return w, ok, converged | ~ok


def _local_maximum(
    w: FloatArray, *derivatives: ComplexArray
) -> NDArray[np.bool_]:
    """Whether ``|B|^2`` has a strict local maximum at the look direction (Hessian test)."""
    b, b_u, b_s, b_uu, b_us, b_ss = (np.einsum("nq,nq->n", d, w) for d in derivatives)
    cb = np.conj(b)
    h_uu = (cb * b_uu).real + np.abs(b_u) ** 2
    h_ss = (cb * b_ss).real + np.abs(b_s) ** 2
    h_us = (cb * b_us).real + (np.conj(b_u) * b_s).real
    return (h_uu < 0.0) & (h_uu * h_ss - h_us * h_us > 0.0)
