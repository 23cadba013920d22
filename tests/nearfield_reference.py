r"""Independent first-principles reference for the honest (near-field) RTS bench.

This module is a measuring instrument: it shares no code with ``rts_scenario`` and uses only
numpy and scipy. It models one radar under test (FMCW, TDM-MIMO, point antennas in its face
plane ``x = 0``) in front of RTS front ends (FEs) that each receive the radar's chirp with their
own receive antenna and re-transmit it, delayed, Doppler shifted, attenuated and phase shifted,
from their own transmit antenna.

Conventions
-----------
Radar frame: x forward, y left, z up. ``az = atan2(y, x)``, ``el = atan2(z, hypot(x, y))``,
unit direction ``u = (cos el cos az, cos el sin az, sin el)``. ``c0 = 299792458 m/s``. The
profile's nominal wavelength is ``c0 / (fc + B / 2)``.

Geometry
--------
Radar TX ``t`` is at ``p_t = (0, tx_y_m[t], tx_z_m[t])`` and RX ``r`` at
``p_r = (0, rx_y_m[r], rx_z_m[r])``, relative to the radar's reference point (the origin).
A FE at nominal direction ``(az, el)`` and distance ``D`` has its centre at ``D u``; its receive
antenna sits at ``D u + dy e_az + dz e_el`` with ``[dy, dz] = rx_offset_m`` and its transmit
antenna likewise with ``tx_offset_m``, where ``e_az = (-sin az, cos az, 0)`` (increasing
azimuth) and ``e_el = (-sin el cos az, -sin el sin az, cos el)`` (increasing elevation). Both
are perpendicular to ``u`` and to each other. Path lengths are exact (spherical):
``d_up[t] = |p_t - FE_rx|``, ``d_down[r] = |FE_tx - p_r|``, ``T_air = (d_up + d_down) / c0``.
The virtual channel ``v = t * n_rx + r`` (TX-major) has the plane-wave position
``(y_v, z_v) = (tx_y + rx_y, tx_z + rx_z)``.

Derivation of the beat signal
-----------------------------
Complex-baseband model, every signal written as ``exp(j Phi)``. Within chirp ``k`` that starts
at absolute time ``t_k`` the radar transmits

    Phi_tx(t) = Phi_k + 2 pi [fc (t - t_k) + S (t - t_k)^2 / 2],   S = B / T_ramp,

so the instantaneous frequency is ``f(t) = fc + S (t - t_k)``. The start phase ``Phi_k`` of the
synthesizer cancels in the mixing below.

*Up leg.* The FE receive antenna sees ``exp(j Phi_tx(t - T_up))``, ``T_up = d_up / c0``.

*RTS, IF delay (digital RTS, ``delay_model="if"``).* The RTS down-converts with a fixed LO at
``f_LO = fc - f_if`` (so ``f_if`` is the IF at the chirp's start frequency; the IF sweeps
``f_if + S (t - t_k)`` with the chirp), multiplying by ``exp(-j 2 pi f_LO t)``; delays the IF
signal by ``tau``; up-converts with the same LO, ``exp(+j 2 pi f_LO t)``:

    exp(j [Phi_tx(t - T_up - tau) - 2 pi f_LO (t - tau) + 2 pi f_LO t])
        = exp(j [Phi_tx(t - T_up - tau) + 2 pi f_LO tau]).

(The LO's absolute phase cancels, being the same LO.) It then applies the Doppler shift
``exp(j 2 pi fd t)`` and the complex gain ``A exp(j phi)`` at its output (RTS output time).

*RTS, RF delay line (``delay_model="rf"``).* The delay acts on the RF signal itself: no
``+2 pi f_LO tau`` term; the delay carries the full RF phase like an air path.

*Down leg.* The radar RX receives the FE output ``T_down = d_down / c0`` later. With
``T = T_up + tau + T_down`` the received signal at radar time ``t`` is

    r(t) = A exp(j [Phi_tx(t - T) + 2 pi f_LO tau [IF only] + 2 pi fd (t - T_down) + phi]).

*Mixing.* The radar's complex (I/Q) mixer forms ``x(t) = r(t) conj(s(t))``, ``s = exp(j Phi_tx)``.
This sign choice is the one consistent with the package's other conventions: a plane wave
from direction ``u`` shortens the path to an element at ``p`` by ``u . p``, so with
``x = r conj(s)`` the channel phase is ``+2 pi u . p / lambda``, which is exactly the steering
vector ``a_v = exp(+j 2 pi / lambda (y_v cos el sin az + z_v sin el))``; and a receding target
(``T`` growing) gives a negative Doppler frequency, matching ``doppler_hz = -2 v / lambda``.
With ``t_f = t - t_k`` the fast time within the chirp,

    Phi_tx(t - T) - Phi_tx(t) = -2 pi [fc T + S t_f T - S T^2 / 2],

so the beat phase is, exactly (no approximation in the model),

    psi = -2 pi [fc T_air + f_x tau + S t_f T - S T^2 / 2] + 2 pi fd (t - T_down) + phi,

with ``f_x = f_if`` for the IF delay (``-2 pi fc tau + 2 pi f_LO tau = -2 pi f_if tau``) and
``f_x = fc`` for the RF delay line. The beat frequency is ``-S T + fd`` (range-Doppler coupling
comes out by itself because the Doppler ramp is evaluated at the true time ``t`` of every
sample: ``t = l T_loop + slot(t_tx) T_slot + t_adc + n / fs``). The total delay ``T`` (air +
RTS) drives the beat frequency through ``S T`` in both models: the IF delay only changes the
*carrier* phase the delay contributes.

*Residual video phase.* The term ``+2 pi S T^2 / 2`` (RVP) is **kept**: it is part of the exact
difference of the two chirp phases, costs nothing, and is not negligible for long RTS delays
(``T = 1 us``, ``S = 2e13 Hz/s``: 10 cycles; its per-channel part ``2 pi S T dT`` is 1e-3 rad
for ``dT = 10 ps``). Equivalently, the element-to-element phase is governed by the frequency of
the wave that arrives at the sampling instant, ``d psi / d T = -2 pi (fc + S (t_f - T))``.

The formula is used as a mathematical continuation when ``t_f < T`` (the echo of the current
chirp has not arrived yet); a real radar starts sampling after the echoes arrive.

*Level.* Isotropic antennas; with ``spreading_loss=True`` each leg's free-space amplitude
``1 / d`` is applied, normalized to the FE's nominal distance: the channel amplitude is
``A (D / d_up) (D / d_down)``, equal to ``A`` for a far FE. The amplitude is evaluated at one
frequency (no ``lambda / (4 pi d)`` change across the sweep).

Snapshot (what a range-Doppler FFT peak gives)
----------------------------------------------
A range FFT over samples ``n = 0 .. N-1`` (symmetric window), evaluated at an echo's beat
frequency, equals ``x(n_c) * W * exp(-j 2 pi k n_c / N)`` with ``n_c = (N - 1) / 2``, ``W`` real
and ``exp(-j 2 pi k n_c / N)`` common to every channel (same bin ``k``). So, up to a channel-
common factor, the radar's complex value is the beat phasor at the centre sample of the sampled
sweep, and its per-channel phase is governed by the frequency there: that is why a well
designed radar steers with ``c0 / (fc + S t_c)``, ``t_c = t_adc + n_c / fs``. Likewise for the
Doppler FFT over loops. :func:`array_snapshot` therefore returns, per virtual channel, the sum
over the echoes of ``beat phasor(n_ref, l_ref) * exp(-j 2 pi fd (l_ref T_loop + t_f,ref))``:

* removed (common to all channels, per echo): the slow-time and fast-time Doppler phase
  ``2 pi fd (l_ref T_loop + t_f,ref)``; with ``compensate_tdm_doppler=True`` also the TDM slot
  term ``2 pi fd slot(t) T_slot``, which is per TX and is what a TDM-MIMO radar removes with its
  Doppler estimate before angle estimation;
* kept (per channel): the carrier and delay phase ``-2 pi [fc T_air + f_x tau + S t_f,ref T -
  S T^2 / 2]`` (its channel-common part is kept too, so that echoes with different delays or
  phases superpose correctly, and tests can read the common phase), the RTS phase, the tiny
  Doppler term ``-2 pi fd T_down`` (the RTS applies Doppler at its output time), and the
  spreading-loss amplitudes.

The FFT's bin phase ``exp(-j 2 pi k n_c / N)`` and window gain are not modelled (common).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

__all__ = [
    "C0_MPS",
    "FmcwChirp",
    "array_snapshot",
    "awr1843boost_layout",
    "bartlett_direction",
    "bartlett_spectrum",
    "beat_phasors",
    "direction_unit_vector",
    "fe_antenna_positions",
    "paper_layout",
    "path_lengths",
    "seen_direction_of_fe",
    "virtual_positions",
]

C0_MPS = 299_792_458.0
"""Speed of light in vacuum, m/s."""


@dataclass(frozen=True)
class FmcwChirp:
    """FMCW chirp sequence of a TDM-MIMO radar.

    Parameters
    ----------
    fc_hz : float
        Start frequency of the chirp.
    bandwidth_hz : float
        Swept bandwidth over ``ramp_time_s``.
    ramp_time_s : float
        Ramp duration; slope ``S = bandwidth_hz / ramp_time_s``.
    sample_rate_hz : float
        ADC sample rate.
    n_samples : int
        ADC samples per chirp.
    adc_start_s : float, optional
        Time from the chirp start to ADC sample 0.
    idle_time_s : float, optional
        Idle time between ramps; one chirp slot lasts ``ramp_time_s + idle_time_s``.
    tx_slot : tuple of int, optional
        Slot index, within one loop, in which each TX fires (default: TX ``t`` in slot ``t``).
    n_slots : int, optional
        Slots per loop (default: number of TX, or ``max(tx_slot) + 1``).
    """

    fc_hz: float
    bandwidth_hz: float
    ramp_time_s: float
    sample_rate_hz: float
    n_samples: int
    adc_start_s: float = 0.0
    idle_time_s: float = 0.0
    tx_slot: tuple[int, ...] | None = None
    n_slots: int | None = None

    @property
    def slope_hz_per_s(self) -> float:
        """Chirp slope ``S`` in Hz/s."""
        return self.bandwidth_hz / self.ramp_time_s

    @property
    def chirp_slot_s(self) -> float:
        """Duration of one TDM slot (ramp plus idle)."""
        return self.ramp_time_s + self.idle_time_s

    @property
    def nominal_wavelength_m(self) -> float:
        """Profile's nominal wavelength ``c0 / (fc + B / 2)``."""
        return C0_MPS / (self.fc_hz + self.bandwidth_hz / 2.0)

    @property
    def centre_sample(self) -> float:
        """Centre of the sampled sweep in samples, ``(N - 1) / 2``."""
        return (self.n_samples - 1) / 2.0

    def fast_time_s(self, sample_index: ArrayLike) -> NDArray[np.float64]:
        """Time since the chirp start of (possibly fractional) ADC samples."""
        return self.adc_start_s + np.asarray(sample_index, dtype=float) / self.sample_rate_hz

    @property
    def sampled_centre_frequency_hz(self) -> float:
        """Transmit frequency at the centre of the sampled sweep."""
        return self.fc_hz + self.slope_hz_per_s * float(self.fast_time_s(self.centre_sample))

    @property
    def steering_wavelength_m(self) -> float:
        """Wavelength a well-designed radar steers with: at the centre of the sampled sweep."""
        return C0_MPS / self.sampled_centre_frequency_hz

    def slots(self, n_tx: int) -> NDArray[np.float64]:
        """Slot index of each of ``n_tx`` TX."""
        if self.tx_slot is None:
            return np.arange(n_tx, dtype=float)
        if len(self.tx_slot) != n_tx:
            raise ValueError(f"tx_slot has {len(self.tx_slot)} entries for {n_tx} TX")
        return np.asarray(self.tx_slot, dtype=float)

    def loop_time_s(self, n_tx: int) -> float:
        """Duration of one loop (all TDM slots)."""
        if self.n_slots is not None:
            n = self.n_slots
        elif self.tx_slot is not None:
            n = max(self.tx_slot) + 1
        else:
            n = n_tx
        return n * self.chirp_slot_s


