"""Radar profiles: FMCW chirp sequence, TDM-MIMO timing and the virtual array, as data.

A profile file (``*.radar.yaml``) names an antenna preset or gives the TX/RX positions; everything
else the product needs (wavelength, resolutions, unambiguous range and velocity, the virtual array)
derives from it. TX/RX positions are the antennas' physical phase centres in the radar's face
plane (x = 0), relative to the radar's **reference point**: the point from which the rig's FE
azimuths, elevations and distances are measured and the mount pose is given.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import ANTENNA_PRESETS, Antennas, VirtualArray
from ..errors import ArrayError, ScenarioError
from ..file_kinds import load_kind
from ..located_yaml import Document, load_yaml, validate
from ..propagation import C0_MPS
from ..responses import FrontEndModel
from .clock import MAX_LATENCY_S, MIN_CYCLE_S, RadarClock

if TYPE_CHECKING:
    from ..rig import Rig

# Frame rates this close above a rig's update rate are at it (a rate written as 1 / period).
RATE_SLACK = 1e-9

FloatArray = NDArray[np.float64]

# The widest virtual array a profile may give, per axis, in nominal wavelengths: the angle grids
# of the radar's estimator and of the solver's global-maximum check grow with (aperture /
# wavelength) per axis (64 x 64 wavelengths: about 1.2 GB and 20 s to validate a scene). The
# widest preset, cascade-12x16, spans 42.5 wavelengths along y.
MAX_APERTURE_WAVELENGTHS = 64
# The most ADC samples one frame may hold: adc_samples x chirp_loops x virtual channels (the
# simulated radar's beat-signal cube, 1 GiB as complex numbers; cascade-12x16: 3.1 million).
MAX_CUBE_SAMPLES = 2**26


def hann_dft_response(offset_bins: FloatArray | float, n: int) -> FloatArray:
    """Response of an ``n``-point DFT windowed with ``hanning(n + 2)[1:-1]``, re its peak.

    The window is ``1/2 + 1/2 cos(2 pi (m - c) / (n + 1))`` about its centre ``c``; its DFT
    (real, the phase referred to the centre) ``offset_bins`` from a tone is a sum of three
    Dirichlet kernels ``sin(n t / 2) / sin(t / 2)``, ``t = 2 pi offset / n`` and shifted by
    ``+-2 pi / (n + 1)``.
    """
    t = 2.0 * np.pi * np.asarray(offset_bins, dtype=np.float64) / n
    shift = 2.0 * np.pi / (n + 1)

    def dirichlet(x: FloatArray) -> FloatArray:
        half = np.sin(0.5 * x)
        small = np.abs(half) < 1e-12
        return np.where(small, float(n), np.sin(0.5 * n * x) / np.where(small, 1.0, half))

    def window(x: FloatArray) -> FloatArray:
        return 0.5 * dirichlet(x) + 0.25 * (dirichlet(x - shift) + dirichlet(x + shift))

    out: FloatArray = window(t) / window(np.zeros(1))
    return out


@dataclass(frozen=True, eq=False)
class RadarProfile:
    """An FMCW TDM-MIMO radar: chirp, timing, noise and virtual array.

    Attributes
    ----------
    fc_hz, bandwidth_hz : float
        Chirp start frequency and swept bandwidth.
    ramp_time_s, idle_time_s : float
        Chirp ramp and idle time; one chirp slot lasts their sum.
    adc_samples : int
        Samples per chirp, taken at ``sample_rate_hz`` (complex baseband).
    adc_start_s : float
        Time from the start of the ramp to the first ADC sample (default 0: sampling starts
        with the ramp when the profile does not say).
    chirp_loops : int
        Chirps per TX per frame.
    tx_order : tuple of int
        TX firing order within a loop (TDM-MIMO).
    frame_period_s : float
        Frame repetition period.
    clock : RadarClock
        When it measures and reports (`rts_scenario.radar.clock`): its cycle (default
        ``frame_period_s``), start offset, latency, jitter and counter start (profile key
        ``clock``).
    noise_level_db : float
        Thermal noise per complex ADC sample, dB relative to the full-scale amplitude 1 that an
        echo through a 0 dB attenuator produces.
    array : VirtualArray
        The virtual array at this profile's nominal wavelength, centred on its centroid: what
        the radar's estimator assumes and the solver uses.
    antennas : Antennas
        The physical TX and RX phase centres, relative to the radar's reference point (the
        point the rig's FE angles and distances are measured from).
    tx_index : tuple of int
        The TX of each virtual element (elements are TX-major: TX t, RX r is t * n_rx + r).
    range_doppler_coupling : {"kept", "corrected"}
        Whether the radar's ranges keep the range-Doppler coupling of its up-chirps (a target
        with range rate ``v`` ranged ``v f / S`` farther; most radars keep it) or correct it
        with the measured Doppler (profile key ``range_doppler_coupling``, default ``kept``).
    """

    name: str
    fc_hz: float
    bandwidth_hz: float
    ramp_time_s: float
    idle_time_s: float
    adc_samples: int
    sample_rate_hz: float
    chirp_loops: int
    tx_order: tuple[int, ...]
    frame_period_s: float
    noise_level_db: float
    array: VirtualArray
    antennas: Antennas
    tx_index: tuple[int, ...] = ()
    adc_start_s: float = 0.0
    clock: RadarClock | None = None
    range_doppler_coupling: str = "kept"

    def __post_init__(self) -> None:
        if self.clock is None:
            object.__setattr__(self, "clock", RadarClock(cycle_s=self.frame_period_s))
        if self.range_doppler_coupling not in ("kept", "corrected"):
            raise ScenarioError(f"range_doppler_coupling: must be 'kept' or 'corrected', got "
                                f"{self.range_doppler_coupling!r}")

    @property
    def radar_clock(self) -> RadarClock:
        """The radar's clock (typed: never None after construction)."""
        assert self.clock is not None
        return self.clock

    @property
    def wavelength_m(self) -> float:
        """``c0 / (fc + B/2)``."""
        return C0_MPS / (self.fc_hz + self.bandwidth_hz / 2.0)

    @property
    def sampled_centre_frequency_hz(self) -> float:
        """Transmit frequency at the centre of the sampled sweep (sample ``(N - 1) / 2``)."""
        centre_s = self.adc_start_s + (self.adc_samples - 1) / (2.0 * self.sample_rate_hz)
        return self.fc_hz + self.slope_hz_per_s * centre_s

    @property
    def coupling_lag_s(self) -> float:
        """The lag the range-Doppler coupling gives the detections (s; 0 where corrected).

        An up-chirp's beat frequency is ``S tau - fD`` with ``fD = -2 v f / c`` at the sampled
        sweep's centre ``f``: a target of range rate ``v`` is ranged ``v f / S`` farther, where
        the scene has it ``f / S`` later: ``-f / S`` (-1.9 ms for the awr1843boost profile).
        """
        if self.range_doppler_coupling == "corrected":
            return 0.0
        return -self.sampled_centre_frequency_hz / self.slope_hz_per_s

    @property
    def range_bin_m(self) -> float:
        """Range per bin of the range FFT: ``c0 fs / (2 S N)``."""
        return C0_MPS * self.sample_rate_hz / (2.0 * self.slope_hz_per_s * self.adc_samples)

    def range_bin(self, delay_s: FloatArray | float, doppler_hz: FloatArray | float = 0.0
                  ) -> FloatArray:
        """Fractional range bin (unfolded) of an echo with total delay ``delay_s``.

        Where the range spectrum shows it: the beat frequency ``S T - fD`` in bins.
        """
        return ((self.slope_hz_per_s * np.asarray(delay_s) - np.asarray(doppler_hz))
                / self.sample_rate_hz * self.adc_samples)

    def range_response(self, offset_bins: FloatArray | float) -> FloatArray:
        """Response of the Hann-windowed range DFT ``offset_bins`` from a tone, re its peak.

        The radar windows its ``N = adc_samples`` samples with ``hanning(N + 2)[1:-1]``
        (`hann_dft_response`).
        """
        return hann_dft_response(offset_bins, self.adc_samples)

    def doppler_response(self, offset_bins: FloatArray | float) -> FloatArray:
        """Response of the Hann-windowed Doppler DFT ``offset_bins`` from a tone, re its peak.

        Its ``L = chirp_loops`` loops windowed with ``hanning(L + 2)[1:-1]``
        (`hann_dft_response`).
        """
        return hann_dft_response(offset_bins, self.chirp_loops)

    @property
    def steering_wavelength_m(self) -> float:
        """Wavelength at the centre of the sampled sweep: what a well-designed radar steers with."""
        return C0_MPS / self.sampled_centre_frequency_hz

    @cached_property
    def steering_array(self) -> VirtualArray:
        """The virtual array at `steering_wavelength_m`: what the radar's estimators steer.

        The schedule solves the weights on it, so that the solver's beamformer is the radar's.
        """
        return VirtualArray.from_positions(self.array.y_m, self.array.z_m,
                                           wavelength_m=self.steering_wavelength_m,
                                           name=self.array.name)

    @property
    def front_end_model(self) -> FrontEndModel:
        """The model of the FEs' echoes on this radar's antennas (`rts_scenario.responses`)."""
        return FrontEndModel(self.antennas)

    @property
    def slope_hz_per_s(self) -> float:
        """Chirp slope."""
        return self.bandwidth_hz / self.ramp_time_s

    @property
    def chirp_slot_s(self) -> float:
        """Time from one chirp start to the next."""
        return self.ramp_time_s + self.idle_time_s

    @property
    def loop_time_s(self) -> float:
        """Time of one TDM loop (every TX once): the slow-time sampling interval."""
        return len(self.tx_order) * self.chirp_slot_s

    def frame_rate_problem(self, frame_rate_hz: float, rig: Rig) -> str | None:
        """Why scene frames at ``frame_rate_hz`` cannot be played and checked, or None.

        The rig must follow the rate (``limits.update_rate_hz``), and the time a radar cycle
        may show either frame after a change (this radar's chirps plus the rig's
        ``limits.update_latency_s``) must be under half the time between the frames the radar
        sees (a frame period, or its cycle where frames come faster): else the check could not
        tell a radar a frame behind from one in step.
        """
        limits = rig.limits
        if frame_rate_hz > limits.update_rate_hz * (1 + RATE_SLACK):
            return (f"the scene runs at {frame_rate_hz:g} Hz but rig {rig.name!r} updates at "
                    f"most {limits.update_rate_hz:g} Hz (limits.update_rate_hz)")
        window_s = self.measurement_s + limits.update_latency_s
        step_s = max(1.0 / frame_rate_hz, self.radar_clock.cycle_s)
        if window_s >= 0.5 * step_s:
            return (f"a radar cycle may show either frame for {window_s * 1e3:.3g} ms after a "
                    f"frame change (the chirps of radar {self.name!r} "
                    f"{self.measurement_s * 1e3:.3g} ms + limits.update_latency_s of rig "
                    f"{rig.name!r} {limits.update_latency_s * 1e3:.3g} ms), half the "
                    f"{step_s * 1e3:.3g} ms between the frames the radar sees or more: the "
                    f"check could not tell a radar a frame behind from one in step; lower "
                    f"frame_rate_hz below {0.5 / window_s:.3g} Hz (or the update latency)")
        return None

    @property
    def measurement_s(self) -> float:
        """How long one cycle's chirp sequence lasts (every TX, every loop)."""
        return self.chirp_loops * self.loop_time_s

    @property
    def range_resolution_m(self) -> float:
        """``c0 / (2 B_sampled)`` with the bandwidth swept while sampling."""
        sampled = self.slope_hz_per_s * self.adc_samples / self.sample_rate_hz
        return C0_MPS / (2.0 * sampled)

    @property
    def max_range_m(self) -> float:
        """Largest unambiguous range: the beat frequency reaches the (complex) sample rate."""
        return self.sample_rate_hz * C0_MPS / (2.0 * self.slope_hz_per_s)

    @property
    def max_radial_velocity_mps(self) -> float:
        """Largest unambiguous |radial velocity|: ``lambda / (4 N_tx T_slot)`` for TDM-MIMO."""
        return self.wavelength_m / (4.0 * len(self.tx_order) * self.chirp_slot_s)

    @property
    def velocity_resolution_mps(self) -> float:
        """``lambda / (2 N_tx N_loops T_slot)``."""
        return self.wavelength_m / (
            2.0 * len(self.tx_order) * self.chirp_loops * self.chirp_slot_s
        )

    @classmethod
    def preset(cls, name: str) -> RadarProfile:
        """Return a shipped profile: see `preset_names`."""
        names = preset_names()
        if name not in names:
            raise ScenarioError(
                f"unknown radar profile {name!r}; valid profiles: {', '.join(names)}"
            )
        path = f"data/radars/{name}.radar.yaml"
        text = resources.files("rts_scenario").joinpath(path).read_text()
        return cls.from_document(load_yaml(f"<profile {name}>", text))

    @classmethod
    def from_file(cls, path: str | Path) -> RadarProfile:
        """Load a ``*.radar.yaml`` file."""
        return cls.from_document(load_kind(path, ".radar.yaml"))

    @classmethod
    def from_document(cls, doc: Document) -> RadarProfile:
        """Build a profile from a loaded document, with located errors."""
        validate(doc, PROFILE_SCHEMA)
        d: dict[str, Any] = doc.data
        fc, bw = float(d["fc_hz"]), float(d["bandwidth_hz"])
        spec = d["array"]
        if isinstance(spec, str):
            # The preset's geometry is in wavelengths: at this profile's nominal wavelength.
            antennas = Antennas.preset(spec, C0_MPS / (fc + bw / 2.0))
        else:
            _check_aperture(doc, spec, C0_MPS / (fc + bw / 2.0))
            try:
                antennas = Antennas(spec["tx_y_m"], spec["tx_z_m"], spec["rx_y_m"],
                                    spec["rx_z_m"], name=d["name"])
            except ArrayError as exc:
                raise doc.error(("array",), str(exc)) from None
        n_tx = antennas.n_tx
        cube = d["adc_samples"] * d["chirp_loops"] * n_tx * antennas.n_rx
        if cube > MAX_CUBE_SAMPLES:
            key = "adc_samples" if d["adc_samples"] >= d["chirp_loops"] else "chirp_loops"
            raise doc.error(
                (key,),
                f"adc_samples x chirp_loops x virtual channels = {d['adc_samples']} x "
                f"{d['chirp_loops']} x {n_tx * antennas.n_rx} = {cube:,} samples per frame; at "
                f"most {MAX_CUBE_SAMPLES:,} (the simulated radar's beat-signal cube)")
        array = antennas.virtual_array(fc_hz=fc, bandwidth_hz=bw)
        for axis, positions in (("y", array.y_m), ("z", array.z_m)):
            # The RTS synthesizes azimuth and elevation: no weight method solves for a line.
            if np.ptp(positions) == 0.0:
                raise doc.error(
                    ("array",),
                    f"the virtual array is a line: every element at one {axis} (tx_{axis}_m "
                    f"plus rx_{axis}_m); azimuth and elevation need elements spread along y "
                    f"and along z")
        tx_order = tuple(int(t) for t in d["tx_order"])
        if sorted(tx_order) != list(range(n_tx)):
            raise doc.error(
                ("tx_order",),
                f"must fire each of the {n_tx} TX once (a permutation of 0..{n_tx - 1}), "
                f"got {list(tx_order)}",
            )
        slot = d["ramp_time_s"] + d["idle_time_s"]
        adc_start = float(d.get("adc_start_s", 0.0))
        if adc_start + d["adc_samples"] / d["sample_rate_hz"] > d["ramp_time_s"]:
            raise doc.error(
                ("adc_samples",),
                f"sampling takes {d['adc_samples'] / d['sample_rate_hz']:.3g} s from "
                f"adc_start_s = {adc_start:.3g} s, beyond ramp_time_s = {d['ramp_time_s']:.3g} s",
            )
        if n_tx * d["chirp_loops"] * slot > d["frame_period_s"]:
            raise doc.error(
                ("frame_period_s",),
                f"the chirps of a frame take {n_tx * d['chirp_loops'] * slot:.3g} s, longer "
                f"than the frame period {d['frame_period_s']:.3g} s",
            )
        c = d.get("clock", {})
        try:
            clock = RadarClock(cycle_s=float(c.get("cycle_s", d["frame_period_s"])),
                               start_offset_s=float(c.get("start_offset_s", 0.0)),
                               latency_s=float(c.get("latency_s", 0.0)),
                               jitter_s=float(c.get("jitter_s", 0.0)),
                               counter_start=None if c.get("counter_start") == "auto"
                               else int(c.get("counter_start", 0)))
        except ValueError as exc:
            key = str(exc).split(":")[0].split(".")[-1]
            raise doc.error(("clock", key) if key in c else ("clock",),
                            str(exc).split(": ", 1)[1]) from None
        return cls(
            name=d["name"], fc_hz=fc, bandwidth_hz=bw, ramp_time_s=float(d["ramp_time_s"]),
            idle_time_s=float(d["idle_time_s"]), adc_samples=int(d["adc_samples"]),
            sample_rate_hz=float(d["sample_rate_hz"]), chirp_loops=int(d["chirp_loops"]),
            tx_order=tx_order, frame_period_s=float(d["frame_period_s"]),
            noise_level_db=float(d.get("noise_level_db", -75.0)), array=array,
            antennas=antennas,
            tx_index=tuple(int(t) for t in np.repeat(np.arange(n_tx), antennas.n_rx)),
            adc_start_s=adc_start, clock=clock,
            range_doppler_coupling=str(d.get("range_doppler_coupling", "kept")),
        )


