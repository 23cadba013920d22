"""Radar virtual arrays: element layout, steering vectors and beamformer response.

Conventions (radar frame x forward, y left, z up): a direction is given by azimuth ``az`` and
elevation ``el``; the kernels work on its direction cosines ``u = cos(el) sin(az)`` and
``s = sin(el)``, in which the steering vector is a plain plane wave::

    a(u, s)_v = exp(j k (y_v u + z_v s)),   k = 2 pi / wavelength

Element positions are referenced to their centroid, so the response of a centro-symmetric array
is real.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ArrayError
from .propagation import C0_MPS

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

PAPER_FC_HZ = 77e9
PAPER_BANDWIDTH_HZ = 1e9

PRESETS = ("paper", "awr1843boost")
"""Virtual-array presets (`VirtualArray.preset`)."""
ANTENNA_PRESETS = ("paper", "awr1843boost", "cascade-12x16")
"""Physical antenna layouts (`Antennas.preset`), for radar profiles."""

# AWR1843BOOST: how far the TX group's centroid sits from the RX group's along y (TX towards -y).
# An assumption about the board (the TX patches are beside the RX patches, about a centimetre
# apart): it moves the physical antennas, never the virtual array.
AWR1843BOOST_TX_RX_SEPARATION_M = 0.010
# MMWCAS-RF-EVM: how far the TX group's centroid sits below the RX row. An approximation (the
# published layout gives positions within each group only): it moves the physical antennas, never
# the virtual array.
CASCADE_TX_RX_SEPARATION_M = 0.020


def wavelength_from_chirp(fc_hz: float, bandwidth_hz: float) -> float:
    """Return the wavelength at the chirp's centre frequency, ``c0 / (fc + B/2)``, in metres."""
    if not (np.isfinite(fc_hz) and fc_hz > 0):
        raise ArrayError(f"fc_hz: must be a finite frequency > 0, got {fc_hz!r}")
    if not (np.isfinite(bandwidth_hz) and bandwidth_hz >= 0):
        raise ArrayError(f"bandwidth_hz: must be finite and >= 0, got {bandwidth_hz!r}")
    return C0_MPS / (fc_hz + bandwidth_hz / 2.0)


