"""The simulated radar under test: FMCW TDM-MIMO, fed by exactly what the RTS emits.

The bench is modelled from its physics, independently of the solver's plane-wave picture
(DESIGN.md 5.5b, 5.6). Each scheduled channel echo travels radar TX element t -> its FE's
receive antenna -> RTS (delay tau, Doppler fD, level A, phase phi, plus any injected channel
errors) -> the FE's transmit antenna -> radar RX element r along straight spherical paths
(``d_up``, ``d_down``), with free-space amplitude loss per leg normalised to the FE's nominal
distance D: ``A (D / d_up) (D / d_down)``. The radar's antennas are the profile's physical ones
(`rts_scenario.arrays.Antennas`, relative to its reference point); an FE sits at its rig
direction and distance from that point (moved by any injected position error), its antennas
offset from there by the rig's ``rx_offset_m``/``tx_offset_m``. With
``T_air = (d_up + d_down) / c0`` and ``T = T_air + tau``, the radar mixes the received signal
with the conjugate of its own chirp (start frequency f0, slope S) and samples, for virtual
element v (TX t fired in slot i_t of each loop), loop l, fast time ``t_f = t_adc + n / fs``::

    x = A_v exp(j [phi - 2 pi (f0 T_air + f_x tau + S t_f T - S T^2 / 2)
                   + 2 pi fD (l T_loop + i_t T_slot + t_f - d_down / c0)])

``f_x`` is the frequency the RTS delays at: its IF for a digital RTS (the carrier phase comes
from the air paths alone), ``f0`` for an RF delay line (`rts_scenario.rig.RtsDelayModel`). The
phase is exact at each sample's true frequency: range-Doppler coupling (beat frequency
``-(S T - fD)``) and the wavelength of the sampled sweep come out by themselves (a profile with
``range_doppler_coupling: corrected`` takes the measured Doppler's share back out of each
range, as a radar correcting it does). The estimators
steer the profile's (centred) virtual array with the wavelength at the centre of the sampled
sweep, as a well-designed radar does; a plane wave from direction u then gives the steering
vector ``exp(+j k u.p_v)`` and a receding target a negative Doppler, the package's conventions.

Fidelity ``adc`` builds that cube (one matrix product over the echoes) and processes it like a
real radar: Hann-windowed range FFT, Doppler FFT, non-coherent sum over channels, CA- or
OS-CFAR, local-maximum peak grouping, sub-bin interpolation, TDM-Doppler compensation and angle
estimation (the range spectrum is read at ``S T - fD``, where a positive range lies).
Fidelity ``analytic`` evaluates the same superposition at each target's range-Doppler cell (the
beat phasors at the centre of the sampled sweep, which is what a symmetric window's FFT peak
gives) without the cube (and draws the noise from the SNR), detecting on the peak cell's level
as the cube's CFAR does (a target between cells reaches it weakened by both windows' responses:
up to 2.9 dB, half a cell off in range and Doppler); ``auto`` uses the cube only for frames
where targets share a range-Doppler neighbourhood (within 2.5 bins), where the analytic model
cannot tell them apart: forced ``analytic`` reads them as if alone, and counts such frames
(``frames_crowded_analytic``: a run fails with ``crowded_in_analytic`` unless the scene
expects it). Every frame of a radar with an OS-CFAR goes through the cube (the analytic model
detects as a CA-CFAR does). The analytic CA-CFAR estimates what the cube's does: the thermal
noise plus the mean, over each target's training cells, of every target's window response
there (`_leakage`), so a strong target masks a weaker one near it and its own sidelobes bound
its SNR, as in ``adc`` (to a few tenths of a dB). What exists only in ``adc``: a strong
target's sidelobes within a weaker one's own cell (they matter where its main lobe does not
mask it first: across the range ends, where the FFT wraps and the CFAR mirrors its window), the
cell in which a target halfway between two cells peaks (the analytic model reads the one
``round`` gives, whose neighbours may differ), and false alarms. Force it when a test is about
them (at the default threshold thermal noise crosses the CFAR's with a chance of 6e-84 per
cell, `thermal_false_alarm_chance`: none in practice).

Both FFTs are circular, so in every fidelity range and velocity fold as a real radar's do: the
sampled beat frequency ``S T - fD`` aliases modulo the (complex) sample rate, so the range bin
``(S T - fD) N / fs`` wraps into [0, N) and the range into [0, ``c0 fs / (2 S)``); the Doppler
sampled once per TDM loop wraps into [-1 / (2 T_loop), 1 / (2 T_loop)), i.e. the Doppler bin
into [-L/2, L/2). The radar knows only the folded Doppler: its TDM-MIMO compensation uses it,
so a target folded by a number of loops that is not a multiple of the TX count keeps a
phase ramp over the TX slots and its angles come out wrong, as on the real radar.
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .. import workers
from ..arrays import direction_cosines
from ..detections import Detections
from ..errors import RtsError
from ..propagation import C0_MPS
from ..registry import Registry
from ..rig import Rig
from .angle import make_estimator
from .profile import RadarProfile, hann_dft_response

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


class PlayedFrames(Protocol):
    """What the radar sees of the RTS: the channel settings it played, frame by frame.

    `rts_scenario.schedule.Schedule` is one (its arrays are frames x targets x channels). The
    radar reads only these, never how they were computed: the honest bench shares no code with
    the solver.
    """

    @property
    def n_frames(self) -> int: ...  # noqa: D102
    @property
    def frame_index(self) -> NDArray[np.int64]: ...  # noqa: D102
    @property
    def t_s(self) -> FloatArray: ...  # noqa: D102
    @property
    def active(self) -> NDArray[np.bool_]: ...  # noqa: D102
    @property
    def fe(self) -> NDArray[np.int64]: ...  # noqa: D102
    @property
    def attenuation_db(self) -> FloatArray: ...  # noqa: D102
    @property
    def delay_s(self) -> FloatArray: ...  # noqa: D102
    @property
    def doppler_hz(self) -> FloatArray: ...  # noqa: D102
    @property
    def phase_rad(self) -> FloatArray: ...  # noqa: D102
    @property
    def status(self) -> NDArray[np.uint16]: ...  # noqa: D102

def cube_every_frame(radar: SimulatedRadar, echoes: Echoes, n_frames: int) -> NDArray[np.bool_]:
    """Fidelity ``adc``: every frame goes through the beat-signal cube."""
    return np.ones(n_frames, dtype=bool)


def cube_no_frame(radar: SimulatedRadar, echoes: Echoes, n_frames: int) -> NDArray[np.bool_]:
    """Fidelity ``analytic``: no frame needs the cube (an OS-CFAR's all go)."""
    return np.zeros(n_frames, dtype=bool)


def cube_crowded_frames(radar: SimulatedRadar, echoes: Echoes,
                        n_frames: int) -> NDArray[np.bool_]:
    """Fidelity ``auto``: the cube only where targets share a range-Doppler neighbourhood."""
    return radar.crowded(echoes, n_frames)


# A fidelity is the choice of the frames that go through the cube (the others are analytic).
FIDELITIES = Registry("fidelity", {
    "auto": "rts_scenario.radar.simulate:cube_crowded_frames",
    "adc": "rts_scenario.radar.simulate:cube_every_frame",
    "analytic": "rts_scenario.radar.simulate:cube_no_frame",
}, plural="fidelities")
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
    """Echoes as the radar receives them (``frame``: position in the batch).

    Per echo, shape (E,): ``frame``, ``target``, ``delay_s`` (air and RTS, mean over the virtual
    elements: what the range FFT sees) and ``doppler_hz``. Per echo and virtual element, shape
    (E, M): ``channel``, the complex beat amplitude without its fast- and slow-time ramps (level
    with spreading loss, RTS phase, carrier and delay phase, TDM-slot and output-time Doppler
    phase), and ``channel_delay_s``, the total delay T of that element's path.
    """

    frame: NDArray[np.int64]
    target: NDArray[np.int64]
    delay_s: FloatArray
    doppler_hz: FloatArray
    channel: ComplexArray
    channel_delay_s: FloatArray

    def select(self, pick: NDArray[np.bool_] | NDArray[np.int64]) -> Echoes:
        """Return the echoes at ``pick`` (mask or indices)."""
        return Echoes(**{f.name: getattr(self, f.name)[pick] for f in fields(self)})


# The CFAR's window about each range-Doppler cell: guard cells and training cells on each side.
CFAR_GUARD, CFAR_TRAIN = 2, 8
# What the radar detects above its CFAR's noise estimate (dB), by default.
THRESHOLD_DB = 13.0


def thermal_false_alarm_chance(profile: RadarProfile, threshold_db: float = THRESHOLD_DB
                               ) -> float:
    """Chance that thermal noise alone crosses the CA-CFAR's threshold in one cell of a frame.

    A cell's power summed over the ``M`` channels and the mean of its ``N`` training cells'
    (each such a sum) are, over noise alone, ``M`` and ``N M`` exponentials of one mean: the
    ratio of the first to the second follows Fisher's F with ``(2 M, 2 N M)`` degrees of
    freedom, and crosses the threshold with its tail's chance. The OS-CFAR's estimate (the
    training cells' 3/4 quantile) lies above their mean: it crosses less often.
    """
    from scipy.special import fdtrc  # scipy when needed: see `check._assign`

    m = profile.array.n_elements
    n = (2 * (CFAR_GUARD + CFAR_TRAIN) + 1) ** 2 - (2 * CFAR_GUARD + 1) ** 2
    return float(fdtrc(2.0 * m, 2.0 * n * m, 10.0 ** (threshold_db / 10.0)))


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
    threshold_db: float = THRESHOLD_DB
    frames_adc: int = 0
    frames_analytic: int = 0
    # Frames read by the analytic model although targets shared a neighbourhood in them.
    frames_crowded_analytic: int = 0

    def __post_init__(self) -> None:
        if self.cfar not in CFARS:
            raise RtsError(f"simulated radar: unknown cfar {self.cfar!r}; valid: "
                           f"{', '.join(CFARS)}")
        self._cube_frames = FIDELITIES.get(self.fidelity)
        p = self.profile
        if self.errors is None:
            self.errors = ChannelErrors.none(self.rig.n_front_ends)
        # The estimators steer the profile's virtual array at the sampled sweep's centre.
        self._steering_array = p.steering_array
        self._angles = make_estimator(self.estimator, self._steering_array)
        ant = p.antennas
        self._tx_m = np.column_stack([np.zeros(ant.n_tx), ant.tx_y_m, ant.tx_z_m])
        self._rx_m = np.column_stack([np.zeros(ant.n_rx), ant.rx_y_m, ant.rx_z_m])
        self._delayed_hz = self.rig.rts.delayed_frequency_hz(p.fc_hz)
        # Fast time of the centre of the sampled sweep (what the windowed FFT peak refers to).
        self._t_centre_s = p.adc_start_s + (p.adc_samples - 1) / (2.0 * p.sample_rate_hz)
        self._n, self._loops = p.adc_samples, p.chirp_loops
        self._range_bin_m = C0_MPS * p.sample_rate_hz / (2.0 * p.slope_hz_per_s * self._n)
        self._win_r = np.hanning(self._n + 2)[1:-1]
        self._win_d = np.hanning(self._loops + 2)[1:-1]
        # What the FFTs' inputs are weighted by: the range window times N (the inverse FFT
        # divides by it); the Doppler window times exp(2 pi j l c / L), c = L // 2, which
        # moves zero Doppler to the middle of the spectrum (an fftshift; (-1)^l for even L).
        self._fft_r = self._win_r * self._n
        loop = np.arange(self._loops)
        self._fft_d = self._win_d * (np.where(loop % 2 == 0, 1.0, -1.0)
                                     if self._loops % 2 == 0 else
                                     np.exp(2j * np.pi * loop * (self._loops // 2)
                                            / self._loops))
        # Amplitude of a unit tone after both windowed FFTs, and the noise power there.
        self._gain = self._win_r.sum() * self._win_d.sum()
        self._noise_gain = (self._win_r**2).sum() * (self._win_d**2).sum()
        self._sigma = 10.0 ** (p.noise_level_db / 20.0) if self.noise else 0.0
        self._noise_weight = (self._sigma / np.sqrt(2.0) * self._fft_d[:, None, None]
                              * self._fft_r[None, None, :])
        # The ADC cube's noise comes from its own stream (spawned from ``rng``), drawn ahead.
        self._noise = _NoiseAhead(self.rng)
        slot_of_tx = {t: i for i, t in enumerate(p.tx_order)}
        self._slot = np.array([slot_of_tx[t] for t in p.tx_index], dtype=float)
        ref = self.rig.reference
        self._rcs_offset = ref.attenuation_db + ref.rcs_dbsm - 40.0 * np.log10(ref.range_m)

    # -- from schedule to echoes ---------------------------------------------------------------

    def echoes(self, schedule: PlayedFrames, frames: slice | None = None) -> Echoes:
        """Return the echoes the radar receives in ``schedule`` (all frames, or a slice)."""
        assert self.errors is not None
        err = self.errors
        active = schedule.active if frames is None else schedule.active[frames]
        offset = 0 if frames is None else (frames.start or 0)
        f, k, c = np.nonzero(active)
        f = f + offset
        fe = schedule.fe[f, k, c]
        return self.propagate(
            fe, frame=f, target=k,
            # The attenuator sets the nearest of its steps, whatever it was sent.
            amplitude=10.0 ** (-(self.rig.limits.attenuator_setting(
                schedule.attenuation_db[f, k, c]) - err.gain_db[fe]) / 20.0),
            rts_delay_s=self.rig.limits.latency_s + schedule.delay_s[f, k, c] + err.delay_s[fe],
            doppler_hz=schedule.doppler_hz[f, k, c],
            # So does its phase shifter.
            phase_rad=self.rig.limits.phase_setting(schedule.phase_rad[f, k, c])
            + np.radians(err.phase_deg[fe]))

    def propagate(self, fe: NDArray[np.int64], *, frame: NDArray[np.int64],
                  target: NDArray[np.int64], amplitude: FloatArray, rts_delay_s: FloatArray,
                  doppler_hz: FloatArray, phase_rad: FloatArray) -> Echoes:
        """Echoes through FEs ``fe`` with these RTS settings (arrays of shape (E,))."""
        rig, p = self.rig, self.profile
        d_up, d_down = self._legs(fe)  # (E, T), (E, R)
        shape = (fe.size, p.array.n_elements)  # element t * n_rx + r: TX t, RX r
        t_air = ((d_up[:, :, None] + d_down[:, None, :]) / C0_MPS).reshape(shape)
        t_down = np.broadcast_to(d_down[:, None, :] / C0_MPS,
                                 (fe.size, d_up.shape[1], d_down.shape[1])).reshape(shape)
        nominal = rig.distance_m[fe][:, None]
        spread = ((nominal / d_up)[:, :, None] * (nominal / d_down)[:, None, :]).reshape(shape)
        total = t_air + rts_delay_s[:, None]
        slope = p.slope_hz_per_s
        # In cycles, each term reduced before it is summed (they reach 1e5 cycles).
        cycles = (_frac(-p.fc_hz * t_air) + _frac(-self._delayed_hz * rts_delay_s)[:, None]
                  + _frac(0.5 * slope * total**2)
                  + _frac(doppler_hz[:, None] * (self._slot[None, :] * p.chirp_slot_s - t_down)))
        channel = (amplitude[:, None] * spread) * np.exp(
            1j * (phase_rad[:, None] + 2.0 * np.pi * cycles))
        return Echoes(frame=frame, target=target, delay_s=total.mean(axis=1),
                      doppler_hz=doppler_hz, channel=channel, channel_delay_s=total)

    def _legs(self, fe: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
        """Spherical path lengths radar TX -> FE receive and FE transmit -> radar RX antenna."""
        assert self.errors is not None
        err, rig = self.errors, self.rig
        az = np.radians(rig.az_deg[fe] + err.az_deg[fe])
        el = np.radians(rig.el_deg[fe] + err.el_deg[fe])
        distance = rig.distance_m[fe] + err.distance_m[fe]
        centre = distance[:, None] * np.column_stack(
            [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        e_az = np.column_stack([-np.sin(az), np.cos(az), np.zeros_like(az)])
        e_el = np.column_stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)])

        def antenna(offset: FloatArray) -> FloatArray:
            return centre + offset[:, :1] * e_az + offset[:, 1:] * e_el

        fe_rx, fe_tx = antenna(rig.rx_offset_m[fe]), antenna(rig.tx_offset_m[fe])
        d_up = np.linalg.norm(fe_rx[:, None, :] - self._tx_m[None, :, :], axis=2)
        d_down = np.linalg.norm(fe_tx[:, None, :] - self._rx_m[None, :, :], axis=2)
        return d_up, d_down

    def fe_directions(self) -> tuple[FloatArray, FloatArray]:
        """Where this radar sees each FE of the rig alone (no noise, no RTS delay): az, el deg.

        The directions differ from the rig's nominal ones where the FEs are inside the radar's
        near field or their antennas are offset.
        """
        fe = np.arange(self.rig.n_front_ends)
        zero = np.zeros(fe.size)
        echoes = self.propagate(fe, frame=fe, target=zero.astype(np.int64),
                                amplitude=np.ones(fe.size), rts_delay_s=zero, doppler_hz=zero,
                                phase_rad=zero)
        est = self._angles(self._snapshot_at_peak(echoes))
        first = np.unique(est.source, return_index=True)[1]
        return est.az_deg[first], est.el_deg[first]

    def _snapshot_at_peak(self, echoes: Echoes) -> ComplexArray:
        """Each echo's value on every virtual element at its range-Doppler peak, (E, M).

        The beat phasor at the centre of the sampled sweep (a symmetric window's FFT peak refers
        to it), the slow-time ramp left out (it is common to a target's echoes).
        """
        beat_hz = self.profile.slope_hz_per_s * echoes.channel_delay_s - echoes.doppler_hz[:, None]
        return echoes.channel * np.exp(-2j * np.pi * _frac(beat_hz * self._t_centre_s))

    # -- the radar -----------------------------------------------------------------------------

    def finish_noise(self) -> None:
        """Wait until the noise drawn ahead for the next frame (if any) is drawn."""
        self._noise.finish()

    @workers.with_one_blas_thread  # small products: BLAS threads would spin beside the noise
    def process(self, schedule: PlayedFrames) -> list[Detections]:
        """Return the detections of every frame of ``schedule``, in frame order.

        Frames that need the ADC cube are processed one by one; all the others go through the
        analytic model together.
        """
        echoes = self.echoes(schedule)
        n_frames = schedule.n_frames
        use_adc = self._cube_frames(self, echoes, n_frames)
        if self.cfar != "ca":
            # The analytic model detects as a CA-CFAR does: an OS-CFAR is the cube's alone.
            use_adc = np.ones(n_frames, dtype=bool)
        alone = np.zeros(n_frames, dtype=bool)
        if self.cfar == "ca" and not use_adc.all():
            # Where targets share a range-Doppler neighbourhood the analytic model cannot tell
            # them apart: it reports each as if alone, where a radar merges or loses them.
            # Counted (the run fails with crowded_in_analytic unless the scene expects it).
            alone = self.crowded(echoes, n_frames) & ~use_adc
            self.frames_crowded_analytic += int(alone.sum())
        self.frames_adc += int(use_adc.sum())
        self.frames_analytic += int(n_frames - use_adc.sum())
        out = self._detect_analytic(echoes, schedule, ~use_adc, alone)
        for pos in np.flatnonzero(use_adc):  # one cube per frame
            one = self.echoes(schedule, slice(pos, pos + 1))
            out[pos] = self._detect_adc(one, int(schedule.frame_index[pos]),
                                        float(schedule.t_s[pos]))
        return [d for d in out if d is not None]

    def _bins(self, echoes: Echoes) -> tuple[FloatArray, FloatArray]:
        """Fractional range and (centred) Doppler bins of each echo, before folding."""
        p = self.profile
        # The beat frequency is -(S T - fD): the range spectrum is read where S T - fD lies.
        range_bin = ((p.slope_hz_per_s * echoes.delay_s - echoes.doppler_hz) / p.sample_rate_hz
                     * self._n)
        doppler_bin = echoes.doppler_hz * p.loop_time_s * self._loops
        return range_bin, doppler_bin

    def _fold(self, range_bin: FloatArray, doppler_bin: FloatArray
              ) -> tuple[FloatArray, FloatArray]:
        """Bins where the circular FFTs show them: range in [0, N), Doppler in [-L/2, L/2)."""
        half = self._loops / 2.0
        return np.mod(range_bin, self._n), np.mod(doppler_bin + half, self._loops) - half

    def crowded(self, echoes: Echoes, n_frames: int) -> NDArray[np.bool_]:
        """Frames where two targets share a range-Doppler neighbourhood (need the real cube)."""
        crowded = np.zeros(n_frames, dtype=bool)
        if echoes.target.size == 0:
            return crowded
        rb, db = self._bins(echoes)
        # One echo per (frame, target): its channels share delay and Doppler.
        keys, first = np.unique(echoes.frame * (echoes.target.max() + 1) + echoes.target,
                                return_index=True)
        f, r, d = echoes.frame[first], *self._fold(rb[first], db[first])
        crowded[f[_close_pairs(f, r, d, self._n, self._loops, CROWDED_BINS)]] = True
        return crowded

    def cube(self, echoes: Echoes, *, windowed: bool = False) -> ComplexArray:
        """Beat-signal cube ``[loop, virtual element, sample]`` of the echoes plus noise.

        ``windowed``: weighted as the FFTs take it (`_fft_r` along fast time, `_fft_d` along
        slow time), the weights folded into the small factors of the signal and into the
        noise's scale instead of passing over the cube again.
        """
        p = self.profile
        m = p.array.n_elements
        beat_hz = p.slope_hz_per_s * echoes.channel_delay_s - echoes.doppler_hz[:, None]  # (E, M)
        # The beat phasor at each fast-time sample t_n = adc_start + n / fs: its value at the
        # first sample times its step to the next, raised to n (`_powers`: exact to ~1e-13 over
        # a chirp, a tenth of the cost of an exponential per sample).
        fast = _powers(echoes.channel * np.exp(-2j * np.pi * _frac(beat_hz * p.adc_start_s)),
                       np.exp(-2j * np.pi * _frac(beat_hz / p.sample_rate_hz)), self._n)
        # Echoes with the same Doppler (a target's channels) share the slow-time ramp: sum
        # their fast-time rows first, then one ramp per Doppler value.
        doppler, group = np.unique(echoes.doppler_hz, return_inverse=True)
        order = np.argsort(group, kind="stable")
        starts = np.searchsorted(group[order], np.arange(doppler.size))
        rows = fast.reshape(group.size, m * self._n)
        summed = np.add.reduceat(rows[order], starts, axis=0) if group.size else rows
        slow = np.exp(2j * np.pi * _frac(np.outer(np.arange(self._loops) * p.loop_time_s,
                                                  doppler)))  # (L, U)
        if windowed:
            slow *= self._fft_d[:, None]
            summed = summed.reshape(-1, m, self._n) * self._fft_r
        cube = (slow @ summed.reshape(-1, m * self._n)).reshape(self._loops, m, self._n)
        if self._sigma > 0.0:
            # Complex white noise: independent real and imaginary parts, drawn interleaved
            # straight into complex numbers, the next frame's while this one is processed.
            noise = self._noise.take(2 * cube.size).view(np.complex128).reshape(cube.shape)
            noise *= self._noise_weight if windowed else self._sigma / np.sqrt(2.0)
            cube += noise
        return cube

    def _detect_adc(self, echoes: Echoes, frame: int, t_s: float) -> Detections:
        p = self.profile
        spec = self.cube(echoes, windowed=True)
        # The beat frequency is -(S T - fD): read the range spectrum at positive S T - fD.
        # Range then Doppler FFT, in place; the windows, the inverse FFT's 1 / N and the
        # centring of zero Doppler are in the cube's weights.
        np.fft.ifft(spec, axis=2, out=spec)
        np.fft.fft(spec, axis=0, out=spec)
        power = np.einsum("lmn,lmn->ln", spec.real, spec.real)  # (L, N): non-coherent over
        power += np.einsum("lmn,lmn->ln", spec.imag, spec.imag)  # the channels
        # Both FFTs are circular: a peak's neighbours wrap around in range and Doppler alike.
        peaks = power == _neighbourhood_max(power)
        noise = self._noise_floor(power, peaks)
        hits = peaks & (power > noise * 10.0 ** (self.threshold_db / 10.0))
        d_idx, r_idx = np.nonzero(hits)
        if d_idx.size == 0:
            return _empty(frame, t_s)
        # Sub-bin positions: parabola through the log power of the neighbours.
        def vertex(lo: FloatArray, mid: FloatArray, hi: FloatArray) -> FloatArray:
            lo, mid, hi = np.log(lo), np.log(mid), np.log(hi)
            den = lo - 2 * mid + hi
            return np.where(den < 0, 0.5 * (lo - hi) / np.where(den < 0, den, 1.0), 0.0)

        r_lo = power[d_idx, (r_idx - 1) % self._n]
        r_hi = power[d_idx, (r_idx + 1) % self._n]
        d_lo = power[(d_idx - 1) % self._loops, r_idx]
        d_hi = power[(d_idx + 1) % self._loops, r_idx]
        mid = power[d_idx, r_idx]
        r_off, d_off = vertex(r_lo, mid, r_hi), vertex(d_lo, mid, d_hi)
        r_frac, d_frac = self._fold(r_idx + r_off, d_idx - self._loops // 2 + d_off)
        doppler = d_frac / (self._loops * p.loop_time_s)
        # Undo the straddle loss of a peak between bins (Hann: sinc(x) / (1 - x^2)).
        loss = _hann_response(r_off) * _hann_response(d_off)
        snap = spec[d_idx, :, r_idx] / loss[:, None]  # (D, M)
        mid = mid / loss**2
        found = self._measure(snap, r_frac * self._range_bin_m, doppler,
                              10.0 * np.log10(mid / noise[d_idx, r_idx]))
        return Detections(cycle=frame, t_s=t_s,
                          **{name: v for name, v in found.items() if name != "source"})

    def _noise_floor(self, power: FloatArray,
                     where: NDArray[np.bool_] | None = None) -> FloatArray:
        """CFAR noise estimate per cell from its training cells (guard cells excluded).

        ``where``: the cells wanted (the others may be left infinite: an OS-CFAR's order
        statistic is taken at those alone, a tenth of the cost at a frame's local maxima).
        """
        guard, train = CFAR_GUARD, CFAR_TRAIN
        half = guard + train
        footprint = np.ones((2 * half + 1, 2 * half + 1), dtype=bool)
        footprint[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
        # Doppler wraps around; range does not (mirror at its ends).
        padded = np.pad(np.pad(power, ((half, half), (0, 0)), mode="wrap"),
                        ((0, 0), (half, half)), mode="reflect")
        if self.cfar == "ca":
            # Training cells = the whole window less the guard window: two box sums.
            inner = padded[train:-train, train:-train]
            floor = (_box_sum(padded, half) - _box_sum(inner, guard)) / footprint.sum()
        else:  # ordered statistic: the 3/4 quantile of the training cells
            rank = int(0.75 * footprint.sum())
            if where is None:
                from scipy import ndimage

                floor = ndimage.rank_filter(padded, rank=rank, footprint=footprint,
                                            mode="constant")[half:-half, half:-half]
            else:
                floor = np.full(power.shape, np.inf)
                d_idx, r_idx = np.nonzero(where)
                windows = np.lib.stride_tricks.sliding_window_view(
                    padded, footprint.shape)[d_idx, r_idx][:, footprint]
                floor[d_idx, r_idx] = np.partition(windows, rank, axis=1)[:, rank]
        # Without noise the floor is the echoes' sidelobes: keep it above numerical zero.
        return np.maximum(floor, power.max(initial=0.0) * 1e-12 + 1e-300)

    def _detect_analytic(self, echoes: Echoes, schedule: PlayedFrames,
                         frames: NDArray[np.bool_],
                         alone: NDArray[np.bool_] | None = None) -> list[Detections | None]:
        """Detect the selected frames with the superposition model (None for the others).

        ``alone``: frames whose targets are read each as if alone (crowded frames the cube does
        not take: each target's CFAR estimate holds its own sidelobes, no other target's).
        """
        p = self.profile
        arr = p.array
        out: list[Detections | None] = [None] * schedule.n_frames
        e = echoes.select(frames[echoes.frame])
        width = schedule.status.shape[1]
        entry, inverse = np.unique(e.frame * width + e.target, return_inverse=True)
        # The snapshot at a target's peak cell: each echo's windowed FFT peak (echoes of one
        # target share its Doppler: the slow-time ramp is common to them). Echoes of one target
        # at different ranges (channel delays apart) are read at the target's range cell k,
        # each through the range window's response at its offset from k, relative to the
        # response at the target's position (what the straddle correction of `adc` undoes).
        contrib = self._gain * self._snapshot_at_peak(e)
        echo_bin = self._bins(e)[0]
        level = np.abs(contrib).mean(axis=1)
        total = np.bincount(inverse, weights=level, minlength=entry.size)
        target_bin = np.bincount(inverse, weights=level * echo_bin, minlength=entry.size) / \
            np.where(total > 0, total, 1.0)
        cell = np.round(target_bin)
        factor = (self.profile.range_response(echo_bin - cell[inverse])
                  / self.profile.range_response(target_bin - cell)[inverse])
        snap = np.zeros((entry.size, arr.n_elements), dtype=complex)
        np.add.at(snap, inverse, contrib * factor[:, None])
        first = np.unique(inverse, return_index=True)[1]
        frame_of = e.frame[first]
        range_bin = target_bin
        doppler_bin = self._bins(e.select(first))[1]
        noise_power = self._sigma**2 * self._noise_gain  # per channel, after both FFTs
        # A target between bins reaches its peak cell weakened by both windows' responses (the
        # straddle loss, up to 2.9 dB at half a bin in range and Doppler): what the CFAR sees.
        # As `_detect_adc`: detected on the peak cell's power, its snapshot and SNR then
        # divided by that loss (the noise with them).
        straddle = (p.range_response(target_bin - cell)
                    * p.doppler_response(doppler_bin - np.round(doppler_bin)))
        # What the CA-CFAR estimates at each target's peak cell: the thermal noise plus every
        # target's window response in its training cells (a strong target masks a weaker one
        # near it, and its own sidelobes bound its SNR), as the cube's CFAR sees them.
        peak_power = (np.abs(snap) ** 2).sum(axis=1)
        thermal = arr.n_elements * noise_power
        floor = thermal + self._leakage(frame_of, *self._fold(target_bin, doppler_bin),
                                        peak_power, None if alone is None else alone[frame_of],
                                        thermal)
        if self._sigma > 0.0:
            noise = self.rng.standard_normal((2, *snap.shape)) * np.sqrt(noise_power / 2.0)
            clean = peak_power / (noise_power * arr.n_elements)
            snap = snap + (noise[0] + 1j * noise[1]) / straddle[:, None]
            # Sub-bin estimates scatter like the interpolated FFT peak: ~1 / (pi sqrt(2 SNR)),
            # the peak cell's SNR over the thermal noise.
            spread = 1.0 / (np.pi * np.sqrt(2.0 * clean * straddle**2))
            range_bin = range_bin + self.rng.standard_normal(clean.size) * spread
            doppler_bin = doppler_bin + self.rng.standard_normal(clean.size) * spread
        else:
            # Without noise the cube's floor is the echoes' sidelobes, kept above numerical
            # zero by the frame's strongest cell (`_noise_floor`).
            strongest = np.zeros(schedule.n_frames)
            np.maximum.at(strongest, frame_of, peak_power * straddle**2)
            floor = np.maximum(floor, strongest[frame_of] * 1e-12 + 1e-300)
        snr = (np.abs(snap) ** 2).sum(axis=1) / floor
        # What the FFTs show; the TDM compensation and the angles get the folded Doppler too.
        range_bin, doppler_bin = self._fold(range_bin, doppler_bin)
        range_m = range_bin * self._range_bin_m
        doppler = doppler_bin / (self._loops * p.loop_time_s)
        seen = snr * straddle**2 > 10.0 ** (self.threshold_db / 10.0)
        with np.errstate(divide="ignore"):
            found = self._measure(snap[seen], range_m[seen], doppler[seen],
                                  10.0 * np.log10(snr[seen]))
        owner = frame_of[seen][found["source"]]
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(schedule.n_frames + 1))
        for pos in np.flatnonzero(frames):  # split the batch into frames
            rows = order[bounds[pos] : bounds[pos + 1]]
            out[pos] = Detections(
                cycle=int(schedule.frame_index[pos]), t_s=float(schedule.t_s[pos]),
                **{name: values[rows] for name, values in found.items() if name != "source"})
        return out

    def _leakage(self, frame: NDArray[np.int64], range_bin: FloatArray, doppler_bin: FloatArray,
                 power: FloatArray, alone: NDArray[np.bool_] | None = None,
                 thermal: float = 0.0) -> FloatArray:
        """Every target's power in each target's CA-CFAR training cells, their mean there.

        ``range_bin, doppler_bin``: folded bins, ``power``: each target's power at its own
        position summed over the channels; ``alone``: targets that see their own power alone
        (`_detect_analytic`). A target at offset ``(dr, dd)`` from a peak cell
        puts ``power |H_r(x - dr)|^2 |H_d(y - dd)|^2`` in the cell ``(x, y)`` cells from it
        (`RadarProfile.range_response`, `doppler_response`), the training cells are the
        CFAR's window less its guard window, so its share is a sum of two products of sums
        over one axis each (`_LeakageTables`). Targets are summed in power (their cross
        terms average out over the cells). A target `LEAKAGE_REACH_BINS` or more away on an
        axis puts 100 dB less than its power there at most (`_LeakageTables.far_share`): it
        counts only where that much is still a thousandth of the noise, ``thermal`` (the
        thermal estimate summed over the channels), or of a twentieth of the frame's weakest
        target without noise, and then for every target of its frame (a target of 120 dB
        masks one 40 bins away). Near the ends of the range axis the cube's CFAR mirrors its
        window (`_noise_floor`): those cells are summed one by one.
        """
        tables = self._leakage_tables
        n_r, n_d = self._n, self._loops
        cell_r = np.mod(np.round(range_bin), n_r)
        cell_d = np.round(doppler_bin)
        leak = power * tables.share(_circular(range_bin - cell_r, n_r), doppler_bin - cell_d)
        among = np.arange(frame.size) if alone is None else np.flatnonzero(~alone)
        first, second = (among[pick] for pick in _near_pairs(
            frame[among], range_bin[among], doppler_bin[among], n_r, n_d, LEAKAGE_REACH_BINS))
        far_victims, far_sources = self._far_pairs(frame, range_bin, doppler_bin, power, among,
                                                   thermal)
        # (victim, source): the near pairs both ways, the far ones from their strong source.
        victims = np.concatenate([first, second, far_victims])
        sources = np.concatenate([second, first, far_sources])
        for chunk in range(0, victims.size, _LEAKAGE_PAIRS):
            i, j = victims[chunk : chunk + _LEAKAGE_PAIRS], sources[chunk : chunk + _LEAKAGE_PAIRS]
            share = tables.share(_circular(range_bin[j] - cell_r[i], n_r),
                                 _circular(doppler_bin[j] - cell_d[i], n_d))
            leak += np.bincount(i, weights=power[j] * share, minlength=leak.size)
        # The mirrored window near the range ends: those targets' sums again, cell by cell.
        half = CFAR_GUARD + CFAR_TRAIN
        edge = np.flatnonzero((cell_r < half) | (cell_r > n_r - 1 - half))
        if edge.size:
            leak[edge] = self._edge_leakage(edge, frame, range_bin, doppler_bin, cell_r, cell_d,
                                            power, victims, sources)
        return leak / tables.n_train

    def _far_pairs(self, frame: NDArray[np.int64], range_bin: FloatArray,
                   doppler_bin: FloatArray, power: FloatArray, among: NDArray[np.int64],
                   thermal: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """`_leakage`'s (victim, source) pairs `LEAKAGE_REACH_BINS` or more apart on an axis.

        Sources are the targets (of ``among``) strong enough to count that far; victims every
        other target of ``among`` in their frame.
        """
        tables = self._leakage_tables
        none = np.zeros(0, dtype=np.int64)
        if among.size < 2:
            return none, none
        f = frame[among]
        weakest = np.full(int(f.max()) + 1, np.inf)
        np.minimum.at(weakest, f, power[among])
        level = thermal if thermal > 0.0 else weakest[f] / 20.0
        strong = among[power[among] * tables.far_share / tables.n_train > 1e-3 * level]
        if strong.size == 0:
            return none, none
        # Each strong target against every target of its frame (one sweep per frame's block).
        order = among[np.argsort(f, kind="stable")]
        begin = np.searchsorted(frame[order], frame[strong], side="left")
        count = np.searchsorted(frame[order], frame[strong], side="right") - begin
        source = np.repeat(strong, count)
        victim = order[np.repeat(begin - np.cumsum(count) + count, count)
                       + np.arange(int(count.sum()))]
        n_r, n_d = self._n, self._loops
        reach = LEAKAGE_REACH_BINS
        # Those within reach on both axes are `_near_pairs`' already.
        far = (victim != source) & (
            (np.abs(_circular(range_bin[victim] - range_bin[source], n_r)) >= reach)
            | (np.abs(_circular(doppler_bin[victim] - doppler_bin[source], n_d)) >= reach))
        return victim[far], source[far]

    def _edge_leakage(self, edge: NDArray[np.int64], frame: NDArray[np.int64],
                      range_bin: FloatArray, doppler_bin: FloatArray, cell_r: FloatArray,
                      cell_d: FloatArray, power: FloatArray, victims: NDArray[np.int64],
                      sources: NDArray[np.int64]) -> FloatArray:
        """`_leakage`'s sums, undivided, for peak cells whose window the range ends mirror.

        ``victims, sources``: the (victim, source) pairs of targets that reach each other.
        """
        p, n_r, n_d = self.profile, self._n, self._loops
        guard, half = CFAR_GUARD, CFAR_GUARD + CFAR_TRAIN
        # The targets each edge target sees: itself and its sources.
        at_edge = np.zeros(frame.size, dtype=bool)
        at_edge[edge] = True
        victims_all = np.concatenate([edge, victims[at_edge[victims]]])
        sources_all = np.concatenate([edge, sources[at_edge[victims]]])
        offsets = np.arange(-half, half + 1)
        inner = np.abs(offsets) <= guard
        period = max(2 * (n_r - 1), 1)
        total = np.zeros(frame.size)
        # In steps of pairs: each step's arrays are pairs x the window's 21 cells.
        step = max(1, _LEAKAGE_PAIRS // offsets.size)
        for chunk in range(0, victims_all.size, step):
            i, j = victims_all[chunk : chunk + step], sources_all[chunk : chunk + step]
            # The window's range cells, mirrored as numpy's "reflect" pads (again and again on
            # an axis shorter than the window).
            x = np.mod(cell_r[i, None] + offsets, period)
            x = np.where(x > n_r - 1, period - x, x)
            r_power = p.range_response(_circular(x - range_bin[j, None], n_r)) ** 2
            d_power = p.doppler_response(_circular(cell_d[i, None] + offsets
                                                   - doppler_bin[j, None], n_d)) ** 2
            share = (r_power[:, ~inner].sum(axis=1) * d_power.sum(axis=1)
                     + r_power[:, inner].sum(axis=1) * d_power[:, ~inner].sum(axis=1))
            total += np.bincount(i, weights=power[j] * share, minlength=frame.size)
        return np.asarray(total[edge], dtype=np.float64)

    @cached_property
    def _leakage_tables(self) -> _LeakageTables:
        return _LeakageTables(self.profile)

    def _measure(self, snap: ComplexArray, range_m: FloatArray, doppler_hz: FloatArray,
                 snr_db: FloatArray) -> dict[str, Any]:
        """TDM-Doppler compensation, angles, velocity and RCS of detections (arrays)."""
        p = self.profile
        comp = np.exp(-2j * np.pi * np.outer(doppler_hz, self._slot * p.chirp_slot_s))
        snap = snap * comp
        est = self._angles(snap)
        src = est.source
        # Level: the full array's beam towards the estimated angle, whatever the estimator.
        arr = self._steering_array
        u, s = direction_cosines(np.radians(est.az_deg), np.radians(est.el_deg))
        steer = np.exp(1j * arr.wavenumber_rad_per_m * (np.outer(u, arr.y_m)
                                                        + np.outer(s, arr.z_m)))
        beam = np.abs(np.einsum("dm,dm->d", snap[src], steer.conj()))
        amplitude = beam / (self._gain * arr.n_elements)
        range_m = range_m[src]
        if p.range_doppler_coupling == "corrected":
            # The beat is S tau - fD: the measured Doppler's share taken back out.
            range_m = range_m + C0_MPS * doppler_hz[src] / (2.0 * p.slope_hz_per_s)
        with np.errstate(divide="ignore"):
            rcs = (20.0 * np.log10(amplitude) + 40.0 * np.log10(range_m)
                   + self._rcs_offset)
        return {"source": src, "range_m": range_m,
                "radial_velocity_mps": -doppler_hz[src] * p.wavelength_m / 2.0,
                "az_deg": est.az_deg, "el_deg": est.el_deg, "snr_db": snr_db[src],
                "rcs_dbsm": rcs}

# Two targets closer than this in range and in Doppler bins share a neighbourhood (crowded).
CROWDED_BINS = 2.5
# Targets this far apart on an axis (bins) or more reach each other's CFAR estimate in the
# analytic model only where one is strong (`SimulatedRadar._far_pairs`): 16 bins beyond the
# CFAR's window, the Hann windows' sidelobes there are below -100 dB of the target's power,
# averaged over the training cells.
LEAKAGE_REACH_BINS = CFAR_GUARD + CFAR_TRAIN + 16
# Pairs of targets per step of the analytic leakage sums (bounded temporaries).
_LEAKAGE_PAIRS = 65_536
# Sub-bin steps of the leakage tables (linear interpolation: within 3e-4 of the value).
_LEAKAGE_STEPS_PER_BIN = 256


def _circular(offset: FloatArray, n: int) -> FloatArray:
    """Offsets on a circular axis of ``n`` bins, in [-n / 2, n / 2)."""
    return np.mod(offset + n / 2.0, n) - n / 2.0


@functools.lru_cache(maxsize=16)
def _axis_sums(n: int) -> tuple[float, FloatArray, FloatArray]:
    """`_LeakageTables`' sums for an axis of ``n`` bins, over the whole of its circle.

    Sums of the Hann window's power response (`hann_dft_response`) over the CFAR's guard
    cells and over its other cells on that axis, at every offset of a target from the window's
    centre in steps of 1 / `_LEAKAGE_STEPS_PER_BIN` bin.
    """
    steps, half = _LEAKAGE_STEPS_PER_BIN, CFAR_GUARD + CFAR_TRAIN
    reach = n / 2.0
    size = int(round(2 * reach * steps)) + 1  # offsets -reach + i / steps
    # Cell m at offset o from the target lies at m - o: on the same grid of steps, the
    # response once at every point, then each cell's values a slice of it.
    wide = int(round((reach + half) * steps))
    power = hann_dft_response(_circular(np.arange(-wide, wide + 1) / steps, n), n) ** 2
    guard = np.zeros(size)
    outside = np.zeros(size)
    for m in range(-half, half + 1):  # 21 cells
        start = wide + m * steps + int(round(reach * steps))  # offset -reach: m + reach
        values = power[start - size + 1 : start + 1][::-1]
        if abs(m) <= CFAR_GUARD:
            guard += values
        else:
            outside += values
    return reach, guard, outside


class _LeakageTables:
    """A target's share of a CA-CFAR estimate by its offset from the peak cell (`_leakage`).

    Per axis, the sums of the window's power response over the CFAR's guard window and over
    the rest of its window, tabulated at `_LEAKAGE_STEPS_PER_BIN` steps per bin over the whole
    of the axis's circle (`_axis_sums`, once per axis length in a process). The
    training cells are the window's cells outside the guard on one axis or the other: a sum of
    two positive products (no difference of near-equal ones, which would lose a target's own
    sidelobes to its main lobe's rounding).
    """

    def __init__(self, profile: RadarProfile) -> None:
        half = CFAR_GUARD + CFAR_TRAIN
        self.n_train = (2 * half + 1) ** 2 - (2 * CFAR_GUARD + 1) ** 2
        self._axes = [_axis_sums(profile.adc_samples), _axis_sums(profile.chirp_loops)]
        # The largest share a target `LEAKAGE_REACH_BINS` or more away on an axis has (its
        # offset on the other axis anywhere, the sidelobes' ripple over a bin beyond).
        beyond = LEAKAGE_REACH_BINS + np.arange(0, 2 * _LEAKAGE_STEPS_PER_BIN + 1) / float(
            _LEAKAGE_STEPS_PER_BIN)
        other = np.arange(-_LEAKAGE_STEPS_PER_BIN, _LEAKAGE_STEPS_PER_BIN + 1) / float(
            _LEAKAGE_STEPS_PER_BIN)
        a, b = np.meshgrid(beyond, other)
        self.far_share = float(max(self.share(a.ravel(), b.ravel()).max(),
                                   self.share(b.ravel(), a.ravel()).max()))
    def share(self, range_offset: FloatArray, doppler_offset: FloatArray) -> FloatArray:
        """Sum over the training cells of a unit target's power at these offsets from them."""
        sums = []
        for (reach, guard, outside), offset in zip(self._axes, (range_offset, doppler_offset),
                                                   strict=True):
            at = (np.clip(offset, -reach, reach) + reach) * _LEAKAGE_STEPS_PER_BIN
            low = np.minimum(at.astype(np.int64), guard.size - 2)
            frac = at - low
            sums.append(((1.0 - frac) * guard[low] + frac * guard[low + 1],
                         (1.0 - frac) * outside[low] + frac * outside[low + 1]))
        (r_guard, r_out), (d_guard, d_out) = sums
        # Outside the guard in range (any Doppler cell), or inside it in range and outside it
        # in Doppler.
        return r_out * (d_guard + d_out) + r_guard * d_out


def _close_pairs(frame: NDArray[np.int64], r: FloatArray, d: FloatArray, n_r: int, n_d: int,
                 within: float) -> NDArray[np.int64]:
    """Return the entries with another of the same frame within ``within`` bins on both axes.

    ``r`` in [0, n_r) and ``d`` in [-n_d / 2, n_d / 2) are folded bins on circular axes
    (`_near_pairs`).
    """
    first, second = _near_pairs(frame, r, d, n_r, n_d, within)
    return np.unique(np.concatenate([first, second]))


def _near_pairs(frame: NDArray[np.int64], r: FloatArray, d: FloatArray, n_r: int, n_d: int,
                within: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Return the pairs of entries of one frame within ``within`` bins of each other on both axes.

    ``r`` in [0, n_r) and ``d`` in [-n_d / 2, n_d / 2) are folded bins on circular axes. Each
    pair of distinct entries once, as two index arrays (``first < second``). Sorted by frame
    and range, each entry is compared with its successors while they are still within reach in
    range (entries near the start of the range axis are also seen one axis length on, next to
    its end): the cost grows with the entries times the largest group sharing a range
    neighbourhood, never with the square of the entries.
    """
    index = np.arange(frame.size)
    wrap = r < within  # also seen one axis length further on, next to the end
    f = np.concatenate([frame, frame[wrap]])
    rr = np.concatenate([r, r[wrap] + n_r])
    dd = np.concatenate([d, d[wrap]])
    who = np.concatenate([index, index[wrap]])
    order = np.lexsort((rr, f))
    f, rr, dd, who = f[order], rr[order], dd[order], who[order]
    found: list[NDArray[np.int64]] = []
    for lag in range(1, f.size):
        reach = (f[lag:] == f[:-lag]) & (rr[lag:] - rr[:-lag] < within)
        if not reach.any():
            break
        apart = np.abs(np.mod(dd[lag:] - dd[:-lag] + n_d / 2, n_d) - n_d / 2)
        pair = reach & (apart < within) & (who[lag:] != who[:-lag])
        a, b = who[:-lag][pair], who[lag:][pair]
        found.append(np.minimum(a, b) * frame.size + np.maximum(a, b))
    # A pair met both directly and through the wrap (reach beyond half the axis): once.
    keys = np.unique(np.concatenate(found)) if found else np.zeros(0, dtype=np.int64)
    return keys // max(frame.size, 1), keys % max(frame.size, 1)


class _NoiseAhead:
    """Standard normal draws for the ADC cubes, drawn one frame ahead.

    Each frame's noise is drawn while the frame before is processed (numpy's generators
    release the GIL: on a second core the draw is free). The draws come from a generator
    spawned from the radar's, one after the other in the order frames ask for them, whatever
    the timing: a seed gives the same noise.
    """

    def __init__(self, parent: np.random.Generator) -> None:
        self._parent = parent
        self._rng: np.random.Generator | None = None
        self._next: Future[FloatArray] | None = None
        self._size = 0

    def take(self, size: int) -> FloatArray:
        """Return ``size`` draws (the ones drawn ahead if the size matches) and draw ahead."""
        if self._rng is None:
            self._rng = self._parent.spawn(1)[0]
        ahead = self._next
        if ahead is not None and self._size == size:
            out = ahead.result()
        else:
            if ahead is not None:
                ahead.result()  # drawn for another size: the stream moves on past it
            out = self._rng.standard_normal(size)
        self._size = size
        self._next = _drawing_pool().submit(self._rng.standard_normal, size)
        return out

    def finish(self) -> None:
        """Wait for the draw ahead, if one runs (it is kept for the next `take`)."""
        if self._next is not None:
            self._next.result()


def _drawing_pool() -> ThreadPoolExecutor:
    """One background thread for noise drawn ahead (tasks run in the order they come)."""
    return workers.pool("rts-noise", threads=1)


def _neighbourhood_max(a: FloatArray) -> FloatArray:
    """Return the largest of each cell's 3 x 3 neighbourhood, both axes circular.

    ``scipy.ndimage.maximum_filter(a, size=3, mode="wrap")``, as two separable maxima over
    shifted views: a seventh of its time on a frame's map.
    """
    padded = np.pad(a, 1, mode="wrap")
    rows = np.maximum(np.maximum(padded[:-2], padded[1:-1]), padded[2:])
    return np.maximum(np.maximum(rows[:, :-2], rows[:, 1:-1]), rows[:, 2:])


def _box_sum(a: FloatArray, r: int) -> FloatArray:
    """Return the sums over every (2r+1) x (2r+1) box of ``a`` that fits in it.

    Separable running sums (cumulative sums differenced), linear in the array's size whatever
    the box: the CA-CFAR's window sums without a 2-D correlation.
    """
    w = 2 * r + 1
    c = np.cumsum(a, axis=0)
    rows = np.concatenate([c[w - 1 : w], c[w:] - c[:-w]], axis=0)
    c = np.cumsum(rows, axis=1)
    return np.concatenate([c[:, w - 1 : w], c[:, w:] - c[:, :-w]], axis=1)


def _powers(first: ComplexArray, step: ComplexArray, n: int) -> ComplexArray:
    """``first * step**k`` for ``k`` in ``0 .. n-1`` along a new last axis.

    Two running products of about sqrt(n) terms each, ``step**j`` and ``(step**K)**i``, and
    their outer product (``k = i K + j``): the rounding of a short product, and a vector
    multiply for the rest, where one running product over ``n`` is a scalar loop (2.4x).
    """
    width = max(1, math.isqrt(n - 1) + 1) if n > 1 else 1
    rows = -(-n // width)
    low = np.empty((*step.shape, width), dtype=complex)
    low[..., 0] = first
    low[..., 1:] = step[..., None]
    np.cumprod(low, axis=-1, out=low)
    high = np.empty((*step.shape, rows), dtype=complex)
    high[..., 0] = 1.0
    high[..., 1:] = (step ** width)[..., None]
    np.cumprod(high, axis=-1, out=high)
    out = high[..., :, None] * low[..., None, :]
    return out.reshape(*step.shape, rows * width)[..., :n]


def _frac(cycles: FloatArray) -> FloatArray:
    """Cycles less their nearest whole number (exact in the phase, keeps its precision)."""
    return cycles - np.round(cycles)


def _hann_response(offset: FloatArray) -> FloatArray:
    """Relative amplitude of a Hann-windowed DFT ``offset`` bins from a tone (|offset| < 1)."""
    x = np.clip(np.abs(offset), 0.0, 0.999)
    return np.sinc(x) / (1.0 - x * x)


def _empty(frame: int, t_s: float) -> Detections:
    return Detections.empty(frame, t_s)


def near_field_warning(profile: RadarProfile, rig: Rig, *,
                       threshold_deg: float = 0.05) -> str | None:
    """Warn when the rig's FEs are inside the radar's near field; None when they are not.

    The near field ends at the Fraunhofer distance ``2 D^2 / lambda``, D the largest extent of
    the radar's physical antenna layout. Inside it the paths to the FEs are not plane waves: the
    radar sees each FE away from its nominal direction. The warning names the size of that
    effect: the largest such deviation of one FE alone as this module's simulated radar sees it
    (no noise, no RTS delay). The Fraunhofer criterion (a pi/8 path difference) is coarse: FEs
    beyond it that the radar still sees ``threshold_deg`` or more off their nominal direction
    (a TX group beside the RX group, FE antenna offsets) are warned about too.
    """
    fraunhofer_m = 2.0 * profile.antennas.extent_m**2 / profile.wavelength_m
    radar = SimulatedRadar(profile, rig, fidelity="analytic", noise=False)
    az, el = radar.fe_directions()
    off_deg = np.hypot((az - rig.az_deg) * np.cos(np.radians(rig.el_deg)), el - rig.el_deg)
    inside = rig.distance_m < fraunhofer_m
    if not inside.any() and off_deg.max() < threshold_deg:
        return None

    def distances(d: FloatArray) -> str:
        return f"{d.min():.3g} m" if np.ptp(d) == 0.0 else f"{d.min():.3g}-{d.max():.3g} m"

    if inside.any():
        return (f"FEs at {distances(rig.distance_m[inside])} are inside radar {profile.name}'s "
                f"near field (Fraunhofer distance {fraunhofer_m:.3g} m): expect "
                f"~{off_deg.max():.2g} deg direction errors")
    return (f"FEs at {distances(rig.distance_m)} are beyond radar {profile.name}'s Fraunhofer "
            f"distance ({fraunhofer_m:.3g} m) but not in its far field: it sees them up to "
            f"~{off_deg.max():.2g} deg off their nominal directions")
