"""RTS rigs: front ends (FE) placed in front of the radar, grouped into quads.

A rig is a grid of ``rows x columns`` FEs; every 2x2 cell is a quad. FE ``r * columns + c`` sits
in row ``r`` (row 0 lowest elevation) and column ``c`` (column 0 smallest azimuth). Inside a quad
the FE order is the paper's Table I order: 0 and 2 have the smaller azimuth, 1 and 3 the larger;
0 and 1 the lower elevation, 2 and 3 the higher.

FE directions and distances are measured from the radar's reference point (see
`rts_scenario.arrays.Antennas`). Each FE has a receive and a transmit antenna, offset from its
nominal point perpendicular to its line of sight (`Rig.rx_offset_m`, `Rig.tx_offset_m`), and the
rig says how its RTS delays the signal (`RtsDelayModel`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from .atomic import write_atomic
from .errors import RigError
from .file_kinds import load_kind
from .located_yaml import Document, load_yaml, validate

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# The coarsest phase shifter: one bit, 0 or 180 deg.
PHASE_STEP_MAX_DEG = 180.0


@dataclass(frozen=True)
class HardwareLimits:
    """What the RTS hardware can set, per channel.

    ``latency_s`` is the signal path's delay (subtracted from every echo's delay);
    ``update_latency_s`` is how long the RTS may take, after a schedule frame reaches it, to
    play it (transport and its own update): cycles the radar measures within it may still see
    the frame before (`rts_scenario.pipeline.CycleTruth`). ``delay_max_s`` is the longest delay
    a channel can set (None: no limit stated): a farther target is not played (``too_far``).
    ``phase_step_deg`` is the resolution of a channel's phase shifter (0: continuous), a whole
    number of steps per turn (an n-bit shifter: ``360 / 2**n``).
    """

    attenuation_min_db: float = 0.0
    attenuation_max_db: float = 120.0
    attenuation_step_db: float = 0.0
    delay_min_s: float = 0.0
    delay_max_s: float | None = None
    delay_step_s: float = 0.0
    phase_step_deg: float = 0.0
    latency_s: float = 0.0
    doppler_min_hz: float = -100e3
    doppler_max_hz: float = 100e3
    echoes_per_channel: int = 8
    update_rate_hz: float = 100.0
    update_latency_s: float = 0.0

    def __post_init__(self) -> None:
        for low, high in (("attenuation_min_db", "attenuation_max_db"),
                          ("doppler_min_hz", "doppler_max_hz")):
            if not getattr(self, low) < getattr(self, high):
                raise RigError(f"limits.{low}: must be below {high} = {getattr(self, high):g}, "
                               f"got {getattr(self, low):g}", key=f"limits.{low}")
        if self.delay_max_s is not None and not self.delay_max_s > self.delay_min_s:
            raise RigError(f"limits.delay_max_s: must be above delay_min_s = "
                           f"{self.delay_min_s:g}, got {self.delay_max_s:g}",
                           key="limits.delay_max_s")
        span = self.attenuation_max_db - self.attenuation_min_db
        if not 0.0 <= self.attenuation_step_db <= span:
            raise RigError(f"limits.attenuation_step_db: must be within 0 (continuous) .. "
                           f"{span:g} (attenuation_max_db - attenuation_min_db), got "
                           f"{self.attenuation_step_db:g}", key="limits.attenuation_step_db")
        step = self.phase_step_deg
        if not 0.0 <= step <= PHASE_STEP_MAX_DEG:
            raise RigError(f"limits.phase_step_deg: must be within 0 (continuous) .. "
                           f"{PHASE_STEP_MAX_DEG:g} (a 1-bit shifter), got {step:g}",
                           key="limits.phase_step_deg")
        if step > 0.0 and abs(360.0 / step - round(360.0 / step)) > 1e-6 * 360.0 / step:
            # A shifter's steps divide the turn; a datasheet's rounded LSB (5.6 for 5.625)
            # would put a gap at the wrap that no hardware has.
            turns = max(2, round(360.0 / step))
            raise RigError(f"limits.phase_step_deg: must divide 360 deg into whole steps "
                           f"(360 / 2**n for an n-bit shifter), got {step:g} "
                           f"({360.0 / step:.4g} steps per turn; the nearest that divides it: "
                           f"{360.0 / turns:g})", key="limits.phase_step_deg")
        if not self.update_rate_hz > 0.0:
            raise RigError(f"limits.update_rate_hz: must be > 0, got {self.update_rate_hz:g}",
                           key="limits.update_rate_hz")

    def attenuator_setting(self, attenuation_db: ArrayLike) -> NDArray[np.float64]:
        """Return what a channel's attenuator sets for ``attenuation_db``.

        The nearest of its steps (``attenuation_min_db + k attenuation_step_db``) within its
        range; NaN (a channel off) stays NaN.
        """
        att = np.clip(np.asarray(attenuation_db, dtype=np.float64), self.attenuation_min_db,
                      self.attenuation_max_db)
        step = self.attenuation_step_db
        if step > 0.0:
            top = np.floor((self.attenuation_max_db - self.attenuation_min_db) / step + 1e-9)
            att = self.attenuation_min_db + np.clip(
                np.round((att - self.attenuation_min_db) / step), 0.0, top) * step
        return att

    def phase_setting(self, phase_rad: ArrayLike) -> NDArray[np.float64]:
        """Return what a channel's phase shifter sets for ``phase_rad``, in rad.

        The nearest of its steps (``k phase_step_deg``) on the circle, wrapped to [-pi, pi)
        (a phase and the same phase a turn away set the same step; a phase half-way between two
        steps takes the upper one); continuous (only wrapped) without a step. NaN (a channel
        off) stays NaN.
        """
        phase = np.asarray(phase_rad, dtype=np.float64)
        step = self.phase_step_deg
        if step > 0.0:
            turns = round(360.0 / step)
            k = np.floor(np.mod(phase, 2.0 * np.pi) / (2.0 * np.pi) * turns + 0.5)
            phase = np.mod(k, turns) * (2.0 * np.pi / turns)
        out: NDArray[np.float64] = np.mod(phase + np.pi, 2.0 * np.pi) - np.pi
        return out


@dataclass(frozen=True)
class Reference:
    """Level calibration point: one FE at full weight gives ``attenuation_db`` for this target."""

    range_m: float = 10.0
    rcs_dbsm: float = 10.0
    attenuation_db: float = 40.0


DELAY_MODELS = ("if", "rf")


@dataclass(frozen=True)
class RtsDelayModel:
    """How the RTS delays the radar's signal, which decides the phase a delay adds.

    ``"if"`` (the paper's digital RTS): the signal is down-converted with a fixed LO, delayed
    at an intermediate frequency (``if_frequency_hz`` at the chirp's start frequency) and
    up-converted with the same LO, so a delay tau turns the echo's phase by ``2 pi f_if tau``
    while the air paths set the carrier phase. ``"rf"``: an RF delay line, tau turns the phase
    by ``2 pi f_carrier tau`` like an air path.
    """

    delay_model: str = "if"
    if_frequency_hz: float = 500.0e6

    def __post_init__(self) -> None:
        if self.delay_model not in DELAY_MODELS:
            raise RigError(f"rts.delay_model: must be one of {', '.join(DELAY_MODELS)}, got "
                           f"{self.delay_model!r}")
        if not (np.isfinite(self.if_frequency_hz) and self.if_frequency_hz > 0):
            raise RigError(f"rts.if_frequency_hz: must be finite and > 0, got "
                           f"{self.if_frequency_hz!r}")

    def delayed_frequency_hz(self, fc_hz: float) -> float:
        """Frequency of the delayed signal at the chirp's start frequency ``fc_hz``.

        The IF (``if_frequency_hz``) for a digital RTS, the carrier ``fc_hz`` for an RF delay
        line; both sweep with the chirp.
        """
        return self.if_frequency_hz if self.delay_model == "if" else float(fc_hz)


@dataclass(frozen=True, eq=False)
class Rig:
    """An RTS rig: FE directions and distances, calibration offsets, limits and quads.

    Attributes
    ----------
    az_deg, el_deg, distance_m : ndarray, shape (F,)
        FE directions as seen by the radar and their distances.
    cal_delay_s, cal_phase_deg, cal_gain_db : ndarray, shape (F,)
        Per-channel calibration offsets.
    rows, columns : int
        Grid shape; ``rows * columns == F``.
    quads : ndarray, shape (Q, 4)
        FE indices of every quad, paper order.
    seen : ndarray, shape (F, 3), or None
        Where a survey saw each FE alone: ``az_deg, el_deg, level_db`` (NaN: not seen).
    rx_offset_m, tx_offset_m : ndarray, shape (F, 2)
        Each FE's receive and transmit antenna relative to its nominal point, ``[dy, dz]``,
        perpendicular to its line of sight: ``dy`` along increasing azimuth
        ``(-sin az, cos az, 0)``, ``dz`` along increasing elevation
        ``(-sin el cos az, -sin el sin az, cos el)``.
    rts : RtsDelayModel
        How the RTS delays the signal (default: the paper's digital IF RTS at 500 MHz).
    description : str
        The file's free text about the rig (kept when the rig is written again).
    """

    name: str
    az_deg: FloatArray
    el_deg: FloatArray
    distance_m: FloatArray
    rows: int
    columns: int
    cal_delay_s: FloatArray
    cal_phase_deg: FloatArray
    cal_gain_db: FloatArray
    limits: HardwareLimits = HardwareLimits()
    reference: Reference = Reference()
    rx_offset_m: FloatArray = field(default_factory=lambda: np.zeros(2))
    tx_offset_m: FloatArray = field(default_factory=lambda: np.zeros(2))
    rts: RtsDelayModel = RtsDelayModel()
    seen: FloatArray | None = None
    description: str = ""

    def __post_init__(self) -> None:
        n = self.rows * self.columns
        if self.rows < 2 or self.columns < 2:
            raise RigError(f"a rig needs at least 2 x 2 FEs, got {self.rows} x {self.columns}")
        for name in ("az_deg", "el_deg", "distance_m", "cal_delay_s", "cal_phase_deg",
                     "cal_gain_db"):
            value = np.array(getattr(self, name), dtype=np.float64, ndmin=1)
            if value.size == 1 and n > 1:
                value = np.full(n, value.item())
            if value.shape != (n,):
                raise RigError(
                    f"{name}: needs one value per FE ({self.rows} x {self.columns} = {n}), "
                    f"got shape {value.shape}"
                )
            bad = ~np.isfinite(value)
            if bad.any():
                raise RigError(
                    f"{name}[{int(np.argmax(bad))}]: must be finite, got {value[bad][0]}"
                )
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        for name in ("rx_offset_m", "tx_offset_m"):
            value = np.array(getattr(self, name), dtype=np.float64, ndmin=1)
            if value.shape == (2,):
                value = np.tile(value, (n, 1))
            if value.shape != (n, 2):
                raise RigError(f"{name}: needs [dy, dz] for all FEs or one per FE ({n}), got "
                               f"shape {value.shape}")
            if not np.all(np.isfinite(value)):
                raise RigError(f"{name}: offsets must be finite")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.seen is not None:
            seen = np.array(self.seen, dtype=np.float64)
            if seen.shape != (n, 3):
                raise RigError(f"seen: needs [az_deg, el_deg, level_db] per FE ({n}), got shape "
                               f"{seen.shape}")
            seen.setflags(write=False)
            object.__setattr__(self, "seen", seen)
        if np.any(self.distance_m <= 0):
            raise RigError(f"distance_m: must be > 0, got {self.distance_m.min()}")
        if np.any(np.abs(self.az_deg) >= 90) or np.any(np.abs(self.el_deg) > 90):
            raise RigError(
                "az_deg, el_deg: FEs must lie in front of the radar (|az| < 90, |el| <= 90)"
            )
        grid_az = self.az_deg.reshape(self.rows, self.columns)
        grid_el = self.el_deg.reshape(self.rows, self.columns)
        if np.any(np.diff(grid_az, axis=1) < 0):
            r, c = np.argwhere(np.diff(grid_az, axis=1) < 0)[0]
            raise RigError(
                f"az_deg: FEs must be ordered by increasing azimuth within a row "
                f"(paper order: FE 0 and 2 smaller azimuth than 1 and 3); row {r}: column {c} "
                f"at {grid_az[r, c]:g} deg, column {c + 1} at {grid_az[r, c + 1]:g} deg",
                key="az_deg", fe=int(r * self.columns + c + 1),
            )
        if np.any(np.diff(grid_el, axis=0) < 0):
            r, c = np.argwhere(np.diff(grid_el, axis=0) < 0)[0]
            raise RigError(
                f"el_deg: FEs must be ordered by increasing elevation between rows "
                f"(paper order: FE 0 and 1 lower than 2 and 3); column {c}: row {r} at "
                f"{grid_el[r, c]:g} deg, row {r + 1} at {grid_el[r + 1, c]:g} deg",
                key="el_deg", fe=int((r + 1) * self.columns + c),
            )

    @property
    def n_front_ends(self) -> int:
        """Number of FEs F."""
        return self.rows * self.columns

    @property
    def quads(self) -> IntArray:
        """FE indices of every 2x2 cell, shape ``(Q, 4)``, paper order, row-major cells."""
        r, c = np.meshgrid(np.arange(self.rows - 1), np.arange(self.columns - 1), indexing="ij")
        base = (r * self.columns + c).ravel()
        return np.stack([base, base + 1, base + self.columns, base + self.columns + 1], axis=1)

    @property
    def key(self) -> tuple[Any, ...]:
        """Hashable identity of the FE geometry, used to cache per-rig precomputation."""
        return (self.az_deg.tobytes(), self.el_deg.tobytes(), self.rows, self.columns)

    def geometry_digest(self) -> bytes:
        """SHA-256 of the FEs' geometry (32 bytes): grid, directions, distances, antennas.

        What an RTS and a run must share for the echoes to come from where the schedule puts
        them (calibration offsets and limits are left out: they are the channels', not the
        geometry's). Values rounded to 1e-9 (a rig written to a file and read back keeps it).
        """
        import hashlib

        digest = hashlib.sha256(np.array([self.rows, self.columns], dtype="<i8").tobytes())
        for values in (self.az_deg, self.el_deg, self.distance_m, self.rx_offset_m,
                       self.tx_offset_m):
            rounded = np.round(np.broadcast_to(np.asarray(values, dtype=np.float64),
                                               np.shape(values)), 9) + 0.0  # no -0.0
            digest.update(rounded.astype("<f8").tobytes())
        return digest.digest()

    def played_digest(self) -> str:
        """Return the SHA-256 (hex) of all a schedule depends on of the rig.

        That is `geometry_digest`, each FE's calibration, the hardware limits, the reference
        and the RTS's delay model (not the name). A recording keeps it (its sidecar's
        ``rig``): a log is re-checked only against the rig it was played on, since another
        calibration or limits play other levels and statuses.
        """
        import hashlib
        from dataclasses import astuple

        digest = hashlib.sha256(self.geometry_digest())
        for values in (self.cal_delay_s, self.cal_phase_deg, self.cal_gain_db):
            rounded = np.round(np.asarray(values, dtype=np.float64), 12) + 0.0  # no -0.0
            digest.update(rounded.astype("<f8").tobytes())
        for part in (self.limits, self.reference, self.rts):
            digest.update(repr(astuple(part)).encode())
        return digest.hexdigest()

    @classmethod
    def from_angles(
        cls,
        az_deg: ArrayLike,
        el_deg: ArrayLike,
        distance_m: ArrayLike = 1.0,
        *,
        name: str = "custom",
        **kwargs: Any,
    ) -> Rig:
        """Build one quad of four FEs given in the paper's order (Table I)."""
        az = np.array(az_deg, dtype=np.float64, ndmin=1)
        el = np.array(el_deg, dtype=np.float64, ndmin=1)
        if az.shape != (4,) or el.shape != (4,):
            raise RigError(
                f"from_angles: needs exactly 4 azimuths and 4 elevations (paper order), got "
                f"{az.size} and {el.size}; use Rig.grid for more FEs"
            )
        return cls.grid(az.reshape(2, 2), el.reshape(2, 2), distance_m, name=name, **kwargs)

    @classmethod
    def grid(
        cls,
        az_deg: ArrayLike,
        el_deg: ArrayLike,
        distance_m: ArrayLike = 1.0,
        *,
        name: str = "custom",
        cal_delay_s: ArrayLike = 0.0,
        cal_phase_deg: ArrayLike = 0.0,
        cal_gain_db: ArrayLike = 0.0,
        limits: HardwareLimits | None = None,
        reference: Reference | None = None,
        rx_offset_m: ArrayLike = (0.0, 0.0),
        tx_offset_m: ArrayLike = (0.0, 0.0),
        rts: RtsDelayModel | None = None,
    ) -> Rig:
        """Build a grid rig from ``(rows, columns)`` arrays of FE angles (row 0 lowest).

        1-D inputs are the column azimuths and the row elevations of a regular grid. FE antenna
        offsets are ``[dy, dz]`` for all FEs or one row per FE (row-major FE order).
        """
        az = np.asarray(az_deg, dtype=np.float64)
        el = np.asarray(el_deg, dtype=np.float64)
        if az.ndim == 1 and el.ndim == 1:
            az, el = np.meshgrid(az, el)
        if az.ndim != 2 or az.shape != el.shape:
            raise RigError(
                f"grid: az_deg and el_deg must both be (rows, columns) or 1-D (columns; rows), "
                f"got shapes {az.shape} and {el.shape}"
            )
        rows, columns = az.shape
        return cls(
            name=name, az_deg=az.ravel(), el_deg=el.ravel(),
            distance_m=np.asarray(distance_m, dtype=np.float64), rows=rows, columns=columns,
            cal_delay_s=np.asarray(cal_delay_s, dtype=np.float64),
            cal_phase_deg=np.asarray(cal_phase_deg, dtype=np.float64),
            cal_gain_db=np.asarray(cal_gain_db, dtype=np.float64),
            limits=limits or HardwareLimits(), reference=reference or Reference(),
            rx_offset_m=np.asarray(rx_offset_m, dtype=np.float64),
            tx_offset_m=np.asarray(tx_offset_m, dtype=np.float64), rts=rts or RtsDelayModel(),
        )

    @classmethod
    def preset(cls, name: str) -> Rig:
        """Return a shipped rig: see `preset_names`."""
        names = preset_names()
        if name not in names:
            raise RigError(f"unknown rig preset {name!r}; valid presets: {', '.join(names)}")
        text = resources.files("rts_scenario").joinpath(f"data/rigs/{name}.rig.yaml").read_text()
        return cls.from_document(load_yaml(f"<preset {name}>", text))

    @classmethod
    def from_file(cls, path: str | Path) -> Rig:
        """Load a ``*.rig.yaml`` file (format: see ``scenarios/rigs/README.md``)."""
        return cls.from_document(load_kind(path, ".rig.yaml"))

    @classmethod
    def from_document(cls, doc: Document) -> Rig:
        """Build a rig from a loaded YAML document, with located errors."""
        validate(doc, RIG_SCHEMA)
        data = doc.data
        fes = data.get("front_ends")
        layout = data.get("layout")
        if (fes is None) == (layout is None):
            raise doc.error((), "give exactly one of 'front_ends' (list) or 'layout' (grid)")
        distance = data.get("distance_m", 1.0)
        if layout is not None:
            az = np.array(layout["az_deg"], dtype=np.float64)
            el = np.array(layout["el_deg"], dtype=np.float64)
            rows, columns = el.size, az.size
            az_grid, el_grid = (g.ravel() for g in np.meshgrid(az, el))
            dist = np.full(rows * columns, float(distance))
            cal = {k: np.zeros(rows * columns) for k in ("delay_s", "phase_deg", "gain_db")}
            offsets = {k: np.zeros((rows * columns, 2)) for k in ("rx_offset_m", "tx_offset_m")}
            seen = None
        else:
            rows = data.get("rows", 2)
            columns = data.get("columns", len(fes) // rows if rows else 0)
            if rows * columns != len(fes):
                raise doc.error(
                    ("front_ends",),
                    f"needs rows x columns = {rows} x {columns} = {rows * columns} FEs, "
                    f"got {len(fes)}",
                )
            az_grid = np.array([fe["az_deg"] for fe in fes], dtype=np.float64)
            el_grid = np.array([fe["el_deg"] for fe in fes], dtype=np.float64)
            dist = np.array([fe.get("distance_m", distance) for fe in fes], dtype=np.float64)
            cal = {
                k: np.array([fe.get("calibration", {}).get(k, 0.0) for fe in fes], dtype=float)
                for k in ("delay_s", "phase_deg", "gain_db")
            }
            offsets = {k: np.array([fe.get(k, (0.0, 0.0)) for fe in fes], dtype=float)
                       for k in ("rx_offset_m", "tx_offset_m")}
            seen = None
            if any("seen" in fe for fe in fes):
                seen = np.array([[fe.get("seen", {}).get(k, np.nan) for k in SEEN_KEYS]
                                 for fe in fes], dtype=float)
        rts = data.get("rts", {})
        try:
            delay_model = RtsDelayModel(
                delay_model=rts.get("delay_model", "if"),
                if_frequency_hz=float(rts.get("if_frequency_hz", 500.0e6)))
        except RigError as exc:
            raise doc.error(("rts",), str(exc)) from None
        try:
            limits = HardwareLimits(**data.get("limits", {}))
        except RigError as exc:
            key = tuple((exc.key or "limits").split("."))
            raise doc.error(key, str(exc).removeprefix(f"{exc.key}: ")) from None
        reference = Reference(**data.get("reference", {}))
        # The reference is the level the bench was measured at, and survey and calibrate play
        # every FE at it: a level the RTS cannot set is a typing mistake, and played anyway it
        # gives numbers that look like a measurement.
        if not (limits.attenuation_min_db <= reference.attenuation_db
                <= limits.attenuation_max_db):
            allowed = (f"the RTS's attenuation limits {limits.attenuation_min_db:g}.."
                       f"{limits.attenuation_max_db:g} dB")
            if "attenuation_db" in data.get("reference", {}):
                raise doc.error(("reference", "attenuation_db"),
                                f"must be within {allowed}, got {reference.attenuation_db:g}")
            bound = ("attenuation_max_db" if reference.attenuation_db
                     > limits.attenuation_max_db else "attenuation_min_db")
            raise doc.error(("limits", bound),
                            f"the default reference.attenuation_db = "
                            f"{reference.attenuation_db:g} dB is outside {allowed}; give "
                            f"reference.attenuation_db (the level the bench was measured at)")
        _check_distinct_directions(doc, az_grid, el_grid, columns, layout is not None)
        try:
            return cls(
                name=data["name"], az_deg=az_grid, el_deg=el_grid, distance_m=dist, rows=rows,
                columns=columns, cal_delay_s=cal["delay_s"], cal_phase_deg=cal["phase_deg"],
                cal_gain_db=cal["gain_db"], limits=limits, reference=reference,
                rx_offset_m=offsets["rx_offset_m"], tx_offset_m=offsets["tx_offset_m"],
                rts=delay_model, seen=seen, description=data.get("description", ""),
            )
        except RigError as exc:
            message = str(exc).removeprefix(f"{exc.key}: ") if exc.fe is not None else str(exc)
            raise doc.error(_fe_key(exc, layout is not None, columns), message) from None


    def to_document(self) -> dict[str, Any]:
        """Return the rig as ``*.rig.yaml`` data: every FE, its calibration, offsets, survey."""
        fes = []
        for i in range(self.n_front_ends):  # one entry per FE
            fe: dict[str, Any] = {
                "az_deg": float(self.az_deg[i]), "el_deg": float(self.el_deg[i]),
                "distance_m": float(self.distance_m[i]),
                "calibration": {"delay_s": float(self.cal_delay_s[i]),
                                "phase_deg": round(float(self.cal_phase_deg[i]), 4),
                                "gain_db": round(float(self.cal_gain_db[i]), 4)}}
            for name in ("rx_offset_m", "tx_offset_m"):
                offset = getattr(self, name)[i]
                if np.any(offset != 0.0):
                    fe[name] = [float(v) for v in offset]
            if self.seen is not None and np.isfinite(self.seen[i]).any():
                fe["seen"] = {k: round(float(v), 5) for k, v in zip(SEEN_KEYS, self.seen[i],
                                                                      strict=True)
                              if np.isfinite(v)}
            fes.append(fe)
        described = {"description": self.description} if self.description else {}
        return {"rts_rig": 1, "name": self.name, **described, "rows": self.rows,
                "columns": self.columns, "front_ends": fes, "rts": asdict(self.rts),
                "limits": {k: v for k, v in asdict(self.limits).items() if v is not None},
                "reference": asdict(self.reference)}

    def write(self, path: str | Path) -> None:
        """Write the rig as a ``*.rig.yaml`` file (`from_file` reads it back), replaced whole."""
        write_atomic(path, yaml.safe_dump(self.to_document(), sort_keys=False, width=100))


def _fe_key(exc: RigError, layout: bool, columns: int) -> tuple[str | int, ...]:
    """Where in a rig file the FE an error names is: its entry, or its layout row or column."""
    if exc.fe is None or exc.key not in ("az_deg", "el_deg"):
        return ("layout",) if layout else ("front_ends",)
    if not layout:
        return ("front_ends", exc.fe, exc.key)
    return ("layout", exc.key, exc.fe % columns if exc.key == "az_deg" else exc.fe // columns)


def _check_distinct_directions(doc: Document, az_deg: FloatArray, el_deg: FloatArray,
                               columns: int, layout: bool) -> None:
    """Refuse a rig file with two FEs in one direction.

    No bench has two FE antennas in one place: such a file is a typing or copying mistake, and
    its quads would fail every target as if the radar missed it. (`Rig` itself accepts
    degenerate quads, whose FEs share an azimuth or an elevation; the solver flags them.)
    """
    same = np.triu((az_deg[:, None] == az_deg) & (el_deg[:, None] == el_deg), k=1)
    if not same.any():
        return
    first, second = (int(i) for i in np.argwhere(same)[0])
    where = (f"az_deg {az_deg[first]:g}, el_deg {el_deg[first]:g}; every FE needs its own "
             f"direction")
    if not layout:
        raise doc.error(("front_ends", second),
                        f"FE {second} is in the same direction as FE {first} ({where})")
    if first % columns != second % columns:
        raise doc.error(("layout", "az_deg", second % columns),
                        f"column {second % columns} repeats the azimuth of column "
                        f"{first % columns} ({where})")
    raise doc.error(("layout", "el_deg", second // columns),
                    f"row {second // columns} repeats the elevation of row "
                    f"{first // columns} ({where})")


# What a survey stores per FE: where the radar saw it alone and its level (`rts_scenario.survey`).
SEEN_KEYS = ("az_deg", "el_deg", "level_db")


def preset_names() -> list[str]:
    """Names of the shipped rig presets."""
    folder = resources.files("rts_scenario").joinpath("data/rigs")
    return sorted(p.name.removesuffix(".rig.yaml") for p in folder.iterdir()
                  if p.name.endswith(".rig.yaml"))


def _number(minimum: float | None = None, exclusive: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "number"}
    if minimum is not None:
        out["exclusiveMinimum" if exclusive else "minimum"] = minimum
    return out


_ANGLE = {"type": "number", "minimum": -90, "maximum": 90}
# Bounds of a bench, wide enough for any real one: values beyond them are typing mistakes that
# would otherwise play (or survey) nonsense without a word. An FE's antennas sit on the FE.
_OFFSET = {"type": "array", "minItems": 2, "maxItems": 2,
           "items": {"type": "number", "minimum": -1.0, "maximum": 1.0}}
_DISTANCE = {"type": "number", "exclusiveMinimum": 0, "maximum": 100.0}
# The RTS's limits, as wide: delays and latencies up to a second (150,000 km of range),
# attenuation within 0..300 dB, a phase step up to half a turn (1 bit), Doppler within +-1 GHz,
# updates up to 1 MHz, 1024 echoes.
_LIMIT_BOUNDS: dict[str, tuple[float, float]] = {
    "attenuation_min_db": (0.0, 300.0), "attenuation_max_db": (0.0, 300.0),
    "attenuation_step_db": (0.0, 300.0), "delay_min_s": (0.0, 1.0), "delay_max_s": (0.0, 1.0),
    "delay_step_s": (0.0, 1.0), "phase_step_deg": (0.0, PHASE_STEP_MAX_DEG),
    "latency_s": (0.0, 1.0), "doppler_min_hz": (-1e9, 1e9),
    "doppler_max_hz": (-1e9, 1e9), "echoes_per_channel": (1, 1024),
    "update_rate_hz": (0.0, 1e6), "update_latency_s": (0.0, 1.0),
}
# Cable and path differences: 1 us is 150 m of range.
_CAL_DELAY = {"type": "number", "minimum": -1e-6, "maximum": 1e-6}
_CAL_GAIN = {"type": "number", "minimum": -60.0, "maximum": 60.0}
# A phase offset within one turn either way (`calibrate` writes them within -180..180).
_CAL_PHASE = {"type": "number", "minimum": -360, "maximum": 360}
# A surveyed level: a difference of detected levels in dB.
_SEEN_LEVEL = {"type": "number", "minimum": -200, "maximum": 200}
# The level reference: a target as far and as large as a scene's may be (positions within
# 100 km, RCS within +-60 dBsm).
_REFERENCE_RANGE = {"type": "number", "exclusiveMinimum": 0, "maximum": 100000}
_REFERENCE_RCS = {"type": "number", "minimum": -60, "maximum": 60}

RIG_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "required": ["rts_rig", "name"],
    "properties": {
        "rts_rig": {"enum": [1]},
        "name": {"type": "string", "minLength": 1},
        "description": {"type": "string"},
        "distance_m": _DISTANCE,
        "rows": {"type": "integer", "minimum": 2},
        "columns": {"type": "integer", "minimum": 2},
        "front_ends": {
            "type": "array",
            "minItems": 4,
            "items": {
                "type": "object",
                "additionalProperties": False,
                "required": ["az_deg", "el_deg"],
                "properties": {
                    "az_deg": _ANGLE,
                    "el_deg": _ANGLE,
                    "distance_m": _DISTANCE,
                    "rx_offset_m": _OFFSET,
                    "tx_offset_m": _OFFSET,
                    "calibration": {
                        "type": "object",
                        "additionalProperties": False,
                        "properties": {
                            "delay_s": _CAL_DELAY,
                            "phase_deg": _CAL_PHASE,
                            "gain_db": _CAL_GAIN,
                        },
                    },
                    "seen": {
                        "type": "object",
                        "additionalProperties": False,
                        "properties": {"az_deg": _ANGLE, "el_deg": _ANGLE,
                                       "level_db": _SEEN_LEVEL},
                    },
                },
            },
        },
        "layout": {
            "type": "object",
            "additionalProperties": False,
            "required": ["az_deg", "el_deg"],
            "properties": {
                "az_deg": {"type": "array", "minItems": 2, "items": _ANGLE},
                "el_deg": {"type": "array", "minItems": 2, "items": _ANGLE},
            },
        },
        "limits": {
            "type": "object",
            "additionalProperties": False,
            "properties": {
                f.name: {"type": "integer" if f.name == "echoes_per_channel" else "number",
                         "minimum": _LIMIT_BOUNDS[f.name][0],
                         "maximum": _LIMIT_BOUNDS[f.name][1]}
                for f in fields(HardwareLimits)
            },
        },
        "rts": {
            "type": "object",
            "additionalProperties": False,
            "properties": {
                "delay_model": {"enum": list(DELAY_MODELS)},
                "if_frequency_hz": _number(0, exclusive=True),
            },
        },
        "reference": {
            "type": "object",
            "additionalProperties": False,
            "properties": {
                "range_m": _REFERENCE_RANGE,
                "rcs_dbsm": _REFERENCE_RCS,
                "attenuation_db": {"type": "number"},  # within limits: Rig checks it
            },
        },
    },
}

__all__ = ["DELAY_MODELS", "RIG_SCHEMA", "HardwareLimits", "Reference", "Rig", "RtsDelayModel",
           "preset_names"]