def direction_cosines(az_rad: ArrayLike, el_rad: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Return ``(u, s) = (cos el sin az, sin el)`` for angles in radians."""
    az = np.asarray(az_rad, dtype=np.float64)
    el = np.asarray(el_rad, dtype=np.float64)
    return np.cos(el) * np.sin(az), np.sin(el)


def angles_from_cosines(u: ArrayLike, s: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Invert `direction_cosines` on the front hemisphere; returns ``(az_rad, el_rad)``."""
    u = np.asarray(u, dtype=np.float64)
    s = np.clip(np.asarray(s, dtype=np.float64), -1.0, 1.0)
    el = np.arcsin(s)
    cos_el = np.sqrt(1.0 - s * s)
    az = np.arctan2(u, np.sqrt(np.maximum(cos_el * cos_el - u * u, 0.0)))
    return az, el


@dataclass(frozen=True, eq=False)
class Antennas:
    """Physical TX and RX antennas of a radar: phase centres in its face plane ``x = 0``.

    Positions are relative to the radar's **reference point**, the point from which the rig's FE
    azimuths, elevations and distances are measured (and the mount pose is given). The virtual
    array (`virtual_array`) only depends on the positions within the TX group and within the RX
    group; where the groups sit relative to the reference point matters at the bench, where the
    FEs are close enough for the paths to be spherical.

    Parameters
    ----------
    tx_y_m, tx_z_m : ndarray, shape (T,)
        TX phase centres along y (left) and z (up), metres.
    rx_y_m, rx_z_m : ndarray, shape (R,)
        RX phase centres, metres.
    name : str
        Preset or profile name, for reports.
    """

    tx_y_m: FloatArray
    tx_z_m: FloatArray
    rx_y_m: FloatArray
    rx_z_m: FloatArray
    name: str = "custom"

    def __post_init__(self) -> None:
        for group in ("tx", "rx"):
            y = np.array(getattr(self, f"{group}_y_m"), dtype=np.float64, ndmin=1)
            z = np.array(getattr(self, f"{group}_z_m"), dtype=np.float64, ndmin=1)
            if y.ndim != 1 or y.shape != z.shape or y.size == 0:
                raise ArrayError(
                    f"{group}_y_m and {group}_z_m: must be non-empty lists of the same length, "
                    f"got shapes {y.shape} and {z.shape}"
                )
            if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
                raise ArrayError(f"{group}_y_m, {group}_z_m: positions must be finite numbers")
            for name, value in ((f"{group}_y_m", y), (f"{group}_z_m", z)):
                value.setflags(write=False)
                object.__setattr__(self, name, value)

    @classmethod
    def preset(cls, name: str, wavelength_m: float) -> Antennas:
        """Return a shipped layout, its spacings in units of ``wavelength_m``.

        Every preset puts the reference point at the virtual array's centroid (the midpoint
        between the TX group's and the RX group's centroids): a far FE's echo then reaches the
        virtual array with the same phase from every direction, as the solver assumes. A
        reference point elsewhere adds a direction-dependent phase to each FE's echo that the
        rig's phase calibration has to take out.

        ``paper``: 4 RX along y, lambda/2 apart, and 3 TX along z at y = 0, lambda/2 apart,
        both centred on the reference point.

        ``awr1843boost``: RX at y = -3l/4 .. 3l/4 (lambda/2 apart) around y = +5 mm; TX0, TX1,
        TX2 at y = -l, 0, +l around y = -5 mm (the groups' centroids
        `AWR1843BOOST_TX_RX_SEPARATION_M` = 10 mm apart); TX0, TX2 and the RX row at
        z = -l/12, TX1 l/2 higher. Relative to each other these are DESIGN 5.1's positions
        (RX at 0 .. 3l/2, TX0 (0, 0), TX1 (l, l/2), TX2 (2l, 0)), so the virtual array is that
        of ``VirtualArray.preset("awr1843boost")``.

        ``cascade-12x16``: TI's 4-chip cascade board MMWCAS-RF-EVM, positions in units of
        d = lambda/2 as published in TI's cascade processing examples (mmWave Studio MATLAB
        ``TI_Cascade_TX_position_azi/ele``, ``TI_Cascade_RX_position_azi``, designed for
        76.8 GHz): RX at azimuth 11..14, 50..53, 46..49, 0..3 (one row); TX at azimuth
        11, 10, 9, 32, 28, 24, 20, 16, 12, 8, 4, 0 and elevation 6, 4, 1, 0, ... 0. The 9 TX
        of the lower row, 2 lambda apart, make 86 distinct virtual azimuth positions; the 3
        raised TX give elevation. Physical placement (an approximation): both groups centred
        on the reference point in y, the TX group's centroid `CASCADE_TX_RX_SEPARATION_M`
        (20 mm) below the RX row.
        """
        lam = float(wavelength_m)
        half = lam / 2.0
        steps3 = np.arange(3, dtype=np.float64) - 1.0  # -1, 0, 1
        steps4 = np.arange(4, dtype=np.float64) - 1.5  # -3/2 .. 3/2
        if name == "paper":
            return cls(np.zeros(3), steps3 * half, steps4 * half, np.zeros(4), name=name)
        if name == "awr1843boost":
            sep = AWR1843BOOST_TX_RX_SEPARATION_M
            return cls(-sep / 2.0 + steps3 * lam, np.array([0.0, half, 0.0]) - lam / 12.0,
                       sep / 2.0 + steps4 * half, np.full(4, -lam / 12.0), name=name)
        if name == "cascade-12x16":
            tx_az = np.array([11, 10, 9, 32, 28, 24, 20, 16, 12, 8, 4, 0], dtype=float)
            tx_el = np.array([6, 4, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0], dtype=float)
            rx_az = np.concatenate([np.arange(11, 15), np.arange(50, 54), np.arange(46, 50),
                                    np.arange(0, 4)]).astype(float)
            sep = CASCADE_TX_RX_SEPARATION_M
            return cls((tx_az - tx_az.mean()) * half,
                       -sep / 2.0 + (tx_el - tx_el.mean()) * half,
                       (rx_az - rx_az.mean()) * half, np.full(16, sep / 2.0), name=name)
        raise ArrayError(
            f"unknown antenna preset {name!r}; valid presets: {', '.join(ANTENNA_PRESETS)}"
        )

    @property
    def n_tx(self) -> int:
        """Number of TX antennas."""
        return int(self.tx_y_m.size)

    @property
    def n_rx(self) -> int:
        """Number of RX antennas."""
        return int(self.rx_y_m.size)

    @property
    def extent_m(self) -> float:
        """Largest distance between any two antennas (the aperture D of the Fraunhofer distance)."""
        y = np.concatenate([self.tx_y_m, self.rx_y_m])
        z = np.concatenate([self.tx_z_m, self.rx_z_m])
        return float(np.hypot(y[:, None] - y[None, :], z[:, None] - z[None, :]).max())

    def virtual_array(self, *, fc_hz: float, bandwidth_hz: float) -> VirtualArray:
        """Return the TDM-MIMO virtual array (TX-major, centred) at the chirp centre wavelength."""
        return VirtualArray.from_tx_rx(self.tx_y_m, self.tx_z_m, self.rx_y_m, self.rx_z_m,
                                       fc_hz=fc_hz, bandwidth_hz=bandwidth_hz, name=self.name)


@dataclass(frozen=True, eq=False)
class VirtualArray:
    """Virtual (TX + RX) element positions of a radar, centred on their centroid.

    Parameters
    ----------
    y_m, z_m : ndarray, shape (M,)
        Element positions along y (left) and z (up), metres, centroid at the origin.
    wavelength_m : float
        Wavelength at the chirp's centre frequency, metres.
    name : str
        Preset or profile name, for reports.
    """

    y_m: FloatArray
    z_m: FloatArray
    wavelength_m: float
    name: str = "custom"

    @classmethod
    def from_positions(
        cls,
        y_m: ArrayLike,
        z_m: ArrayLike,
        *,
        wavelength_m: float,
        name: str = "custom",
    ) -> VirtualArray:
        """Build an array from virtual element positions (metres); they are re-centred."""
        y = np.array(y_m, dtype=np.float64, ndmin=1)
        z = np.array(z_m, dtype=np.float64, ndmin=1)
        if y.ndim != 1 or y.shape != z.shape:
            raise ArrayError(
                f"y_m and z_m: must be 1-D with the same length, got shapes {y.shape} and {z.shape}"
            )
        if y.size == 0:
            raise ArrayError("y_m: an array needs at least one element, got none")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
            raise ArrayError("y_m, z_m: element positions must be finite numbers")
        if not (np.isfinite(wavelength_m) and wavelength_m > 0):
            raise ArrayError(f"wavelength_m: must be finite and > 0, got {wavelength_m!r}")
        y = y - y.mean()
        z = z - z.mean()
        y.setflags(write=False)
        z.setflags(write=False)
        return cls(y_m=y, z_m=z, wavelength_m=float(wavelength_m), name=name)

    @classmethod
    def from_tx_rx(
        cls,
        tx_y_m: ArrayLike,
        tx_z_m: ArrayLike,
        rx_y_m: ArrayLike,
        rx_z_m: ArrayLike,
        *,
        fc_hz: float,
        bandwidth_hz: float,
        name: str = "custom",
    ) -> VirtualArray:
        """Build the TDM-MIMO virtual array (every TX position plus every RX position).

        Element order is TX-major: element ``t * n_rx + r`` is TX ``t`` with RX ``r``.
        """
        tx_y, tx_z = (np.array(v, dtype=np.float64, ndmin=1) for v in (tx_y_m, tx_z_m))
        rx_y, rx_z = (np.array(v, dtype=np.float64, ndmin=1) for v in (rx_y_m, rx_z_m))
        if tx_y.shape != tx_z.shape or rx_y.shape != rx_z.shape:
            raise ArrayError("TX and RX positions: y and z lists must have the same length")
        y = (tx_y[:, None] + rx_y[None, :]).ravel()
        z = (tx_z[:, None] + rx_z[None, :]).ravel()
        return cls.from_positions(
            y, z, wavelength_m=wavelength_from_chirp(fc_hz, bandwidth_hz), name=name
        )

    @classmethod
    def preset(cls, name: str) -> VirtualArray:
        """Return a shipped array: ``"paper"`` or ``"awr1843boost"`` (77 GHz, 1 GHz chirp).

        ``paper``: 4 RX along y and 3 TX along z, both lambda/2 apart (12 elements).
        ``awr1843boost``: RX at y = 0, l/2, l, 3l/2; TX at (0, 0), (l, l/2), (2l, 0) in (y, z),
        giving 8 elements in the azimuth row and 4 in a row lambda/2 higher.
        """
        lam = wavelength_from_chirp(PAPER_FC_HZ, PAPER_BANDWIDTH_HZ)
        half = lam / 2.0
        if name == "paper":
            rx_y = np.arange(4) * half
            tx_z = np.arange(3) * half
            return cls.from_tx_rx(
                np.zeros(3), tx_z, rx_y, np.zeros(4),
                fc_hz=PAPER_FC_HZ, bandwidth_hz=PAPER_BANDWIDTH_HZ, name=name,
            )
        if name == "awr1843boost":
            return cls.from_tx_rx(
                [0.0, lam, 2 * lam], [0.0, half, 0.0], np.arange(4) * half, np.zeros(4),
                fc_hz=PAPER_FC_HZ, bandwidth_hz=PAPER_BANDWIDTH_HZ, name=name,
            )
        raise ArrayError(f"unknown array preset {name!r}; valid presets: {', '.join(PRESETS)}")

    @property
    def n_elements(self) -> int:
        """Number of virtual elements M."""
        return int(self.y_m.size)

    @property
    def wavenumber_rad_per_m(self) -> float:
        """Wavenumber ``k = 2 pi / wavelength``."""
        return 2.0 * np.pi / self.wavelength_m

    @cached_property
    def is_centrosymmetric(self) -> bool:
        """Whether the layout equals its point reflection (then the response is real).

        Counting elements at one place: as many at each position as at its mirror.
        """
        tol = 1e-9 * self.wavelength_m
        pos = np.column_stack([self.y_m, self.z_m])
        mirrored = (np.abs(pos[:, None, :] + pos[None, :, :]).max(axis=2) <= tol).sum(axis=1)
        same = (np.abs(pos[:, None, :] - pos[None, :, :]).max(axis=2) <= tol).sum(axis=1)
        return bool(np.all(mirrored == same))

    @property
    def key(self) -> tuple[Any, ...]:
        """Hashable identity of the layout, used to cache per-array precomputation."""
        return (self.y_m.tobytes(), self.z_m.tobytes(), self.wavelength_m)

    def sinc_aperture_m(self) -> tuple[float, float]:
        """Effective apertures (N * d) along y and z of the paper's sinc model, metres.

        N is the number of distinct positions along the axis and d their mean pitch; for the
        paper's uniform rows that is exactly ``N_rx * d_y,rx`` and ``N_tx * d_z,tx``.
        """
        out = []
        for pos in (self.y_m, self.z_m):
            distinct = _distinct(pos, 1e-9 * self.wavelength_m)
            n = distinct.size
            out.append(0.0 if n < 2 else n * (distinct[-1] - distinct[0]) / (n - 1))
        return out[0], out[1]

    def steering_vector(self, az_deg: ArrayLike, el_deg: ArrayLike) -> ComplexArray:
        """Return steering vectors ``a(az, el)``, shape ``(N, M)``, for angles in degrees."""
        u, s = direction_cosines(np.radians(az_deg), np.radians(el_deg))
        phase = self.wavenumber_rad_per_m * (
            np.multiply.outer(np.ravel(u), self.y_m) + np.multiply.outer(np.ravel(s), self.z_m)
        )
        return np.exp(1j * phase)

    def response(
        self,
        az_deg: ArrayLike,
        el_deg: ArrayLike,
        source_az_deg: ArrayLike,
        source_el_deg: ArrayLike,
    ) -> ComplexArray:
        """Return ``f_q(az, el) = a(az, el)^H a(source_q)``, shape ``(N, Q)``."""
        look = self.steering_vector(az_deg, el_deg)
        src = self.steering_vector(source_az_deg, source_el_deg)
        return look.conj() @ src.T

    def beamformer(
        self,
        az_deg: ArrayLike,
        el_deg: ArrayLike,
        weights: ArrayLike,
        source_az_deg: ArrayLike,
        source_el_deg: ArrayLike,
    ) -> ComplexArray:
        """Bartlett output ``B = sum_q w_q f_q(az, el)`` for one weight row per look direction.

        ``weights`` has shape ``(N, Q)`` (complex allowed: magnitude and phase per source).
        """
        f = self.response(az_deg, el_deg, source_az_deg, source_el_deg)
        return np.einsum("nq,nq->n", f, np.asarray(weights).reshape(f.shape))

    def source_response(
        self, source_u: ArrayLike, source_s: ArrayLike, vectors: ComplexArray | None = None
    ) -> SourceResponse:
        """Precompute the response kernel for fixed sources given by direction cosines.

        ``vectors`` (shape ``(M, Q)``), when given, are the sources' response vectors on the
        array (e.g. near-field FEs, `rts_scenario.responses`) in place of their plane-wave
        steering vectors.
        """
        return SourceResponse(self, np.ravel(source_u), np.ravel(source_s), vectors)


def plane_waves(array: VirtualArray, source_u: ArrayLike, source_s: ArrayLike) -> ComplexArray:
    """Steering vectors of sources at direction cosines ``(u, s)``, shape ``(M, Q)``."""
    k = array.wavenumber_rad_per_m
    return np.exp(1j * k * (np.outer(array.y_m, np.ravel(source_u))
                            + np.outer(array.z_m, np.ravel(source_s))))


def _distinct(values: FloatArray, tol: float) -> FloatArray:
    ordered = np.sort(values)
    keep = np.concatenate([[True], np.diff(ordered) > tol])
    return ordered[keep]


class SourceResponse:
    """Response ``f_q(u, s)`` and its derivatives for a fixed set of Q sources, vectorized over N.

    ``f_q(u, s) = a(u, s)^H r_q``, with ``r_q`` the source's steering vector ``a(u_q, s_q)``
    or, when ``vectors`` is given (shape ``(M, Q)``), its column q.

    Exploits the layout: with ``ny`` distinct y and ``nz`` distinct z positions, the steering
    vector factors into ``ny + nz`` complex exponentials per look direction (fewer for symmetric
    or evenly spaced positions); the sum over elements is one small matrix product.
    """

    def __init__(
        self,
        array: VirtualArray,
        source_u: FloatArray,
        source_s: FloatArray,
        vectors: ComplexArray | None = None,
    ) -> None:
        k = array.wavenumber_rad_per_m
        tol = 1e-9 * array.wavelength_m
        self.k = k
        self.n_sources = int(source_u.size)
        self.source_u, self.source_s = source_u, source_s
        self.y_distinct = _distinct(array.y_m, tol)
        self.z_distinct = _distinct(array.z_m, tol)
        iy = np.abs(array.y_m[:, None] - self.y_distinct[None, :]).argmin(axis=1)
        iz = np.abs(array.z_m[:, None] - self.z_distinct[None, :]).argmin(axis=1)
        if vectors is None:
            a_src = plane_waves(array, source_u, source_s)
        else:
            a_src = np.asarray(vectors, dtype=np.complex128)
            if a_src.shape != (array.n_elements, source_u.size):
                raise ArrayError(
                    f"vectors: need shape (elements, sources) = "
                    f"({array.n_elements}, {source_u.size}), got {a_src.shape}"
                )
        dy = -1j * k * array.y_m[:, None]
        dz = -1j * k * array.z_m[:, None]
        stacked = np.stack(
            [a_src, dy * a_src, dz * a_src, dy * dy * a_src, dy * dz * a_src, dz * dz * a_src]
        )
        # table[term, q, v]: what element v contributes to each term, times conj(a_v(u, s)).
        self.table = np.ascontiguousarray(np.moveaxis(stacked, 1, 2))
        self._iy, self._iz = iy, iz
        self._y_plan = _exp_plan(self.y_distinct, tol)
        self._z_plan = _exp_plan(self.z_distinct, tol)

    def evaluate(
        self, u: FloatArray, s: FloatArray, terms: int = 6, phase: FloatArray | None = None
    ) -> ComplexArray:
        """Return ``f`` and its derivatives at look directions ``(u, s)``.

        Shape ``(terms, Q, N)``: the first ``terms`` of ``f, f_u, f_s, f_uu, f_us, f_ss``,
        multiplied by ``exp(-j phase)`` per look direction when ``phase`` is given.
        """
        u = np.asarray(u, dtype=np.float64)
        s = np.asarray(s, dtype=np.float64)
        ey = _exp_rows(self.k, self.y_distinct, self._y_plan, u)
        ez = _exp_rows(self.k, self.z_distinct, self._z_plan, s)
        if phase is not None:
            ez *= np.exp(-1j * phase)
        # conj(a_v(u, s)) = exp(-j k y_v u) exp(-j k z_v s): one product per element, then one
        # matrix product (a single pass over memory; chunks stay cache-sized).
        look = ey[self._iy]
        look *= ez[self._iz]
        rows = terms * self.n_sources
        out = self.table[:terms].reshape(rows, -1) @ look
        return out.reshape(terms, self.n_sources, -1)


@dataclass(frozen=True)
class _ExpPlan:
    """How to get ``exp(-j k c x)`` for a set of coordinates with the fewest exponentials.

    ``direct`` coordinates are computed, in increasing order: by ``exp`` or, when they form an
    arithmetic progression, from the first one and the common step by multiplication.
    ``mirror[i]`` is the computed coordinate equal to ``-c_i`` (taken as a conjugate);
    ``indirect`` the coordinates taken so, in increasing order.
    """

    direct: NDArray[np.int64]
    mirror: NDArray[np.int64]
    progression: bool
    indirect: NDArray[np.int64]


def _exp_plan(coords: FloatArray, tol: float) -> _ExpPlan:
    index = np.arange(coords.size)
    mirror = np.abs(coords[:, None] + coords[None, :]).argmin(axis=1)
    symmetric = np.abs(coords + coords[mirror]) <= tol
    direct = index[(coords >= -tol) | ~symmetric | (mirror == index)]
    steps = np.diff(coords[direct])
    progression = direct.size >= 3 and bool(np.all(np.abs(steps - steps[0]) <= tol))
    taken = np.zeros(coords.size, dtype=bool)
    taken[direct] = True
    return _ExpPlan(direct=direct, mirror=np.where(symmetric, mirror, -1), progression=progression,
                    indirect=index[~taken])


def _exp_rows(k: float, coords: FloatArray, plan: _ExpPlan, x: FloatArray) -> ComplexArray:
    """``exp(-j k c x)`` for every coordinate ``c``, shape ``(len(coords), N)``."""
    out = np.empty((coords.size, x.size), dtype=np.complex128)
    direct = plan.direct
    if plan.progression:
        np.exp(-1j * k * coords[direct[0]] * x, out=out[direct[0]])
        step = np.exp(-1j * k * (coords[direct[1]] - coords[direct[0]]) * x)
        for prev, i in zip(direct[:-1], direct[1:], strict=True):
            np.multiply(out[prev], step, out=out[i])
    else:
        for i in direct:
            np.exp(-1j * k * coords[i] * x, out=out[i])
    # exp(-j k (-c) x) = conj(exp(-j k c x)).
    for i in plan.indirect:
        np.conjugate(out[plan.mirror[i]], out=out[i])
    return out
