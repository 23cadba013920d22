"""Estimator-aware synthesis: weights whose target the radar's own estimator reads on the set angle.

The exact method puts the peak of the conventional (Bartlett) beamformer on the set angle. A
radar that estimates angles differently (TI's SDK: an azimuth FFT, elevation from a phase
difference) sees the synthesized wavefront - not a plane wave - somewhere else. Here the exact
weights are aimed at a corrected angle: the estimator (any registered one, called on the array
snapshot the weights synthesize) reports where the target appears, the aim moves by the miss,
and a few fixed-point steps later the estimator reports the set angle. All targets are iterated
together (vectorized); a target whose miss does not fall below `TOLERANCE_DEG` keeps the reason
``NOT_CONVERGED``.

The weights stay real (amplitudes only, the channel phases stay at their calibration): re-aiming
real weights reaches every angle the quad covers, and an RTS that only attenuates and delays
can play them. Complex weights (a per-channel phase beyond calibration) would add freedom to
shape the wavefront for an estimator whose reading depends on more than the peak, but would
bind the schedule to an RTS with per-channel phase control; they are not used.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..arrays import VirtualArray
from ..errors import SolverError
from ..radar.angle import make_estimator
from ..responses import FrontEndModel
from ..rig import Rig
from . import WeightSolution, solve_weights
from .reasons import Reason

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# Fixed-point steps; each divides the miss by ~30 on the shipped arrays.
ITERATIONS = 6
# A target counts as synthesized when the estimator's reading is this close to the set angle.
TOLERANCE_DEG = 1e-4


# Methods a schedule is built with: the solver's, and "estimator" (aimed at the radar's
# estimator, on the exact method's plan).
SCHEDULE_METHODS = ("exact", "paper", "estimator")


def plan_method(method: str) -> str:
    """Return the solver method whose plan a schedule method uses (estimator-aware: exact).

    Raises
    ------
    SolverError
        ``method`` is none of `SCHEDULE_METHODS` nor a registered solver method (the message
        lists them all).
    """
    if method == "estimator":
        return "exact"
    from .plan import METHODS

    if method not in METHODS:
        valid = [*SCHEDULE_METHODS, *(name for name in METHODS if name not in SCHEDULE_METHODS)]
        raise SolverError(f"unknown method {method!r}; valid methods: {', '.join(valid)}")
    return method


def front_end_vectors(rig: Rig, array: VirtualArray) -> ComplexArray:
    """Each FE's plane-wave response on the virtual array, shape (F, M)."""
    az, el = np.radians(rig.az_deg), np.radians(rig.el_deg)
    u, s = np.cos(el) * np.sin(az), np.sin(el)
    return np.exp(1j * array.wavenumber_rad_per_m * (np.outer(u, array.y_m)
                                                     + np.outer(s, array.z_m)))


def estimator_weights(az_deg: FloatArray, el_deg: FloatArray, *, rig: Rig, array: VirtualArray,
                      estimator: str, model: FrontEndModel | None = None,
                      iterations: int = ITERATIONS) -> WeightSolution:
    """Weights that make ``estimator`` report each target at its set angle.

    Parameters
    ----------
    az_deg, el_deg : ndarray, shape (N,)
        Set angles, degrees.
    rig, array : Rig, VirtualArray
        The rig and the radar's virtual array.
    estimator : str
        A registered angle estimator (`rts_scenario.radar.angle.ESTIMATORS` or a plugin).
    model : FrontEndModel, optional
        The FEs' echoes as the radar receives them (near field, antenna offsets); default:
        plane waves from the FE directions. The exact weights are solved with the same model.
    iterations : int
        Fixed-point steps.

    Returns
    -------
    WeightSolution
        ``method`` is ``"estimator"``; targets the exact method cannot synthesize keep its
        reason, targets whose reading did not converge get ``NOT_CONVERGED``.
    """
    az = np.asarray(az_deg, dtype=np.float64).reshape(-1)
    el = np.asarray(el_deg, dtype=np.float64).reshape(-1)
    vectors = (front_end_vectors(rig, array) if model is None
               else model.vectors(rig, np.arange(rig.n_front_ends), array).T)
    read = make_estimator(estimator, array)
    aim_az, aim_el = az.copy(), el.copy()
    miss = np.full(az.size, np.inf)
    sol = solve_weights(aim_az, aim_el, rig=rig, array=array, method="exact", model=model)
    for _ in range(iterations):
        seen_az, seen_el = _seen(read, sol, rig, vectors)
        miss = np.hypot(seen_az - az, seen_el - el)
        step = sol.feasible & np.isfinite(miss)
        if not np.any(step & (miss > TOLERANCE_DEG)):
            break
        aim_az = np.where(step, aim_az + az - seen_az, aim_az)
        aim_el = np.where(step, aim_el + el - seen_el, aim_el)
        sol = solve_weights(aim_az, aim_el, rig=rig, array=array, method="exact", model=model)
    else:
        seen_az, seen_el = _seen(read, sol, rig, vectors)
        miss = np.hypot(seen_az - az, seen_el - el)
    reason = sol.reason.copy()
    reason[(reason == Reason.OK) & ~(miss <= TOLERANCE_DEG)] = Reason.NOT_CONVERGED
    weights = np.where((reason == Reason.OK)[:, None], sol.weights, 0.0)
    return WeightSolution(weights=weights, quad=sol.quad, reason=reason, method="estimator")


def _seen(read: object, sol: WeightSolution, rig: Rig,
          vectors: ComplexArray) -> tuple[FloatArray, FloatArray]:
    """Where the estimator reads each feasible target (strongest reading), NaN elsewhere."""
    n = sol.weights.shape[0]
    seen_az, seen_el = np.full(n, np.nan), np.full(n, np.nan)
    ok = np.flatnonzero(sol.feasible)
    if ok.size == 0:
        return seen_az, seen_el
    snap = np.einsum("nq,nqm->nm", sol.weights[ok], vectors[rig.quads[sol.quad[ok]]])
    est = read(snap)  # type: ignore[operator]
    order = np.argsort(-est.power, kind="stable")
    source = est.source[order]
    source, first = np.unique(source, return_index=True)
    seen_az[ok[source]] = est.az_deg[order][first]
    seen_el[ok[source]] = est.el_deg[order][first]
    return seen_az, seen_el


__all__ = ["SCHEDULE_METHODS", "estimator_weights", "front_end_vectors", "plan_method"]
