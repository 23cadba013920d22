"""The conventional beamformer's peak: curvature of ``|B|^2`` and the Newton step to its peak.

``B(u, s) = a(u, s)^H x`` is the Bartlett beamformer output in direction cosines ``(u, s)``
(`rts_scenario.arrays`). Its derivatives ``B_u, B_s, B_uu, B_us, B_ss`` come from the array
response (`rts_scenario.arrays.SourceResponse.evaluate`) or from the snapshots directly. Every
Newton step on a beamformer output in the package (the schedule's predicted angle error and
sensitivity, the simulated radar's estimator) goes through here; `rts_scenario.peak_search`, the
independent measuring instrument, deliberately does not.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
BoolArray = NDArray[np.bool_]


def power_curvature(
    b: ComplexArray, b_u: ComplexArray, b_s: ComplexArray, b_uu: ComplexArray,
    b_us: ComplexArray, b_ss: ComplexArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Gradient and Hessian of ``|B|^2 / 2`` in (u, s) from B and its derivatives.

    Parameters
    ----------
    b, b_u, b_s, b_uu, b_us, b_ss : ndarray of complex, broadcastable shapes
        The beamformer output and its first and second derivatives in (u, s).

    Returns
    -------
    g_u, g_s, h_uu, h_us, h_ss : ndarray
        Gradient and Hessian entries; a peak has zero gradient and a negative definite Hessian.
    """
    cb = np.conj(b)
    return ((cb * b_u).real, (cb * b_s).real, (cb * b_uu).real + np.abs(b_u) ** 2,
            (cb * b_us).real + (np.conj(b_u) * b_s).real, (cb * b_ss).real + np.abs(b_s) ** 2)


def hessian_step(
    g_u: FloatArray, g_s: FloatArray, h_uu: FloatArray, h_us: FloatArray, h_ss: FloatArray,
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Newton step ``-H^-1 g`` of a 2-D quadratic model, vectorized.

    With ``g`` the gradient of ``|B|^2 / 2`` this is the step to the stationary point of the
    local quadratic model; with ``g`` the derivative of that gradient with respect to a
    parameter it is how far the stationary point moves per unit of the parameter (implicit
    function theorem).

    Parameters
    ----------
    g_u, g_s : ndarray
        Gradient (or its derivative), broadcastable against the Hessian entries.
    h_uu, h_us, h_ss : ndarray
        Hessian entries.

    Returns
    -------
    du, ds : ndarray
        The step in direction cosines; zero where the Hessian is not definite (no stationary
        point of the model to step to).
    ok : ndarray of bool
        Where the Hessian is negative definite: the function curves down and the step leads
        to a maximum.
    """
    det = h_uu * h_ss - h_us * h_us
    definite = det > 0.0
    det = np.where(definite, det, np.inf)
    du = -(h_ss * g_u - h_us * g_s) / det
    ds = -(h_uu * g_s - h_us * g_u) / det
    return du, ds, np.asarray(definite & (h_uu < 0.0), dtype=bool)


def newton_step(
    b: ComplexArray, b_u: ComplexArray, b_s: ComplexArray, b_uu: ComplexArray,
    b_us: ComplexArray, b_ss: ComplexArray,
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """One Newton step towards the peak of ``|B|^2`` from B and its derivatives at (u, s).

    Parameters
    ----------
    b, b_u, b_s, b_uu, b_us, b_ss : ndarray of complex, broadcastable shapes
        The beamformer output and its first and second derivatives in (u, s).

    Returns
    -------
    du, ds : ndarray
        Step in direction cosines to the stationary point of the local quadratic model of
        ``|B|^2``; zero where its Hessian is not definite. Near a peak the error after the step
        is of the order of the squared error before it.
    ok : ndarray of bool
        Where ``|B|^2`` curves down (negative definite Hessian), i.e. the step heads for a peak.
    """
    return hessian_step(*power_curvature(b, b_u, b_s, b_uu, b_us, b_ss))


__all__ = ["hessian_step", "newton_step", "power_curvature"]
