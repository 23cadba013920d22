"""Angle estimation from array snapshots: a 2-D Bartlett beamformer and TI's method.

Both take snapshots ``(D, M)`` (one per detection, virtual elements of the profile's array,
TDM-Doppler already compensated) and return azimuth and elevation in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..arrays import VirtualArray, angles_from_cosines
from ..beamformer import hessian_step, power_curvature
from ..errors import RtsError
from ..registry import Registry

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# A user estimator: a class (or factory) called with the `VirtualArray`, whose instances map
# snapshots (D, M) to an `AngleEstimate`, installed in this entry-point group.
ESTIMATOR_ENTRY_POINT_GROUP = "rts_scenario.estimators"
_ESTIMATOR_REGISTRY = Registry("angle estimator", {
    "bartlett": "rts_scenario.radar.angle:Bartlett2D",
    "ti": "rts_scenario.radar.angle:TiStyle",
}, entry_point_group=ESTIMATOR_ENTRY_POINT_GROUP)


def estimator_names() -> list[str]:
    """Every angle estimator: the built-ins, then those installed as entry points."""
    return _ESTIMATOR_REGISTRY.names()
ESTIMATORS = ("bartlett", "ti")  # the built-ins; `estimator_names` adds installed ones


@dataclass(frozen=True)
class AngleEstimate:
    """Per snapshot: azimuth, elevation (deg) and the index of the snapshot it came from."""

    az_deg: FloatArray
    el_deg: FloatArray
    source: NDArray[np.int64]
    power: FloatArray


# The Newton refinement stops when every step is below this fraction of a grid cell (~1e-14
# deg on the shipped arrays): one more step would not change the estimate.
CONVERGED_CELLS = 1e-11


class Bartlett2D:
    """Conventional beamformer over (u, s): coarse grid, then Newton steps on the peak.

    ``peak_ratio`` below 1 also reports secondary peaks at least that fraction (in power) of
    the strongest one, so two targets in one range-Doppler cell give two detections when the
    array resolves them.
    """

    def __init__(self, array: VirtualArray, *, u_max: float = 0.8, s_max: float = 0.6,
                 per_cell: int = 6, peak_ratio: float = 0.5, max_peaks: int = 2) -> None:
        self.array = array
        self.k = array.wavenumber_rad_per_m
        # Grid steps: a fraction of the resolution cell (wavelength / aperture) per axis.
        ap_y, ap_z = array.sinc_aperture_m()
        self.step_u = min(array.wavelength_m / ap_y if ap_y else 2.0, 1.0) / per_cell
        self.step_s = min(array.wavelength_m / ap_z if ap_z else 2.0, 1.0) / per_cell
        gu = np.arange(-u_max, u_max + self.step_u / 2, self.step_u)
        gs = np.arange(-s_max, s_max + self.step_s / 2, self.step_s)
        self.shape = (gu.size, gs.size)
        u, s = (g.ravel() for g in np.meshgrid(gu, gs, indexing="ij"))
        self.grid_u, self.grid_s = u, s
        self.steer = np.exp(1j * self.k * (np.outer(u, array.y_m) + np.outer(s, array.z_m)))
        # The grid spectrum factors by the array's height levels: per level a beam over the u
        # axis, then one phase per level along s (M n_u + L G products instead of M G).
        tol = 1e-9 * array.wavelength_m
        _, self._level_of = np.unique(np.round(array.z_m / tol), return_inverse=True)
        levels = np.bincount(self._level_of, weights=array.z_m) / np.bincount(self._level_of)
        self._row_beams = np.zeros((array.n_elements, levels.size * gu.size), dtype=complex)
        for level in range(levels.size):  # (M, L n_u): element m's term on its level's beam
            rows = np.flatnonzero(self._level_of == level)
            self._row_beams[rows, level * gu.size : (level + 1) * gu.size] = np.exp(
                -1j * self.k * np.outer(array.y_m[rows], gu))
        self._level_phase = np.exp(-1j * self.k * np.outer(levels, gs))  # (L, n_s)
        self.peak_ratio = peak_ratio
        self.max_peaks = max_peaks

    def __call__(self, snapshots: ComplexArray) -> AngleEstimate:
        """Estimate the angles of every snapshot (shape (D, M)).

        Snapshots go through the grid spectrum in blocks of `BLOCK`: memory stays bounded
        however many detections a batch of frames has.
        """
        x = np.atleast_2d(snapshots)
        if len(x) <= self.BLOCK:
            return self._estimate(x)
        parts = [self._estimate(x[i : i + self.BLOCK]) for i in range(0, len(x), self.BLOCK)]
        return AngleEstimate(
            np.concatenate([p.az_deg for p in parts]), np.concatenate([p.el_deg for p in parts]),
            np.concatenate([p.source + i for p, i in zip(parts, range(0, len(x), self.BLOCK),
                                                         strict=True)]),
            np.concatenate([p.power for p in parts]))

    # Snapshots per grid-spectrum block: (BLOCK x grid) arrays of a few MB.
    BLOCK = 1024

    def _estimate(self, x: ComplexArray) -> AngleEstimate:
        if len(x) == 0:
            return _nothing()
        n_u, n_s = self.shape
        level_beams = (x @ self._row_beams).reshape(len(x), -1, n_u)  # (D, L, n_u)
        beams = np.matmul(level_beams.transpose(0, 2, 1), self._level_phase)  # (D, n_u, n_s)
        spec = beams.real**2 + beams.imag**2
        spectrum = spec.reshape(len(x), -1)  # (D, G)
        # Local maxima of each spectrum: at least the largest of its 3 x 3 neighbourhood (the
        # neighbourhood's maximum taken along u, then along s).
        along_u = spec.copy()
        np.maximum(along_u[:, 1:], spec[:, :-1], out=along_u[:, 1:])
        np.maximum(along_u[:, :-1], spec[:, 1:], out=along_u[:, :-1])
        around = along_u.copy()
        np.maximum(around[:, :, 1:], along_u[:, :, :-1], out=around[:, :, 1:])
        np.maximum(around[:, :, :-1], along_u[:, :, 1:], out=around[:, :, :-1])
        is_peak = (spec >= around).reshape(len(x), -1)
        # The strongest few peaks, in order: one maximum search per peak wanted.
        score = np.where(is_peak, spectrum, -1.0)
        n_top = min(self.max_peaks, score.shape[1])
        every = np.arange(len(x))
        picks = []
        for _ in range(n_top):
            pick = np.argmax(score, axis=1)
            picks.append(pick)
            score[every, pick] = -np.inf
        ranked = np.stack(picks, axis=1)
        best = spectrum[np.arange(len(x)), ranked[:, 0]]
        rows, cols = [], []
        for rank in range(ranked.shape[1]):  # a few peaks per snapshot at most
            idx = ranked[:, rank]
            value = spectrum[np.arange(len(x)), idx]
            keep = is_peak[np.arange(len(x)), idx] & (
                (rank == 0) | (value >= self.peak_ratio * best))
            rows.append(np.flatnonzero(keep))
            cols.append(idx[keep])
        source = np.concatenate(rows)
        start = np.concatenate(cols)
        u, s = self._refine(x[source], self.grid_u[start], self.grid_s[start])
        az, el = angles_from_cosines(u, s)
        power = np.abs(np.einsum("dm,dm->d", x[source], self._steering(u, s).conj())) ** 2
        return AngleEstimate(np.degrees(az), np.degrees(el), source, power)

    def _steering(self, u: FloatArray, s: FloatArray) -> ComplexArray:
        return np.exp(1j * self.k * (np.outer(u, self.array.y_m) + np.outer(s, self.array.z_m)))

    def _refine(self, x: ComplexArray, u: FloatArray, s: FloatArray,
                steps: int = 12) -> tuple[FloatArray, FloatArray]:
        """Newton steps on ``|a(u, s)^H x|^2`` with analytic derivatives."""
        y, z = self.array.y_m, self.array.z_m
        for _ in range(steps):
            a = self._steering(u, s).conj()
            b = np.einsum("dm,dm->d", x, a)
            dy, dz = -1j * self.k * y, -1j * self.k * z
            b_u = np.einsum("dm,dm->d", x, a * dy)
            b_s = np.einsum("dm,dm->d", x, a * dz)
            b_uu = np.einsum("dm,dm->d", x, a * dy * dy)
            b_us = np.einsum("dm,dm->d", x, a * dy * dz)
            b_ss = np.einsum("dm,dm->d", x, a * dz * dz)
            g_u, g_s, h_uu, h_us, h_ss = power_curvature(b, b_u, b_s, b_uu, b_us, b_ss)
            du, ds, ok = hessian_step(g_u, g_s, h_uu, h_us, h_ss)
            # Newton where the spectrum curves down; elsewhere a short climb along the gradient.
            # Steps are measured in grid cells and limited to one.
            gu_c, gs_c = g_u * self.step_u, g_s * self.step_s
            g_norm = np.maximum(np.hypot(gu_c, gs_c), 1e-300)
            du = np.where(ok, du, 0.25 * self.step_u * gu_c / g_norm)
            ds = np.where(ok, ds, 0.25 * self.step_s * gs_c / g_norm)
            cells = np.hypot(du / self.step_u, ds / self.step_s)
            scale = np.minimum(1.0, 1.0 / np.maximum(cells, 1e-300))
            u, s = u + du * scale, s + ds * scale
            if cells.size == 0 or cells.max() < CONVERGED_CELLS:  # Newton has converged
                break
        return u, s


class TiStyle:
    """TI's mmWave SDK method: azimuth FFT, elevation from a phase difference.

    The azimuth comes from a zero-padded FFT over the azimuth row (peak interpolated), the
    elevation from the phase difference between the elevated row and the azimuth row, both
    beamformed towards that azimuth.
    """

    def __init__(self, array: VirtualArray, *, fft_size: int = 64) -> None:
        tol = 1e-9 * array.wavelength_m
        rows = np.round(array.z_m / tol) * tol
        levels, counts = np.unique(rows, return_counts=True)
        az_level = levels[np.argmax(counts)]
        above = levels[levels > az_level + tol]
        if above.size == 0:
            raise RtsError(f"array {array.name!r}: TI-style elevation needs a second row of "
                           f"elements above the azimuth row")
        el_level = above[0]
        self.az_idx = np.flatnonzero(np.abs(rows - az_level) <= tol)
        self.az_idx = self.az_idx[np.argsort(array.y_m[self.az_idx])]
        y_az = array.y_m[self.az_idx]
        pitch = np.diff(y_az)
        if pitch.size == 0 or np.ptp(pitch) > tol:
            raise RtsError(f"array {array.name!r}: TI-style azimuth needs an evenly spaced row")
        self.d = float(pitch[0])
        self.el_idx = np.flatnonzero(np.abs(rows - el_level) <= tol)
        self.dz = float(el_level - az_level)
        self.array = array
        self.k = array.wavenumber_rad_per_m
        self.fft_size = max(fft_size, 1 << int(np.ceil(np.log2(len(self.az_idx)))))

    def __call__(self, snapshots: ComplexArray) -> AngleEstimate:
        """Estimate the angles of every snapshot (shape (D, M))."""
        x = np.atleast_2d(snapshots)
        if len(x) == 0:
            return _nothing()
        n = self.fft_size
        spec = np.abs(np.fft.fft(x[:, self.az_idx], n=n, axis=1)) ** 2
        peak = np.argmax(spec, axis=1)
        rows = np.arange(len(x))
        left, mid, right = (spec[rows, (peak + o) % n] for o in (-1, 0, 1))
        denom = left - 2 * mid + right
        frac = np.where(denom < 0, 0.5 * (left - right) / np.where(denom < 0, denom, 1.0), 0.0)
        # The FFT sums x_m e^{-j 2 pi b m / n}; x_m = e^{j k d u m} peaks at 2 pi b / n = k d u.
        phase = 2 * np.pi * (peak + frac) / n
        phase = np.mod(phase + np.pi, 2 * np.pi) - np.pi
        u = phase / (self.k * self.d)
        # Beamform both rows towards u and compare their phases: k dz s.
        y = self.array.y_m
        w_az = np.exp(-1j * self.k * np.outer(u, y[self.az_idx]))
        w_el = np.exp(-1j * self.k * np.outer(u, y[self.el_idx]))
        b_az = np.einsum("dm,dm->d", x[:, self.az_idx], w_az)
        b_el = np.einsum("dm,dm->d", x[:, self.el_idx], w_el)
        s = np.angle(b_el * np.conj(b_az)) / (self.k * self.dz)
        az, el = angles_from_cosines(u, np.clip(s, -1.0, 1.0))
        return AngleEstimate(np.degrees(az), np.degrees(el), rows, np.abs(b_az) ** 2)


def _nothing() -> AngleEstimate:
    empty = np.zeros(0)
    return AngleEstimate(empty, empty, np.zeros(0, dtype=np.int64), empty)


def make_estimator(name: str, array: VirtualArray) -> Bartlett2D | TiStyle:
    """Return the estimator called ``name`` (one of `ESTIMATORS`) for ``array``."""
    return _ESTIMATOR_REGISTRY.get(name)(array)


def estimator_problem(name: str, array: VirtualArray) -> str | None:
    """Why the built-in estimator ``name`` cannot estimate angles on ``array``, else None.

    Checked where a scene or a command names the estimator, so that an array it cannot work
    on is bad input there, not an error of the run. ``"ti"`` needs an evenly spaced azimuth
    row with a second row above it (`TiStyle`); ``"bartlett"`` works on any 2-D array. An
    installed estimator is not built here (it may be costly): it says so when a run builds it.
    """
    if name != "ti":
        return None
    try:
        TiStyle(array)
    except RtsError as exc:
        usable = [n for n in ESTIMATORS if n == "bartlett"]
        return (f"{name!r} cannot estimate angles on the radar's array: {exc}; an estimator "
                f"that can: {', '.join(usable)}")
    return None
