"""Four-channel weight solver: put the synthesized target at a set azimuth and elevation.

``solve_weights`` assigns every target to the quad that encloses it, solves the chosen method
on each quad's targets at once, retries targets a quad cannot synthesize in its neighbours
(curved synthesis borders), and checks that the peak is the global maximum of the radar's
beamformer wherever a quad can split. Per rig FE geometry, array and method the quads' kernels,
probe grids and split maps are computed once into a `SolverPlan`, cached by value in memory and
on disk (see `rts_scenario.solver.plan`).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..arrays import VirtualArray
from ..errors import SolverError
from ..quads import assign_quads
from ..responses import FrontEndModel
from ..rig import Rig
from ..workers import THREADS, one_blas_thread, run_parts
from . import compiled
from .globalmax import GlobalMaxCheck
from .plan import (
    METHODS,
    SolverPlan,
    clear_memory_cache,
    plan_cache_dir,
    plan_key,
    solver_plan,
)
from .reasons import Reason

FloatArray = NDArray[np.float64]

CHUNK = 32768
WORKERS = THREADS
# Targets a quad cannot synthesize are retried in quads within this distance (deg) of them.
RETRY_MARGIN_DEG = 1.0


@dataclass(frozen=True)
class WeightSolution:
    """Solver result, one row per target.

    Attributes
    ----------
    weights : ndarray, shape (N, 4), float64
        Linear amplitude weights of the quad's FEs in paper order, >= 0, max 1 per feasible
        row, 0 for infeasible rows.
    quad : ndarray, shape (N,), int64
        Index into ``rig.quads`` of the quad used, -1 outside every quad.
    reason : ndarray, shape (N,), uint8
        `Reason` code per target; ``Reason.OK`` where feasible.
    method : str
        Method name.
    """

    weights: FloatArray
    quad: NDArray[np.int64]
    reason: NDArray[np.uint8]
    method: str

    @property
    def feasible(self) -> NDArray[np.bool_]:
        """Whether each target was synthesized, shape ``(N,)``."""
        return self.reason == Reason.OK

    def explain(self, index: int) -> str:
        """Human-readable reason for target ``index``."""
        return Reason(int(self.reason[index])).description

    def counts(self) -> dict[str, int]:
        """Count targets per reason name (only reasons that occur)."""
        codes, counts = np.unique(self.reason, return_counts=True)
        return {Reason(int(c)).name: int(n) for c, n in zip(codes, counts, strict=True)}


def solve_weights(
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    *,
    rig: Rig,
    array: VirtualArray,
    method: str = "exact",
    plan: SolverPlan | None = None,
    model: FrontEndModel | None = None,
) -> WeightSolution:
    """Weights of the four FEs of the enclosing quad that synthesize each target's angle.

    Parameters
    ----------
    az_deg, el_deg : array_like, shape (N,)
        Set azimuth (positive left) and elevation (positive up) of every target, degrees.
    rig : Rig
        The RTS rig.
    array : VirtualArray
        The radar's virtual array.
    method : {"exact", "paper"}
        ``"paper"``: the paper's equations (sinc model, averaged FE angles). ``"exact"``: true
        FE directions and exact array response; the beamformer peak is on the set angle.
    plan : SolverPlan, optional
        The plan of ``rig``, ``array`` and ``method`` from `solver_plan`, when the caller has
        it already (default: get it from `solver_plan`).
    model : FrontEndModel, optional
        The radar's physical antennas: the FEs' responses on ``array`` are then modeled from
        the bench geometry (FE distances and antenna offsets, spherical paths; see
        `rts_scenario.responses`) instead of plane waves from the FEs' directions. ``array``
        must be the antennas' virtual array, at the wavelength the radar steers with.

    Returns
    -------
    WeightSolution

    Raises
    ------
    SolverError
        Unknown method, mismatched shapes or non-finite angles, or a ``plan`` of other values.
    """
    METHODS.get(method)  # an unknown name is an error naming the valid ones
    az = _angles("az_deg", az_deg)
    el = _angles("el_deg", el_deg)
    # Their range is checked chunk by chunk on the worker threads (`_checked`), before each
    # chunk is solved.
    if az.shape != el.shape:
        raise SolverError(
            f"az_deg and el_deg: must have the same length, got {az.size} and {el.size}"
        )
    if plan is None:
        plan = solver_plan(rig, array, method, model)
    elif plan.key != plan_key(rig, array, method, model):
        # Weights from a plan of other values synthesize other angles, silently.
        raise SolverError(
            f"plan: was built for other values than rig {rig.name!r}, array {array.name!r}, "
            f"method {method!r} (its method: {plan.method!r}); a plan is made for one set of FE "
            f"angles, grid shape, element positions, wavelength, method and FE response model: "
            f"get it from solver_plan(rig, array, method, model)"
        )
    # Load (or compile) the kernel here, not in the pool's threads.
    n = az.size
    kernel = compiled.exact_kernel(n) if plan.exact_tables is not None else None
    # Filled chunk by chunk on the worker threads, just before each chunk is solved: set in
    # one pass here they cost about as much again as the angles' range check (1.4 ns per
    # target, 8 % of the paper array's solve) and run on one core.
    weights = np.empty((n, 4))
    quad = np.empty(n, dtype=np.int64)
    reason = np.empty(n, dtype=np.uint8)

    # Each quad's share of a chunk should stay large enough to amortize the per-call overhead
    # (threads share the GIL between numpy calls: fewer, larger calls run more in parallel).
    # The compiled kernel takes every quad in one call: chunks of CHUNK balance the threads.
    chunk = CHUNK if kernel is not None else CHUNK * min(len(plan.kernels), 8)

    def run(start: int) -> None:
        part = slice(start, start + chunk)
        if not (_in_range(az[part]) and _in_range(el[part])):
            raise _OutOfRange
        weights[part] = 0.0
        quad[part] = -1
        reason[part] = Reason.OUTSIDE
        _solve_chunk(plan, kernel, az[part], el[part], weights[part], quad[part], reason[part])

    def retry() -> None:
        # Once over all targets, not per chunk: it costs a few numpy calls per quad whatever
        # the number of targets (per chunk they were a sixth of the wide-3x5 grid's time).
        if len(plan.kernels) > 1:
            _retry_neighbours(plan, az, el, weights, quad, reason)

    starts = range(0, n, chunk)
    try:
        if len(starts) > 1 and WORKERS > 1:
            # numpy releases the GIL inside its kernels, so chunks run in parallel on threads;
            # the chunks' small matrix products must not spawn BLAS threads of their own on top.
            with one_blas_thread():
                run_parts(run, starts)
                retry()
        else:
            for start in starts:
                run(start)
            retry()
    except _OutOfRange:
        # A chunk held an angle out of range: the error names the first of all of them.
        _check_range("az_deg", az)
        _check_range("el_deg", el)
        raise SolverError("az_deg, el_deg: must be finite angles within -90..90 degrees") \
            from None
    return WeightSolution(weights=weights, quad=quad, reason=reason, method=method)


class _OutOfRange(Exception):
    """A chunk's angles are not all finite and within -90..90 degrees (`_check_range` says)."""


