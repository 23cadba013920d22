"""From a scene to per-frame target parameters as the radar sees them.

World frame: x forward along the road, y left, z up. The ego's body yaws with its velocity
direction (against it while it drives backwards); the radar sits on the ego at its mount pose.
Every array is ``[frame, target]``; there is no Python loop over frames or targets.

Radial velocity is ``d(range)/dt`` computed from the analytic velocities of target and radar
(the radar's includes the ego's yaw rate acting on the mount lever arm), not by differencing.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from .propagation import C0_MPS
from .quads import assign_quads
from .rcs import rcs_series
from .scenario.model import Scenario
from .scenario.trajectory import Motion, TrajectorySet

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# Below this speed (m/s) a body keeps the heading of its path instead of its velocity's.
_STANDSTILL_MPS = 1e-6


@dataclass(frozen=True)
class Tracks:
    """Per-frame ground truth of every target, as seen by the radar.

    Attributes
    ----------
    names : tuple of str
        Target names (K).
    t_s : ndarray, shape (F,)
        Frame times.
    range_m, radial_velocity_mps, doppler_hz, rcs_dbsm, az_deg, el_deg : ndarray, shape (F, K)
        Range from the radar, range rate (> 0 receding), Doppler shift
        ``-2 v_r / wavelength``, RCS, azimuth (positive left), elevation (positive up).
    position_m : ndarray, shape (F, K, 3)
        Target position in the radar frame.
    present : ndarray of bool, shape (F, K)
        Between the target's appear and disappear times.
    in_coverage : ndarray of bool, shape (F, K)
        Inside a quad of the rig (its direction can be synthesized).
    in_range, in_velocity : ndarray of bool, shape (F, K)
        Within the radar's unambiguous range and radial velocity.
    max_range_m, max_radial_velocity_mps : float
        Those limits (infinite: none known). Beyond them the radar's FFTs fold an echo: its
        range into ``[0, max_range_m)``, its radial velocity into
        ``[-max_radial_velocity_mps, max_radial_velocity_mps)`` (`folded`).
    beat_m_per_hz : float
        How far the range spectrum shows an echo per Hz of Doppler, ``c0 / (2 S)`` (0: not
        known). The range FFT folds at the beat frequency ``S T - fD``, not at the range: an
        echo receding at 10 m/s on the awr1843boost folds 19 mm short of ``max_range_m``
        (`beat_range_m`).
    """

    names: tuple[str, ...]
    t_s: FloatArray
    range_m: FloatArray
    radial_velocity_mps: FloatArray
    doppler_hz: FloatArray
    rcs_dbsm: FloatArray
    az_deg: FloatArray
    el_deg: FloatArray
    position_m: FloatArray
    present: BoolArray
    in_coverage: BoolArray
    in_range: BoolArray
    in_velocity: BoolArray
    max_range_m: float = np.inf
    max_radial_velocity_mps: float = np.inf
    beat_m_per_hz: float = 0.0

    @property
    def checkable(self) -> BoolArray:
        """Present, synthesizable and unambiguous: frames a radar result can be checked on."""
        return self.present & self.in_coverage & self.in_range & self.in_velocity

    def take(self, rows: NDArray[np.intp] | NDArray[np.int64], t_s: FloatArray | None = None
             ) -> Tracks:
        """Return the frames ``rows`` (indices, repeats allowed), at times ``t_s`` if given."""
        out = {f.name: getattr(self, f.name)[rows] for f in fields(self)
               if f.name not in _SCALARS}
        if t_s is not None:
            out["t_s"] = np.asarray(t_s, dtype=np.float64)
        return Tracks(**{name: getattr(self, name) for name in _SCALARS}, **out)

    def beat_range_m(self) -> FloatArray:
        """Range where the radar's range FFT shows each echo: its beat frequency, in metres.

        ``range_m - doppler_hz * beat_m_per_hz``: a receding target farther, an approaching
        one nearer (the range-Doppler coupling of an up-chirp).
        """
        return self.range_m - self.doppler_hz * self.beat_m_per_hz

    def folded(self) -> tuple[FloatArray, FloatArray]:
        """Range and radial velocity as the radar's FFTs show them, shape (F, K) each.

        Within its unambiguous limits the truth; beyond them folded as `rts_scenario.radar`
        folds them (and as a real radar's circular FFTs do).
        """
        r_max, v_max = self.max_range_m, self.max_radial_velocity_mps
        # Folded by whole unambiguous ranges, as many as the beat frequency wrapped: a radar
        # that keeps the coupling reports it on top, as within the limits.
        range_m = self.range_m if not np.isfinite(r_max) else np.where(
            self.in_range, self.range_m,
            self.range_m - np.floor(self.beat_range_m() / r_max) * r_max)
        velocity = self.radial_velocity_mps if not np.isfinite(v_max) else np.where(
            self.in_velocity, self.radial_velocity_mps,
            np.mod(self.radial_velocity_mps + v_max, 2.0 * v_max) - v_max)
        return range_m, velocity


# Fields of `Tracks` that are not per frame.
_SCALARS = ("names", "max_range_m", "max_radial_velocity_mps", "beat_m_per_hz")


def _rotation_z(yaw: FloatArray) -> FloatArray:
    """Rotations about z, shape ``yaw.shape + (3, 3)``."""
    c, s = np.cos(yaw), np.sin(yaw)
    zero, one = np.zeros_like(yaw), np.ones_like(yaw)
    return np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1),
                     np.stack([zero, zero, one], -1)], -2)


def _body_yaw(v: FloatArray, tangent: FloatArray, moving: BoolArray) -> FloatArray:
    """Yaw of bodies with velocity ``v`` along paths with ``tangent`` (both ``(..., 3)``).

    A moving body faces its velocity, or against it where it drives backwards (against its
    path's direction: it still faces along the path); a standing one faces along its path.
    """
    along = np.arctan2(tangent[..., 1], tangent[..., 0])
    backwards = v[..., 0] * tangent[..., 0] + v[..., 1] * tangent[..., 1] < 0.0
    return np.where(moving, np.arctan2(v[..., 1], v[..., 0]) + np.where(backwards, np.pi, 0.0),
                    along)


def _heading(motion: Motion) -> tuple[FloatArray, FloatArray | None]:
    """Yaw of each body (velocity direction, or path tangent when standing) and its rate.

    The rate needs the motion's acceleration; without it it is None.
    """
    v, a = motion.velocity_mps, motion.acceleration_mps2
    speed2 = v[..., 0] ** 2 + v[..., 1] ** 2
    moving = speed2 > _STANDSTILL_MPS**2
    yaw = _body_yaw(v, motion.tangent, moving)
    if a is None:
        return yaw, None
    rate = np.where(moving, (v[..., 0] * a[..., 1] - v[..., 1] * a[..., 0])
                    / np.where(moving, speed2, 1.0), 0.0)
    return yaw, rate


def compute_tracks(scenario: Scenario, t_s: FloatArray | None = None,
                   frame_index: NDArray[np.int64] | None = None) -> Tracks:
    """Evaluate the scene at every frame: range, radial velocity, Doppler, RCS and angles.

    ``t_s`` evaluates at other times than the scene's frames (shape (F,)); ``frame_index``
    (shape (F,), default 0, 1, ...) numbers them for the RCS fluctuation, so a scene evaluated
    batch by batch equals the scene evaluated at once.
    """
    t = scenario.t_s if t_s is None else np.asarray(t_s, dtype=np.float64)
    frames = np.arange(t.size) if frame_index is None else np.asarray(frame_index)
    targets = scenario.targets
    ego = TrajectorySet([scenario.ego]).evaluate(t)
    ego_yaw, ego_rate = _heading(ego)
    assert ego_rate is not None
    ego_yaw, ego_rate = ego_yaw[:, 0], ego_rate[:, 0]
    ego_rot = _rotation_z(ego_yaw)  # (F, 3, 3): ego frame -> world
    omega = np.stack([np.zeros_like(ego_rate), np.zeros_like(ego_rate), ego_rate], -1)
    ego_p, ego_v = ego.position_m[:, 0], ego.velocity_mps[:, 0]

    lever = np.einsum("fij,j->fi", ego_rot, scenario.mount.position_m)
    radar_p = ego_p + lever
    radar_v = ego_v + np.cross(omega, lever)

    motion = TrajectorySet([tg.trajectory for tg in targets]).evaluate(t, acceleration=False)
    p, v = motion.position_m, motion.velocity_mps
    yaw, _ = _heading(motion)
    relative = np.array([tg.frame == "ego" for tg in targets])
    if relative.any():
        # Motions given in the moving ego frame: rotate and carry along with the ego.
        rel_p = np.einsum("fij,fkj->fki", ego_rot, p)
        rel_v = np.einsum("fij,fkj->fki", ego_rot, v) + np.cross(omega[:, None, :], rel_p)
        p = np.where(relative[None, :, None], ego_p[:, None, :] + rel_p, p)
        v = np.where(relative[None, :, None], ego_v[:, None, :] + rel_v, v)
        # A body faces where it drives in the world (a car falling back behind the ego still
        # drives forward); standing in the world, along its path, turned with the ego.
        moving = v[..., 0] ** 2 + v[..., 1] ** 2 > _STANDSTILL_MPS**2
        world_yaw = np.where(moving, np.arctan2(v[..., 1], v[..., 0]),
                             np.arctan2(motion.tangent[..., 1], motion.tangent[..., 0])
                             + ego_yaw[:, None])
        yaw = np.where(relative[None, :], world_yaw, yaw)

    line = p - radar_p[:, None, :]
    range_m = np.linalg.norm(line, axis=-1)
    safe_range = np.where(range_m > 0.0, range_m, 1.0)
    radial = np.einsum("fki,fki->fk", line, v - radar_v[:, None, :]) / safe_range

    # World -> radar frame: undo the ego yaw, then the mount rotation.
    to_radar = np.einsum("ij,fkj->fki", scenario.mount.rotation.T,
                         np.einsum("fji,fkj->fki", ego_rot, line))
    x, y, z = to_radar[..., 0], to_radar[..., 1], to_radar[..., 2]
    az = np.degrees(np.arctan2(y, x))
    el = np.degrees(np.arctan2(z, np.hypot(x, y)))

    # Aspect: where the radar lies as seen from the target's body (0: ahead of it).
    aspect = np.degrees(np.arctan2(-line[..., 1], -line[..., 0]) - yaw)
    rcs = rcs_series([tg.rcs for tg in targets], aspect, scenario.seed, frames)

    appear = np.array([tg.appear_s for tg in targets])
    disappear = np.array([tg.disappear_s for tg in targets])
    profile = scenario.radar
    doppler_hz = -2.0 * radial / profile.wavelength_m
    beat_m_per_hz = C0_MPS / (2.0 * profile.slope_hz_per_s)
    beat_range = range_m - doppler_hz * beat_m_per_hz
    return Tracks(
        names=tuple(tg.name for tg in targets),
        t_s=t,
        range_m=range_m,
        radial_velocity_mps=radial,
        doppler_hz=doppler_hz,
        rcs_dbsm=rcs,
        az_deg=az,
        el_deg=el,
        position_m=to_radar,
        present=(t[:, None] >= appear) & (t[:, None] < disappear),
        in_coverage=assign_quads(scenario.rig, az, el) >= 0,
        # The range FFT folds at the beat frequency (`Tracks.beat_range_m`).
        in_range=(beat_range >= 0.0) & (beat_range < profile.max_range_m),
        in_velocity=np.abs(radial) < profile.max_radial_velocity_mps,
        max_range_m=profile.max_range_m,
        max_radial_velocity_mps=profile.max_radial_velocity_mps,
        beat_m_per_hz=beat_m_per_hz,
    )