def _check_aperture(doc: Document, spec: dict[str, list[float]], wavelength_m: float) -> None:
    """Refuse antennas whose virtual array is wider than `MAX_APERTURE_WAVELENGTHS`.

    The virtual array (every TX + RX) spans the TX group's spread plus the RX group's per axis.
    """
    for axis in ("y", "z"):
        spreads = {key: max(spec[key]) - min(spec[key])
                   for key in (f"tx_{axis}_m", f"rx_{axis}_m")}
        span = sum(spreads.values())
        if span <= MAX_APERTURE_WAVELENGTHS * wavelength_m:
            continue
        widest = max(spreads, key=lambda key: spreads[key])
        raise doc.error(
            ("array", widest),
            f"the virtual array spans {span:.3g} m along {axis} (the spread of tx_{axis}_m plus "
            f"that of rx_{axis}_m), {span / wavelength_m:.3g} wavelengths of "
            f"{wavelength_m * 1e3:.3g} mm; at most {MAX_APERTURE_WAVELENGTHS} wavelengths (the "
            f"estimator's angle grid grows with it): check the positions are in metres")


def preset_names() -> list[str]:
    """Names of the shipped radar profiles."""
    folder = resources.files("rts_scenario").joinpath("data/radars")
    return sorted(p.name.removesuffix(".radar.yaml") for p in folder.iterdir()
                  if p.name.endswith(".radar.yaml"))