def paper_layout(wavelength_m: float) -> dict[str, NDArray[np.float64]]:
    """Return the ``paper`` antenna layout, not centred.

    RX along y: 4 elements ``lambda / 2`` apart at ``z = 0`` starting at ``y = 0``; TX along z:
    3 elements ``lambda / 2`` apart at ``y = 0`` starting at ``z = 0``.

    Parameters
    ----------
    wavelength_m : float
        Wavelength the spacings refer to.

    Returns
    -------
    dict
        ``tx_y_m, tx_z_m, rx_y_m, rx_z_m`` arrays.
    """
    h = wavelength_m / 2.0
    return {
        "tx_y_m": np.zeros(3),
        "tx_z_m": np.arange(3) * h,
        "rx_y_m": np.arange(4) * h,
        "rx_z_m": np.zeros(4),
    }


def awr1843boost_layout(wavelength_m: float) -> dict[str, NDArray[np.float64]]:
    """Return the ``awr1843boost`` antenna layout, not centred.

    RX at ``y = 0, lambda/2, lambda, 3 lambda/2`` (``z = 0``); TX0 at ``(0, 0)``, TX1 at
    ``(lambda, lambda/2)``, TX2 at ``(2 lambda, 0)``.

    Parameters
    ----------
    wavelength_m : float
        Wavelength the positions refer to.

    Returns
    -------
    dict
        ``tx_y_m, tx_z_m, rx_y_m, rx_z_m`` arrays.
    """
    lam = wavelength_m
    return {
        "tx_y_m": np.array([0.0, lam, 2.0 * lam]),
        "tx_z_m": np.array([0.0, lam / 2.0, 0.0]),
        "rx_y_m": np.arange(4) * lam / 2.0,
        "rx_z_m": np.zeros(4),
    }


