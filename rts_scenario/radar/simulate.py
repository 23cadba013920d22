"""The simulated radar under test: FMCW TDM-MIMO, fed by exactly what the RTS emits.

Each scheduled channel echo reaches the radar as a point echo from its FE's physical direction
and distance, with the scheduled delay, level, Doppler and phase (plus any injected channel
errors). Beat signal of echo e on virtual element v (TX t fired in slot i_t of each loop), loop
l, sample n::

    x = A_e exp(j [2 pi (f0 tau_e + S tau_e n / fs) + phi_e
                   + 2 pi fD_e (l T_loop + i_t T_slot) + k (y_v u_e + z_v s_e)])

Fidelity ``adc`` builds that cube (one matrix product over the echoes) and processes it like a
real radar: Hann-windowed range FFT, Doppler FFT, non-coherent sum over channels, CA- or
OS-CFAR, local-maximum peak grouping, sub-bin interpolation, TDM-Doppler compensation and angle
estimation. Fidelity ``analytic`` evaluates the same superposition at each target's
range-Doppler cell without the cube (and draws the noise from the SNR); ``auto`` uses the cube
only for frames where targets share a range-Doppler neighbourhood.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from ..arrays import direction_cosines
from ..constants import C0_MPS
from ..errors import RtsError
from ..rig import Rig
from ..schedule import Schedule
from .angle import ESTIMATORS, make_estimator
from .profile import RadarProfile

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

FIDELITIES = ("auto", "adc", "analytic")
CFARS = ("ca", "os")


@dataclass(frozen=True)
class ChannelErrors:
    """Physical deviations of each RTS channel (per rig FE) that calibration must cancel.

    ``gain_db`` > 0 makes a channel stronger, ``phase_deg`` and ``delay_s`` add to its echo,
    ``az_deg``/``el_deg``/``distance_m`` move its FE away from where the rig file says.
    """

    gain_db: FloatArray
    phase_deg: FloatArray
    delay_s: FloatArray
    az_deg: FloatArray
    el_deg: FloatArray
    distance_m: FloatArray

    @classmethod
    def none(cls, n_fe: int) -> ChannelErrors:
        """No errors for ``n_fe`` channels."""
        zero = np.zeros(n_fe)
        return cls(zero, zero, zero, zero, zero, zero)

    @classmethod
    def random(cls, n_fe: int, rng: np.random.Generator, *, phase_deg: float = 180.0,
               gain_db: float = 1.0, delay_s: float = 0.0, position_deg: float = 0.0
               ) -> ChannelErrors:
        """Uniform errors within +-the given spans (seeded)."""
        def span(x: float) -> FloatArray:
            return rng.uniform(-x, x, n_fe) if x else np.zeros(n_fe)

        return cls(gain_db=span(gain_db), phase_deg=span(phase_deg), delay_s=span(delay_s),
                   az_deg=span(position_deg), el_deg=span(position_deg),
                   distance_m=np.zeros(n_fe))


@dataclass(frozen=True)
class Echoes:
    """The echoes of one frame as the radar receives them, shape (E,) each."""

    target: NDArray[np.int64]
    amplitude: FloatArray
    delay_s: FloatArray
    doppler_hz: FloatArray
    phase_rad: FloatArray
    u: FloatArray
    s: FloatArray


@dataclass(frozen=True)
class Detections:
    """One frame of radar output, shape (D,) each."""

    frame: int
    t_s: float
    range_m: FloatArray
    radial_velocity_mps: FloatArray
    az_deg: FloatArray
    el_deg: FloatArray
    snr_db: FloatArray
    rcs_dbsm: FloatArray

    @property
    def count(self) -> int:
        """Number of detections."""
        return int(self.range_m.size)


@dataclass
class SimulatedRadar:
    """A radar under test in software: feed it schedules, get detections.

    Parameters
    ----------
    profile : RadarProfile
        Chirp, timing, noise level and array.
    rig : Rig
        The RTS rig (true FE positions; its reference calibrates the RCS estimate).
    fidelity : {"auto", "adc", "analytic"}
    estimator : {"bartlett", "ti"}
    cfar : {"ca", "os"}
    noise : bool
        Thermal noise at the profile's level.
    errors : ChannelErrors, optional
        Injected channel errors (default none).
    rng : numpy.random.Generator, optional
        Noise source (seeded for repeatable runs).
    threshold_db : float
        CFAR threshold over the noise estimate (also the analytic detection threshold).
    """

    profile: RadarProfile
    rig: Rig
    fidelity: str = "auto"
    estimator: str = "bartlett"
    cfar: str = "ca"
    noise: bool = True
    errors: ChannelErrors | None = None
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    threshold_db: float = 13.0
    frames_adc: int = 0
    frames_analytic: int = 0

    def __post_init__(self) -> None:
        for name, value, valid in (("fidelity", self.fidelity, FIDELITIES),
                                   ("estimator", self.estimator, ESTIMATORS),
                                   ("cfar", self.cfar, CFARS)):
            if value not in valid:
                raise RtsError(f"simulated radar: unknown {name} {value!r}; valid: "
                               f"{', '.join(valid)}")
        p = self.profile
        if self.errors is None:
            self.errors = ChannelErrors.none(self.rig.n_front_ends)
        self._angles = make_estimator(self.estimator, p.array)
        self._n, self._loops = p.adc_samples, p.chirp_loops
        self._range_bin_m = C0_MPS * p.sample_rate_hz / (2.0 * p.slope_hz_per_s * self._n)
        self._win_r = np.hanning(self._n + 2)[1:-1]
        self._win_d = np.hanning(self._loops + 2)[1:-1]
        # Amplitude of a unit tone after both windowed FFTs, and the noise power there.
        self._gain = self._win_r.sum() * self._win_d.sum()
        self._noise_gain = (self._win_r**2).sum() * (self._win_d**2).sum()
        self._sigma = 10.0 ** (p.noise_level_db / 20.0) if self.noise else 0.0
        slot_of_tx = {t: i for i, t in enumerate(p.tx_order)}
        self._slot = np.array([slot_of_tx[t] for t in p.tx_index], dtype=float)
        ref = self.rig.reference
        self._rcs_offset = ref.attenuation_db + ref.rcs_dbsm - 40.0 * np.log10(ref.range_m)

    # -- from schedule to echoes ---------------------------------------------------------------

    def echoes(self, schedule: Schedule, pos: int) -> Echoes:
        """Return the echoes the radar receives in frame ``pos`` of ``schedule``."""
        assert self.errors is not None
        err, rig, p = self.errors, self.rig, self.profile
        k, c = np.nonzero(schedule.active[pos])
        fe = schedule.fe[pos, k, c]
        az = np.radians(rig.az_deg[fe] + err.az_deg[fe])
        el = np.radians(rig.el_deg[fe] + err.el_deg[fe])
        u, s = direction_cosines(az, el)
        distance = rig.distance_m[fe] + err.distance_m[fe]
        delay = (2.0 * distance / C0_MPS + rig.limits.latency_s + schedule.delay_s[pos, k, c]
                 + err.delay_s[fe])
        start_hz = p.fc_hz
        phase = (schedule.phase_rad[pos, k, c] + np.radians(err.phase_deg[fe])
                 + 2.0 * np.pi * start_hz * delay)
        amplitude = 10.0 ** (-(schedule.attenuation_db[pos, k, c] - err.gain_db[fe]) / 20.0)
        return Echoes(target=k, amplitude=amplitude, delay_s=delay,
                      doppler_hz=schedule.doppler_hz[pos, k, c], phase_rad=phase, u=u, s=s)

    # -- the radar -----------------------------------------------------------------------------

    def process(self, schedule: Schedule) -> list[Detections]:
        """Return the detections of every frame of ``schedule``."""
        return [self.detect(schedule, pos) for pos in range(schedule.n_frames)]

    def detect(self, schedule: Schedule, pos: int) -> Detections:
        """Return the detections of frame ``pos``, with the fidelity the frame needs."""
        echoes = self.echoes(schedule, pos)
        use_adc = self.fidelity == "adc" or (self.fidelity == "auto" and self._crowded(echoes))
        frame, t_s = int(schedule.frame_index[pos]), float(schedule.t_s[pos])
        if use_adc:
            self.frames_adc += 1
            return self._detect_adc(echoes, frame, t_s)
        self.frames_analytic += 1
        return self._detect_analytic(echoes, frame, t_s)

    def _bins(self, echoes: Echoes) -> tuple[FloatArray, FloatArray]:
        """Fractional range and (centred) Doppler bins of each echo."""
        p = self.profile
        range_bin = p.slope_hz_per_s * echoes.delay_s / p.sample_rate_hz * self._n
        doppler_bin = echoes.doppler_hz * p.loop_time_s * self._loops
        return range_bin, doppler_bin

    def _crowded(self, echoes: Echoes) -> bool:
        """Whether two targets share a range-Doppler neighbourhood (needs the real cube)."""
        if echoes.target.size == 0:
            return False
        rb, db = self._bins(echoes)
        targets, first = np.unique(echoes.target, return_index=True)
        if targets.size < 2:
            return False
        r, d = rb[first], db[first]
        near = (np.abs(r[:, None] - r[None]) < 2.5) & (
            np.abs(np.mod(d[:, None] - d[None] + self._loops / 2, self._loops) - self._loops / 2)
            < 2.5)
        return bool(np.triu(near, 1).any())

    def cube(self, echoes: Echoes) -> ComplexArray:
        """Beat-signal cube ``[loop, virtual element, sample]`` of the echoes plus noise."""
        p = self.profile
        n = np.arange(self._n)
        loops = np.arange(self._loops)
        arr = p.array
        k = arr.wavenumber_rad_per_m
        fast = np.exp(2j * np.pi * np.outer(p.slope_hz_per_s * echoes.delay_s / p.sample_rate_hz,
                                            n))  # (E, N)
        slow = np.exp(2j * np.pi * np.outer(loops * p.loop_time_s, echoes.doppler_hz))  # (L, E)
        chan = (echoes.amplitude * np.exp(1j * echoes.phase_rad))[None, :] * np.exp(1j * (
            k * (np.outer(arr.y_m, echoes.u) + np.outer(arr.z_m, echoes.s))
            + 2.0 * np.pi * np.outer(self._slot * p.chirp_slot_s, echoes.doppler_hz)))  # (M, E)
        lm = (slow[:, None, :] * chan[None, :, :]).reshape(-1, echoes.amplitude.size)
        cube = (lm @ fast).reshape(self._loops, arr.n_elements, self._n)
        if self._sigma > 0.0:
            noise = self.rng.standard_normal((2, *cube.shape)) * (self._sigma / np.sqrt(2.0))
            cube = cube + noise[0] + 1j * noise[1]
        return cube

    def _detect_adc(self, echoes: Echoes, frame: int, t_s: float) -> Detections:
        p = self.profile
        cube = self.cube(echoes)
        spec = np.fft.fft(cube * self._win_r, axis=2)
        spec = np.fft.fftshift(np.fft.fft(spec * self._win_d[:, None, None], axis=0), axes=0)
        power = (np.abs(spec) ** 2).sum(axis=1)  # (L, N): non-coherent over channels
        noise = self._noise_floor(power)
        hits = (power > noise * 10.0 ** (self.threshold_db / 10.0)) & (
            power == ndimage.maximum_filter(power, size=3, mode=("wrap", "nearest")))
        d_idx, r_idx = np.nonzero(hits)
        if d_idx.size == 0:
            return _empty(frame, t_s)
        # Sub-bin positions: parabola through the log power of the neighbours.
        def vertex(lo: FloatArray, mid: FloatArray, hi: FloatArray) -> FloatArray:
            lo, mid, hi = np.log(lo), np.log(mid), np.log(hi)
            den = lo - 2 * mid + hi
            return np.where(den < 0, 0.5 * (lo - hi) / np.where(den < 0, den, 1.0), 0.0)

        r_lo = power[d_idx, np.maximum(r_idx - 1, 0)]
        r_hi = power[d_idx, np.minimum(r_idx + 1, self._n - 1)]
        d_lo = power[(d_idx - 1) % self._loops, r_idx]
        d_hi = power[(d_idx + 1) % self._loops, r_idx]
        mid = power[d_idx, r_idx]
        r_frac = r_idx + vertex(r_lo, mid, r_hi)
        d_frac = d_idx - self._loops // 2 + vertex(d_lo, mid, d_hi)
        doppler = d_frac / (self._loops * p.loop_time_s)
        snap = spec[d_idx, :, r_idx]  # (D, M)
        return self._finish(snap, r_frac * self._range_bin_m, doppler,
                            10.0 * np.log10(mid / noise[d_idx, r_idx]), frame, t_s)

    def _noise_floor(self, power: FloatArray) -> FloatArray:
        """CFAR noise estimate per cell from its training cells (guard cells excluded)."""
        guard, train = 2, 8
        half = guard + train
        footprint = np.ones((2 * half + 1, 2 * half + 1), dtype=bool)
        footprint[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
        # Doppler wraps around; range does not (mirror at its ends).
        padded = np.pad(np.pad(power, ((half, half), (0, 0)), mode="wrap"),
                        ((0, 0), (half, half)), mode="reflect")
        if self.cfar == "ca":
            total = ndimage.correlate(padded, footprint.astype(float), mode="constant")
            floor = total[half:-half, half:-half] / footprint.sum()
        else:  # ordered statistic: the 3/4 quantile of the training cells
            floor = ndimage.rank_filter(padded, rank=int(0.75 * footprint.sum()),
                                        footprint=footprint, mode="constant")[half:-half,
                                                                              half:-half]
        # Without noise the floor is the echoes' sidelobes: keep it above numerical zero.
        return np.maximum(floor, power.max(initial=0.0) * 1e-12 + 1e-300)

    def _detect_analytic(self, echoes: Echoes, frame: int, t_s: float) -> Detections:
        if echoes.target.size == 0:
            return _empty(frame, t_s)
        p = self.profile
        arr = p.array
        k = arr.wavenumber_rad_per_m
        targets, inverse = np.unique(echoes.target, return_inverse=True)
        # The snapshot at a target's peak cell: each echo's windowed FFT peak, phased by its
        # direction and TDM slot (echoes of one target share delay and Doppler, so the rest of
        # the phase is common to them and does not move the angle).
        level = echoes.amplitude * self._gain * np.exp(1j * echoes.phase_rad)
        contrib = level[:, None] * np.exp(1j * (
            k * (np.outer(echoes.u, arr.y_m) + np.outer(echoes.s, arr.z_m))
            + 2.0 * np.pi * np.outer(echoes.doppler_hz, self._slot * p.chirp_slot_s)))
        snap = np.zeros((targets.size, arr.n_elements), dtype=complex)
        np.add.at(snap, inverse, contrib)
        rb, db = self._bins(echoes)
        first = np.unique(echoes.target, return_index=True)[1]
        noise_power = self._sigma**2 * self._noise_gain  # per channel, after both FFTs
        signal = (np.abs(snap) ** 2).sum(axis=1)
        floor = max(noise_power * arr.n_elements, signal.max() * 1e-12)
        snr = signal / floor
        range_m = rb[first] * self._range_bin_m
        doppler = echoes.doppler_hz[first]
        if self._sigma > 0.0:
            noise = self.rng.standard_normal((2, *snap.shape)) * np.sqrt(noise_power / 2.0)
            snap = snap + noise[0] + 1j * noise[1]
            # Sub-bin estimates scatter like the interpolated FFT peak: ~1 / (pi sqrt(2 SNR)).
            spread = 1.0 / (np.pi * np.sqrt(2.0 * snr))
            range_m = range_m + self.rng.standard_normal(snr.size) * spread * self._range_bin_m
            doppler = doppler + self.rng.standard_normal(snr.size) * spread / (
                self._loops * p.loop_time_s)
            signal = (np.abs(snap) ** 2).sum(axis=1)
            snr = signal / (noise_power * arr.n_elements)
        seen = snr > 10.0 ** (self.threshold_db / 10.0)
        return self._finish(snap[seen], range_m[seen], doppler[seen],
                            10.0 * np.log10(snr[seen]), frame, t_s)

    def _finish(self, snap: ComplexArray, range_m: FloatArray, doppler_hz: FloatArray,
                snr_db: FloatArray, frame: int, t_s: float) -> Detections:
        """TDM-Doppler compensation, angles, velocity and RCS of the detections."""
        p = self.profile
        comp = np.exp(-2j * np.pi * np.outer(doppler_hz, self._slot * p.chirp_slot_s))
        snap = snap * comp
        est = self._angles(snap)
        src = est.source
        # Level: the full array's beam towards the estimated angle, whatever the estimator.
        arr = p.array
        u, s = direction_cosines(np.radians(est.az_deg), np.radians(est.el_deg))
        steer = np.exp(1j * arr.wavenumber_rad_per_m * (np.outer(u, arr.y_m)
                                                        + np.outer(s, arr.z_m)))
        beam = np.abs(np.einsum("dm,dm->d", snap[src], steer.conj()))
        amplitude = beam / (self._gain * arr.n_elements)
        with np.errstate(divide="ignore"):
            rcs = (20.0 * np.log10(amplitude) + 40.0 * np.log10(range_m[src])
                   + self._rcs_offset)
        return Detections(frame=frame, t_s=t_s, range_m=range_m[src],
                          radial_velocity_mps=-doppler_hz[src] * p.wavelength_m / 2.0,
                          az_deg=est.az_deg, el_deg=est.el_deg, snr_db=snr_db[src],
                          rcs_dbsm=rcs)


def _empty(frame: int, t_s: float) -> Detections:
    e = np.zeros(0)
    return Detections(frame, t_s, e, e, e, e, e, e)