_POSITIVE = {"type": "number", "exclusiveMinimum": 0}
_POSITIONS = {"type": "array", "minItems": 1, "items": {"type": "number"}}

PROFILE_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "required": ["rts_radar", "name", "fc_hz", "bandwidth_hz", "ramp_time_s", "idle_time_s",
                 "adc_samples", "sample_rate_hz", "chirp_loops", "tx_order", "frame_period_s",
                 "array"],
    "properties": {
        "rts_radar": {"enum": [1]},
        "name": {"type": "string", "minLength": 1},
        "description": {"type": "string"},
        # Radar bands from 1 to 300 GHz (automotive: 24, 77-81 GHz); beyond them the
        # estimator's angle grid, which grows with (aperture / wavelength)^2, would not fit.
        "fc_hz": {"type": "number", "minimum": 1e9, "maximum": 3e11},
        # A range resolution c0 / (2 bandwidth) from 150 m down to half a millimetre.
        "bandwidth_hz": {"type": "number", "minimum": 1e6, "maximum": 3e11},
        "ramp_time_s": _POSITIVE,
        "idle_time_s": {"type": "number", "minimum": 0},
        "adc_samples": {"type": "integer", "minimum": 2},
        "adc_start_s": {"type": "number", "minimum": 0},
        "sample_rate_hz": _POSITIVE,
        "chirp_loops": {"type": "integer", "minimum": 1},
        "tx_order": {"type": "array", "minItems": 1, "items": {"type": "integer", "minimum": 0}},
        "frame_period_s": _POSITIVE,
        "noise_level_db": {"type": "number", "minimum": -300, "maximum": 0},
        "range_doppler_coupling": {"enum": ["kept", "corrected"]},
        "clock": {
            "type": "object",
            "additionalProperties": False,
            "properties": {
                "cycle_s": {"type": "number", "minimum": MIN_CYCLE_S},
                "start_offset_s": {"type": "number", "minimum": 0},
                # Seconds from measuring to the bus: a radar's take some ms to a second.
                "latency_s": {"type": "number", "minimum": 0, "maximum": MAX_LATENCY_S},
                "jitter_s": {"type": "number", "minimum": 0},
                "counter_start": {"oneOf": [{"type": "integer", "minimum": 0},
                                            {"enum": ["auto"]}]},
            },
        },
        "array": {
            "oneOf": [
                {"enum": list(ANTENNA_PRESETS)},
                {
                    "type": "object",
                    "additionalProperties": False,
                    "required": ["tx_y_m", "tx_z_m", "rx_y_m", "rx_z_m"],
                    "properties": {k: _POSITIONS for k in ("tx_y_m", "tx_z_m", "rx_y_m",
                                                            "rx_z_m")},
                },
            ]
        },
    },
}