def direction_unit_vector(az_deg: ArrayLike, el_deg: ArrayLike) -> NDArray[np.float64]:
    """Unit vector ``(cos el cos az, cos el sin az, sin el)``.

    Parameters
    ----------
    az_deg, el_deg : array_like
        Azimuth and elevation in degrees (broadcast together).

    Returns
    -------
    ndarray
        Shape ``broadcast_shape + (3,)``.
    """
    az = np.deg2rad(np.asarray(az_deg, dtype=float))
    el = np.deg2rad(np.asarray(el_deg, dtype=float))
    az, el = np.broadcast_arrays(az, el)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def fe_antenna_positions(
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    distance_m: ArrayLike,
    rx_offset_m: ArrayLike = (0.0, 0.0),
    tx_offset_m: ArrayLike = (0.0, 0.0),
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions of the FEs' receive and transmit antennas in the radar frame.

    Parameters
    ----------
    az_deg, el_deg, distance_m : array_like
        Nominal direction and distance of each FE (broadcast to ``(E,)``).
    rx_offset_m, tx_offset_m : array_like
        ``[dy, dz]`` offsets, shape ``(2,)`` or ``(E, 2)``: ``dy`` along
        ``e_az = (-sin az, cos az, 0)``, ``dz`` along
        ``e_el = (-sin el cos az, -sin el sin az, cos el)``.

    Returns
    -------
    fe_rx_m, fe_tx_m : ndarray
        Shape ``(E, 3)`` each.
    """
    az_deg, el_deg, distance_m = (
        np.atleast_1d(np.asarray(a, dtype=float))
        for a in np.broadcast_arrays(az_deg, el_deg, distance_m)
    )
    n = az_deg.shape[0]
    az = np.deg2rad(az_deg)
    el = np.deg2rad(el_deg)
    u = direction_unit_vector(az_deg, el_deg)
    e_az = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], axis=-1)
    e_el = np.stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)], axis=-1)
    centre = distance_m[:, None] * u
    rx_off = np.broadcast_to(np.asarray(rx_offset_m, dtype=float), (n, 2))
    tx_off = np.broadcast_to(np.asarray(tx_offset_m, dtype=float), (n, 2))
    fe_rx = centre + rx_off[:, :1] * e_az + rx_off[:, 1:] * e_el
    fe_tx = centre + tx_off[:, :1] * e_az + tx_off[:, 1:] * e_el
    return fe_rx, fe_tx


def virtual_positions(
    tx_y_m: ArrayLike, tx_z_m: ArrayLike, rx_y_m: ArrayLike, rx_z_m: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Virtual array positions ``tx + rx`` in TX-major order ``v = t * n_rx + r``.

    Parameters
    ----------
    tx_y_m, tx_z_m, rx_y_m, rx_z_m : array_like
        Physical antenna positions in the radar face plane.

    Returns
    -------
    y_m, z_m : ndarray
        Shape ``(n_tx * n_rx,)`` each.
    """
    ty, tz = np.asarray(tx_y_m, dtype=float), np.asarray(tx_z_m, dtype=float)
    ry, rz = np.asarray(rx_y_m, dtype=float), np.asarray(rx_z_m, dtype=float)
    return (ty[:, None] + ry[None, :]).ravel(), (tz[:, None] + rz[None, :]).ravel()


def path_lengths(
    tx_y_m: ArrayLike,
    tx_z_m: ArrayLike,
    rx_y_m: ArrayLike,
    rx_z_m: ArrayLike,
    fe_rx_m: ArrayLike,
    fe_tx_m: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact spherical leg lengths.

    Parameters
    ----------
    tx_y_m, tx_z_m, rx_y_m, rx_z_m : array_like
        Radar antenna positions (``x = 0``).
    fe_rx_m, fe_tx_m : array_like
        FE receive / transmit antenna positions, shape ``(E, 3)``.

    Returns
    -------
    d_up_m : ndarray
        ``|TX_t - FE_rx|``, shape ``(E, n_tx)``.
    d_down_m : ndarray
        ``|FE_tx - RX_r|``, shape ``(E, n_rx)``.
    """
    tx = np.stack(
        np.broadcast_arrays(0.0, np.asarray(tx_y_m, float), np.asarray(tx_z_m, float)), axis=-1
    )
    rx = np.stack(
        np.broadcast_arrays(0.0, np.asarray(rx_y_m, float), np.asarray(rx_z_m, float)), axis=-1
    )
    fe_rx = np.atleast_2d(np.asarray(fe_rx_m, dtype=float))
    fe_tx = np.atleast_2d(np.asarray(fe_tx_m, dtype=float))
    d_up = np.linalg.norm(fe_rx[:, None, :] - tx[None, :, :], axis=-1)
    d_down = np.linalg.norm(fe_tx[:, None, :] - rx[None, :, :], axis=-1)
    return d_up, d_down


def _echo_phasors(
    tx_y_m: ArrayLike,
    tx_z_m: ArrayLike,
    rx_y_m: ArrayLike,
    rx_z_m: ArrayLike,
    fe_az_deg: ArrayLike,
    fe_el_deg: ArrayLike,
    fe_distance_m: ArrayLike,
    chirp: FmcwChirp,
    amplitude: ArrayLike,
    tau_s: ArrayLike,
    phase_rad: ArrayLike,
    doppler_hz: ArrayLike,
    fe_rx_offset_m: ArrayLike,
    fe_tx_offset_m: ArrayLike,
    sample_index: ArrayLike,
    loop_index: ArrayLike,
    delay_model: str,
    if_hz: float,
    spreading_loss: bool,
    doppler_removed_time_s: NDArray[np.float64] | None = None,
) -> NDArray[np.complex128]:
    """Per-echo beat phasors, shape ``(E, L, V, N)``; see :func:`beat_phasors`."""
    if delay_model not in ("if", "rf"):
        raise ValueError(f"delay_model must be 'if' or 'rf', not {delay_model!r}")
    az, el, dist, amp, tau, phi, fd = (
        np.atleast_1d(a).astype(float)
        for a in np.broadcast_arrays(
            fe_az_deg, fe_el_deg, fe_distance_m, amplitude, tau_s, phase_rad, doppler_hz
        )
    )
    fe_rx, fe_tx = fe_antenna_positions(az, el, dist, fe_rx_offset_m, fe_tx_offset_m)
    d_up, d_down = path_lengths(tx_y_m, tx_z_m, rx_y_m, rx_z_m, fe_rx, fe_tx)  # (E,T), (E,R)
    n_e, n_tx = d_up.shape
    n_rx = d_down.shape[1]

    t_air = ((d_up[:, :, None] + d_down[:, None, :]) / C0_MPS).reshape(n_e, n_tx * n_rx)  # (E,V)
    t_down = np.broadcast_to(d_down[:, None, :] / C0_MPS, (n_e, n_tx, n_rx)).reshape(n_e, -1)
    t_total = t_air + tau[:, None]  # (E, V)
    f_x = if_hz if delay_model == "if" else chirp.fc_hz
    s = chirp.slope_hz_per_s

    n = np.atleast_1d(np.asarray(sample_index, dtype=float))
    t_f = chirp.fast_time_s(n)  # (N,)
    loops = np.atleast_1d(np.asarray(loop_index, dtype=float))
    slot_t = np.repeat(chirp.slots(n_tx), n_rx) * chirp.chirp_slot_s  # (V,)
    chirp_start = loops[:, None] * chirp.loop_time_s(n_tx) + slot_t[None, :]  # (L, V)

    # Range part, in cycles: -[fc T_air + f_x tau + S t_f T - S T^2 / 2]   -> (E, 1, V, N)
    carrier_cyc = chirp.fc_hz * t_air + f_x * tau[:, None]  # (E, V)
    range_cyc = -(
        carrier_cyc[:, :, None]
        + s * t_f[None, None, :] * t_total[:, :, None]
        - 0.5 * s * t_total[:, :, None] ** 2
    )
    # Doppler at the RTS output time t - T_down, t = chirp start + t_f   -> (E, L, V, N)
    t_abs = chirp_start[None, :, :, None] + t_f[None, None, None, :]
    dop_time = t_abs - t_down[:, None, :, None]
    if doppler_removed_time_s is not None:  # (E?, L, V) time whose Doppler phase is removed
        dop_time = dop_time - doppler_removed_time_s[..., None]
    dop_cyc = fd[:, None, None, None] * dop_time
    cycles = range_cyc[:, None, :, :] + dop_cyc
    cycles = cycles - np.round(cycles)  # keep precision in the exponent
    level = amp[:, None] * np.ones((1, n_tx * n_rx))
    if spreading_loss:
        up = dist[:, None] / d_up
        down = dist[:, None] / d_down
        level = level * (up[:, :, None] * down[:, None, :]).reshape(n_e, -1)
    gain = level * np.exp(1j * phi)[:, None]  # (E, V)
    return gain[:, None, :, None] * np.exp(2j * np.pi * cycles)


def beat_phasors(
    tx_y_m: ArrayLike,
    tx_z_m: ArrayLike,
    rx_y_m: ArrayLike,
    rx_z_m: ArrayLike,
    fe_az_deg: ArrayLike,
    fe_el_deg: ArrayLike,
    fe_distance_m: ArrayLike,
    *,
    chirp: FmcwChirp,
    amplitude: ArrayLike = 1.0,
    tau_s: ArrayLike = 0.0,
    phase_rad: ArrayLike = 0.0,
    doppler_hz: ArrayLike = 0.0,
    fe_rx_offset_m: ArrayLike = (0.0, 0.0),
    fe_tx_offset_m: ArrayLike = (0.0, 0.0),
    sample_index: ArrayLike | None = None,
    loop_index: ArrayLike = (0,),
    delay_model: str = "if",
    if_hz: float = 500e6,
    spreading_loss: bool = True,
    sum_echoes: bool = True,
) -> NDArray[np.complex128]:
    """Complex beat-signal samples of FMCW echoes on every virtual channel.

    Echo ``e`` comes from one FE (nominal direction, distance, antenna offsets) with RTS
    amplitude, delay, phase and Doppler shift; see the module docstring for the derivation:
    ``x = A_ev exp(j psi)``, ``psi = -2 pi [fc T_air + f_x tau + S t_f T - S T^2 / 2]
    + 2 pi fd (t - T_down) + phi``.

    Parameters
    ----------
    tx_y_m, tx_z_m, rx_y_m, rx_z_m : array_like
        Radar antenna positions in the face plane, relative to the reference point.
    fe_az_deg, fe_el_deg, fe_distance_m : array_like
        FE nominal direction and distance per echo (broadcast to ``(E,)``).
    chirp : FmcwChirp
        Chirp and TDM timing.
    amplitude, tau_s, phase_rad, doppler_hz : array_like, optional
        RTS settings per echo (broadcast to ``(E,)``).
    fe_rx_offset_m, fe_tx_offset_m : array_like, optional
        FE antenna offsets ``[dy, dz]``, shape ``(2,)`` or ``(E, 2)``.
    sample_index : array_like, optional
        Fast-time sample indices (may be fractional); default ``0 .. n_samples - 1``.
    loop_index : array_like, optional
        Loop (slow-time) indices.
    delay_model : {"if", "rf"}, optional
        ``"if"``: digital RTS delaying at the IF (the delay's carrier phase is
        ``-2 pi if_hz tau``); ``"rf"``: RF delay line (``-2 pi fc tau``).
    if_hz : float, optional
        RTS intermediate frequency at the chirp's start frequency (LO = ``fc - if_hz``).
    spreading_loss : bool, optional
        Apply ``(D / d_up) (D / d_down)`` per channel.
    sum_echoes : bool, optional
        Sum over echoes (default) or keep the echo axis.

    Returns
    -------
    ndarray
        Complex, shape ``(L, V, N)`` or ``(E, L, V, N)`` with ``V = n_tx * n_rx`` in TX-major
        order.
    """
    if sample_index is None:
        sample_index = np.arange(chirp.n_samples)
    x = _echo_phasors(
        tx_y_m, tx_z_m, rx_y_m, rx_z_m, fe_az_deg, fe_el_deg, fe_distance_m, chirp, amplitude,
        tau_s, phase_rad, doppler_hz, fe_rx_offset_m, fe_tx_offset_m, sample_index, loop_index,
        delay_model, if_hz, spreading_loss,
    )
    return x.sum(axis=0) if sum_echoes else x


def array_snapshot(
    tx_y_m: ArrayLike,
    tx_z_m: ArrayLike,
    rx_y_m: ArrayLike,
    rx_z_m: ArrayLike,
    fe_az_deg: ArrayLike,
    fe_el_deg: ArrayLike,
    fe_distance_m: ArrayLike,
    *,
    chirp: FmcwChirp,
    amplitude: ArrayLike = 1.0,
    tau_s: ArrayLike = 0.0,
    phase_rad: ArrayLike = 0.0,
    doppler_hz: ArrayLike = 0.0,
    fe_rx_offset_m: ArrayLike = (0.0, 0.0),
    fe_tx_offset_m: ArrayLike = (0.0, 0.0),
    reference_sample: float | None = None,
    reference_loop: int = 0,
    compensate_tdm_doppler: bool = True,
    delay_model: str = "if",
    if_hz: float = 500e6,
    spreading_loss: bool = True,
) -> NDArray[np.complex128]:
    """Per-virtual-channel value at the range-Doppler peak of one echo set.

    The beat phasor of every echo at fast-time sample ``reference_sample`` (default: the centre
    of the sampled sweep, ``(N - 1) / 2``, which is what a symmetric-window range FFT peak
    refers to) of loop ``reference_loop``, times ``exp(-j 2 pi fd (l_ref T_loop + t_f,ref))``
    (channel-common Doppler phase) and, if ``compensate_tdm_doppler``, times
    ``exp(-j 2 pi fd slot(t) T_slot)`` (per-TX TDM Doppler phase, which a TDM-MIMO radar
    compensates), summed over echoes. The carrier/delay phase is kept, common part included;
    see the module docstring for exactly what remains.

    Parameters
    ----------
    tx_y_m, tx_z_m, rx_y_m, rx_z_m, fe_az_deg, fe_el_deg, fe_distance_m, chirp, amplitude, \
tau_s, phase_rad, doppler_hz, fe_rx_offset_m, fe_tx_offset_m, delay_model, if_hz, \
spreading_loss
        As in :func:`beat_phasors`.
    reference_sample : float, optional
        Fast-time sample (may be fractional) the snapshot refers to.
    reference_loop : int, optional
        Loop index the snapshot refers to.
    compensate_tdm_doppler : bool, optional
        Remove the per-TX Doppler phase of the TDM slot offsets.

    Returns
    -------
    ndarray
        Complex, shape ``(n_tx * n_rx,)``, TX-major.
    """
    if reference_sample is None:
        reference_sample = chirp.centre_sample
    n_tx = np.asarray(tx_y_m).size
    n_rx = np.asarray(rx_y_m).size
    slot_t = np.repeat(chirp.slots(n_tx), n_rx) * chirp.chirp_slot_s
    removed = reference_loop * chirp.loop_time_s(n_tx) + float(
        chirp.fast_time_s(reference_sample)
    ) + (slot_t if compensate_tdm_doppler else np.zeros_like(slot_t))
    x = _echo_phasors(
        tx_y_m, tx_z_m, rx_y_m, rx_z_m, fe_az_deg, fe_el_deg, fe_distance_m, chirp, amplitude,
        tau_s, phase_rad, doppler_hz, fe_rx_offset_m, fe_tx_offset_m, [reference_sample],
        [reference_loop], delay_model, if_hz, spreading_loss,
        doppler_removed_time_s=removed[None, None, :],
    )
    return x[:, 0, :, 0].sum(axis=0)


def _uv_from_angles(az_deg: ArrayLike, el_deg: ArrayLike) -> tuple[NDArray, NDArray]:
    az = np.deg2rad(np.asarray(az_deg, dtype=float))
    el = np.deg2rad(np.asarray(el_deg, dtype=float))
    return np.cos(el) * np.sin(az), np.sin(el)


def _angles_from_uv(u: float, s: float) -> tuple[float, float]:
    c = np.sqrt(max(0.0, 1.0 - u * u - s * s))
    return float(np.rad2deg(np.arctan2(u, c))), float(np.rad2deg(np.arcsin(np.clip(s, -1, 1))))


def bartlett_spectrum(
    snapshot: ArrayLike,
    virtual_y_m: ArrayLike,
    virtual_z_m: ArrayLike,
    wavelength_m: float,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
) -> NDArray[np.float64]:
    """Conventional beamformer output ``|sum_v conj(a_v(az, el)) x_v|``.

    Parameters
    ----------
    snapshot : array_like
        Complex per-virtual-channel values, shape ``(V,)``.
    virtual_y_m, virtual_z_m : array_like
        Virtual element positions, shape ``(V,)``.
    wavelength_m : float
        Steering wavelength.
    az_deg, el_deg : array_like
        Look directions (broadcast together).

    Returns
    -------
    ndarray
        ``|B|`` with the broadcast shape of the look directions.
    """
    x = np.asarray(snapshot, dtype=complex)
    y = np.asarray(virtual_y_m, dtype=float)
    z = np.asarray(virtual_z_m, dtype=float)
    u, s = _uv_from_angles(*np.broadcast_arrays(az_deg, el_deg))
    k = 2.0 * np.pi / wavelength_m
    phase = k * (u[..., None] * y + s[..., None] * z)
    return np.abs(np.exp(-1j * phase) @ x)


def bartlett_direction(
    snapshot: ArrayLike,
    virtual_y_m: ArrayLike,
    virtual_z_m: ArrayLike,
    wavelength_m: float,
    *,
    az_range_deg: tuple[float, float] = (-70.0, 70.0),
    el_range_deg: tuple[float, float] = (-40.0, 40.0),
    grid_step_deg: float = 0.5,
) -> tuple[float, float]:
    """Direction where the plane-wave Bartlett beamformer peaks.

    ``a_v = exp(j 2 pi / lambda (y_v cos el sin az + z_v sin el))``; the global maximum of
    ``|a^H x|`` over a grid in (az, el) is refined by a trust-region Newton search with exact
    gradient and Hessian in direction cosines ``(u, s) = (cos el sin az, sin el)`` (the
    beamformer is a sum of exponentials there), converged far below 1e-5 deg.

    Parameters
    ----------
    snapshot : array_like
        Complex per-virtual-channel values, shape ``(V,)``.
    virtual_y_m, virtual_z_m : array_like
        Virtual element positions, shape ``(V,)``.
    wavelength_m : float
        Steering wavelength.
    az_range_deg, el_range_deg : tuple of float, optional
        Field of view of the grid search.
    grid_step_deg : float, optional
        Grid step of the coarse search.

    Returns
    -------
    az_deg, el_deg : float
        Direction of the peak.
    """
    x = np.asarray(snapshot, dtype=complex)
    x = x / np.sum(np.abs(x))
    y = np.asarray(virtual_y_m, dtype=float)
    z = np.asarray(virtual_z_m, dtype=float)
    k = 2.0 * np.pi / wavelength_m
    az_g = np.arange(az_range_deg[0], az_range_deg[1] + 0.5 * grid_step_deg, grid_step_deg)
    el_g = np.arange(el_range_deg[0], el_range_deg[1] + 0.5 * grid_step_deg, grid_step_deg)
    aa, ee = np.meshgrid(az_g, el_g, indexing="ij")
    spec = bartlett_spectrum(x, y, z, wavelength_m, aa, ee)
    i = np.unravel_index(np.argmax(spec), spec.shape)
    u0, s0 = _uv_from_angles(aa[i], ee[i])
    ky, kz = k * y, k * z

    def terms(p: NDArray[np.float64]) -> tuple[complex, NDArray, NDArray]:
        e = x * np.exp(-1j * (ky * p[0] + kz * p[1]))
        b = e.sum()
        d = np.array([(-1j * ky * e).sum(), (-1j * kz * e).sum()])
        h = np.array(
            [
                [(-(ky**2) * e).sum(), (-(ky * kz) * e).sum()],
                [(-(ky * kz) * e).sum(), (-(kz**2) * e).sum()],
            ]
        )
        return b, d, h

    def fun(p: NDArray[np.float64]) -> float:
        return -float(abs(terms(p)[0]) ** 2)

    def jac(p: NDArray[np.float64]) -> NDArray[np.float64]:
        b, d, _ = terms(p)
        return -2.0 * np.real(np.conj(b) * d)

    def hess(p: NDArray[np.float64]) -> NDArray[np.float64]:
        b, d, h = terms(p)
        return -2.0 * np.real(np.conj(d)[:, None] * d[None, :] + np.conj(b) * h)

    res = minimize(
        fun, np.array([u0, s0]), jac=jac, hess=hess, method="trust-exact",
        options={"gtol": 1e-13, "maxiter": 200},
    )
    p = res.x
    for _ in range(3):  # polish with plain Newton steps (quadratic convergence at the peak)
        step = np.linalg.solve(hess(p), -jac(p))
        if not np.all(np.isfinite(step)) or np.max(np.abs(step)) > 1e-3:
            break
        p = p + step
    return _angles_from_uv(float(p[0]), float(p[1]))


def seen_direction_of_fe(
    fe_az_deg: float,
    fe_el_deg: float,
    fe_distance_m: float,
    tx_y_m: ArrayLike,
    tx_z_m: ArrayLike,
    rx_y_m: ArrayLike,
    rx_z_m: ArrayLike,
    *,
    chirp: FmcwChirp,
    fe_rx_offset_m: ArrayLike = (0.0, 0.0),
    fe_tx_offset_m: ArrayLike = (0.0, 0.0),
    tau_s: float = 0.0,
    delay_model: str = "if",
    if_hz: float = 500e6,
    spreading_loss: bool = True,
    wavelength_m: float | None = None,
    **bartlett_kwargs: object,
) -> tuple[float, float]:
    """Where the radar's Bartlett beamformer sees one FE alone at full amplitude.

    Parameters
    ----------
    fe_az_deg, fe_el_deg, fe_distance_m : float
        FE nominal direction and distance.
    tx_y_m, tx_z_m, rx_y_m, rx_z_m : array_like
        Radar antenna positions.
    chirp : FmcwChirp
        Chirp profile.
    fe_rx_offset_m, fe_tx_offset_m : array_like, optional
        FE antenna offsets ``[dy, dz]``.
    tau_s : float, optional
        RTS delay.
    delay_model, if_hz, spreading_loss
        As in :func:`beat_phasors`.
    wavelength_m : float, optional
        Steering wavelength; default ``chirp.steering_wavelength_m`` (centre of the sampled
        sweep, what a well-designed radar uses).
    **bartlett_kwargs
        Passed to :func:`bartlett_direction`.

    Returns
    -------
    az_deg, el_deg : float
        The near-field (seen) direction.
    """
    x = array_snapshot(
        tx_y_m, tx_z_m, rx_y_m, rx_z_m, fe_az_deg, fe_el_deg, fe_distance_m, chirp=chirp,
        tau_s=tau_s, fe_rx_offset_m=fe_rx_offset_m, fe_tx_offset_m=fe_tx_offset_m,
        delay_model=delay_model, if_hz=if_hz, spreading_loss=spreading_loss,
    )
    vy, vz = virtual_positions(tx_y_m, tx_z_m, rx_y_m, rx_z_m)
    lam = chirp.steering_wavelength_m if wavelength_m is None else wavelength_m
    return bartlett_direction(x, vy, vz, lam, **bartlett_kwargs)  # type: ignore[arg-type]