def _in_range(values: FloatArray) -> bool:
    # Two reading passes (NaN propagates through min and max).
    return values.size == 0 or bool(-90.0 <= values.min() and values.max() <= 90.0)


def _angles(name: str, values: ArrayLike) -> FloatArray:
    try:
        out = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise SolverError(f"{name}: must be numbers in degrees, got {values!r:.80}") from None
    if out.ndim > 1:
        raise SolverError(f"{name}: must be a scalar or 1-D, got shape {out.shape}")
    return out.reshape(-1)


def _check_range(name: str, out: FloatArray) -> None:
    """Raise `SolverError` naming the first angle of ``out`` not finite and within +-90 deg."""
    if _in_range(out):
        return
    bad = ~np.isfinite(out)
    if bad.any():
        i = int(np.argmax(bad))
        raise SolverError(
            f"{name}[{i}]: must be a finite angle in degrees, got {out[i]} "
            f"({int(bad.sum())} non-finite value(s) in all)"
        )
    if np.any(np.abs(out) > 90.0):
        i = int(np.argmax(np.abs(out) > 90.0))
        raise SolverError(f"{name}[{i}]: must be within -90..90 degrees, got {out[i]}")


def _solve_chunk(
    plan: SolverPlan,
    kernel: ModuleType | None,
    az_deg: FloatArray,
    el_deg: FloatArray,
    weights: FloatArray,
    quad: NDArray[np.int64],
    reason: NDArray[np.uint8],
) -> None:
    """Solve one chunk into the given output views (weights zeroed, reason OUTSIDE).

    Targets their quad cannot synthesize are not retried here: `solve_weights` retries them
    in the neighbouring quads once all chunks are solved (`_retry_neighbours`). With the
    compiled ``kernel`` every quad's targets are solved in one pass, in place.
    """
    if kernel is not None and plan.exact_tables is not None:
        tables = plan.exact_tables
        # The kernel finds the quad of targets in their candidate cell; the rest are scanned.
        tables.solve(kernel, az_deg, el_deg, _DEGREES, quad, weights, reason, _NO_MARGIN,
                     geometry=plan.geometry)
        missed = np.flatnonzero(quad < 0)
        if missed.size:
            found, off_line = plan.geometry.assign(az_deg[missed], el_deg[missed])
            quad[missed] = found
            reason[missed[off_line]] = Reason.DEGENERATE
            hit = missed[found >= 0]
            if hit.size:
                w, r = np.zeros((hit.size, 4)), np.empty(hit.size, dtype=np.uint8)
                tables.solve(kernel, az_deg[hit], el_deg[hit], _DEGREES, quad[hit], w, r,
                             _NO_MARGIN)
                weights[hit], reason[hit] = w, r
        for q, check in enumerate(plan.checks):
            if check is not None:
                _mark_splits(check, np.flatnonzero((quad == q) & (reason == Reason.OK)),
                             np.radians(az_deg), np.radians(el_deg), weights, reason)
        return
    quad[:], off_line = plan.geometry.assign(az_deg, el_deg)
    reason[off_line] = Reason.DEGENERATE
    az, el = np.radians(az_deg), np.radians(el_deg)
    first = quad[0] if quad.size else -1
    if first >= 0 and np.all(quad == first):
        weights[:], reason[:] = _solve_in(plan, int(first), az, el)
    else:
        # Solve each quad's targets at once: group them by quad.
        order = np.argsort(quad, kind="stable")
        bounds = np.searchsorted(quad[order], np.arange(len(plan.kernels) + 1))
        for q in range(len(plan.kernels)):
            idx = order[bounds[q] : bounds[q + 1]]
            if idx.size:
                weights[idx], reason[idx] = _solve_in(plan, q, az[idx], el[idx])


