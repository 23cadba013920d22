"""Where does the radar see the synthesized target? An independent Bartlett peak search.

This is the measuring instrument for every angle-error figure: it shares no code with the
solver. It builds the array snapshot of the superposed echoes explicitly,
``x_v = sum_q c_q exp(j 2 pi / lambda (y_v cos el_q sin az_q + z_v sin el_q))``, scans
``|a(az, el)^H x|`` on a grid in azimuth and elevation, and refines the best grid point by Newton
steps on finite differences (no analytic derivatives).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .arrays import VirtualArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

_FD_STEP_DEG = 1e-3
_NEWTON_STEPS = 12
_MAX_STEP_DEG = 0.5
# Search grids up to this size are kept between calls (the default window on a 12-element array
# is 11 MB); a larger one (a cascade radar's 192 elements) is built once per call and dropped.
_MAX_CACHED_GRID_BYTES = 64 * 2**20


def snapshot(
    array: VirtualArray, amplitudes: ArrayLike, source_az_deg: ArrayLike, source_el_deg: ArrayLike
) -> ComplexArray:
    """Array snapshot of superposed point sources, shape ``(N, M)``.

    ``amplitudes`` is ``(N, Q)`` (complex allowed); source angles are ``(Q,)`` or ``(N, Q)``.
    """
    amp = np.atleast_2d(np.asarray(amplitudes))
    az = np.radians(np.broadcast_to(source_az_deg, amp.shape))
    el = np.radians(np.broadcast_to(source_el_deg, amp.shape))
    two_pi_over_lambda = 2.0 * np.pi / array.wavelength_m
    phase = two_pi_over_lambda * (
        (np.cos(el) * np.sin(az))[..., None] * array.y_m + np.sin(el)[..., None] * array.z_m
    )
    return np.einsum("nq,nqv->nv", amp, np.exp(1j * phase))


def bartlett_power(array: VirtualArray, x: ComplexArray, az_deg: FloatArray,
                   el_deg: FloatArray) -> FloatArray:
    """``|a(az, el)^H x|^2`` for look directions ``(N, K)`` and snapshots ``(N, M)``."""
    return _power(_conjugate_steering(array.y_m, array.z_m, array.wavelength_m, az_deg, el_deg), x)


def _conjugate_steering(y_m: FloatArray, z_m: FloatArray, wavelength_m: float,
                        az_deg: FloatArray, el_deg: FloatArray) -> ComplexArray:
    """``conj(a(az, el))`` for look directions ``(N, K)``: shape ``(N, K, M)``."""
    az, el = np.radians(az_deg), np.radians(el_deg)
    two_pi_over_lambda = 2.0 * np.pi / wavelength_m
    phase = two_pi_over_lambda * (
        (np.cos(el) * np.sin(az))[..., None] * y_m + np.sin(el)[..., None] * z_m
    )
    return np.exp(-1j * phase)


def _power(conjugate_steering: ComplexArray, x: ComplexArray) -> FloatArray:
    out = np.einsum("nkv,nv->nk", conjugate_steering, x)
    return out.real**2 + out.imag**2


def find_peak(
    array: VirtualArray,
    x: ComplexArray,
    *,
    az_range_deg: tuple[float, float] = (-30.0, 30.0),
    el_range_deg: tuple[float, float] = (-30.0, 30.0),
    grid_step_deg: float = 0.25,
) -> tuple[FloatArray, FloatArray]:
    """Global maximum of the Bartlett spectrum of each snapshot in the given window.

    Parameters
    ----------
    array : VirtualArray
        The radar's virtual array.
    x : ndarray, shape (N, M)
        Snapshots (see `snapshot`).
    az_range_deg, el_range_deg : (float, float)
        Search window, degrees.
    grid_step_deg : float
        Coarse grid step; must be well below the beamwidth.

    Returns
    -------
    az_deg, el_deg : ndarray, shape (N,)
        Peak direction, refined to ~1e-7 deg.
    """
    x = np.atleast_2d(x)
    key = (array.key, (float(az_range_deg[0]), float(az_range_deg[1])),
           (float(el_range_deg[0]), float(el_range_deg[1])), float(grid_step_deg))
    n_looks = _grid_axis(*key[1], key[3]).size * _grid_axis(*key[2], key[3]).size
    cached = n_looks * array.n_elements * 16 <= _MAX_CACHED_GRID_BYTES
    g_az, g_el, steering = (_search_grid if cached else _search_grid.__wrapped__)(*key)
    best = np.empty(len(x), dtype=np.int64)
    for i in range(len(x)):  # one spectrum per snapshot keeps memory at grid size
        best[i] = np.argmax(_power(steering, x[i : i + 1])[0])
    az, el = g_az[best], g_el[best]
    return _newton_refine(array, x, az, el)


def _grid_axis(lo_deg: float, hi_deg: float, step_deg: float) -> FloatArray:
    return np.arange(lo_deg, hi_deg + step_deg / 2, step_deg)


@lru_cache(maxsize=8)
def _search_grid(
    array_key: tuple[Any, ...],
    az_range_deg: tuple[float, float],
    el_range_deg: tuple[float, float],
    grid_step_deg: float,
) -> tuple[FloatArray, FloatArray, ComplexArray]:
    """Look directions ``(K,)`` of the coarse grid and their conjugate steering ``(1, K, M)``.

    Keyed by the array's value (`VirtualArray.key`), so equal arrays share one grid.
    """
    y_bytes, z_bytes, wavelength_m = array_key
    y_m, z_m = np.frombuffer(y_bytes), np.frombuffer(z_bytes)
    g_az, g_el = (v.ravel() for v in np.meshgrid(_grid_axis(*az_range_deg, grid_step_deg),
                                                 _grid_axis(*el_range_deg, grid_step_deg)))
    steering = _conjugate_steering(y_m, z_m, wavelength_m, g_az[None], g_el[None])
    for values in (g_az, g_el, steering):
        values.setflags(write=False)  # shared by every later call
    return g_az, g_el, steering


def _newton_refine(array: VirtualArray, x: ComplexArray, az: FloatArray,
                   el: FloatArray) -> tuple[FloatArray, FloatArray]:
    h = _FD_STEP_DEG
    stencil = np.array(
        [[0, 0], [h, 0], [-h, 0], [0, h], [0, -h], [h, h], [-h, -h], [h, -h], [-h, h]]
    )
    for _ in range(_NEWTON_STEPS):
        p = bartlett_power(array, x, az[:, None] + stencil[:, 0], el[:, None] + stencil[:, 1])
        p = np.log(p)  # log power is closer to quadratic near a main-lobe peak
        g = np.stack([(p[:, 1] - p[:, 2]) / (2 * h), (p[:, 3] - p[:, 4]) / (2 * h)], axis=1)
        h_aa = (p[:, 1] - 2 * p[:, 0] + p[:, 2]) / h**2
        h_ee = (p[:, 3] - 2 * p[:, 0] + p[:, 4]) / h**2
        h_ae = (p[:, 5] + p[:, 6] - p[:, 7] - p[:, 8]) / (4 * h**2)
        det = h_aa * h_ee - h_ae**2
        concave = (h_aa < 0) & (det > 0)
        safe_det = np.where(concave, det, 1.0)
        step_az = np.where(concave, -(h_ee * g[:, 0] - h_ae * g[:, 1]) / safe_det, g[:, 0] * 1e-3)
        step_el = np.where(concave, -(h_aa * g[:, 1] - h_ae * g[:, 0]) / safe_det, g[:, 1] * 1e-3)
        norm = np.hypot(step_az, step_el)
        shrink = np.minimum(1.0, _MAX_STEP_DEG / np.maximum(norm, 1e-300))
        az = az + step_az * shrink
        el = el + step_el * shrink
    return az, el