_NO_MARGIN = np.empty(0)
_DEGREES = np.pi / 180.0


def _solve_in(
    plan: SolverPlan, q: int, az: FloatArray, el: FloatArray
) -> tuple[FloatArray, NDArray[np.uint8]]:
    weights, reason = plan.kernels[q].solve(az, el)
    check = plan.checks[q]
    if check is not None:
        _mark_splits(check, np.flatnonzero(reason == Reason.OK), az, el, weights, reason)
    weights[reason != Reason.OK] = 0.0
    return weights, reason


def _mark_splits(
    check: GlobalMaxCheck,
    rows: NDArray[np.intp],
    az: FloatArray,
    el: FloatArray,
    weights: FloatArray,
    reason: NDArray[np.uint8],
) -> None:
    """Targets ``rows`` whose echoes would split get reason SPLIT and weights 0 (angles: rad)."""
    split = rows[check.splits(az[rows], el[rows], weights[rows])]
    reason[split] = Reason.SPLIT
    weights[split] = 0.0


def _retry_neighbours(
    plan: SolverPlan,
    az_deg: FloatArray,
    el_deg: FloatArray,
    weights: FloatArray,
    quad: NDArray[np.int64],
    reason: NDArray[np.uint8],
) -> None:
    pending = np.flatnonzero(reason == Reason.NO_SOLUTION)
    # Targets a neighbouring quad puts at their angle only with their echoes split: split,
    # not unsynthesizable, where no quad places them cleanly.
    split = np.zeros(reason.shape, dtype=bool)
    for q in range(len(plan.kernels)):
        if pending.size == 0:
            break
        idx = pending[quad[pending] != q]
        idx = idx[plan.geometry.within(az_deg[idx], el_deg[idx], q, RETRY_MARGIN_DEG)]
        if idx.size == 0:
            continue
        w, r = _solve_in(plan, q, np.radians(az_deg[idx]), np.radians(el_deg[idx]))
        solved = idx[r == Reason.OK]
        weights[solved] = w[r == Reason.OK]
        quad[solved] = q
        reason[solved] = Reason.OK
        split[idx[r == Reason.SPLIT]] = True
        pending = np.setdiff1d(pending, solved, assume_unique=True)
    reason[pending[split[pending]]] = Reason.SPLIT


__all__ = [
    "METHODS",
    "FrontEndModel",
    "Reason",
    "SolverPlan",
    "WeightSolution",
    "assign_quads",
    "clear_memory_cache",
    "plan_cache_dir",
    "plan_key",
    "solve_weights",
    "solver_plan",
]
