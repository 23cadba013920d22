"""Trajectories of many objects, evaluated for all frames at once.

Every motion of the scene vocabulary compiles to the same three parts:

- a path: a polyline in 3-D with its cumulative arc length (a straight line for the simple
  motions; the waypoints' polyline; a dense sampling of a cubic spline with its exact tangents
  and curvature),
- a travel law: arc length over time, piecewise quadratic (constant acceleration per piece),
- lateral offsets: smooth lane changes (quintic in time) to the left of the path.

`TrajectorySet` stacks the parts of all objects into flat tables, so evaluating position,
velocity and acceleration for (frames x objects) is a handful of numpy operations with no Python
loop over frames or objects. Velocity and acceleration are analytic, not finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from ..lookup import piece_index

FloatArray = NDArray[np.float64]

# Spline paths are sampled at about this spacing (m), with at least SPLINE_MIN_SAMPLES per piece.
SPLINE_STEP_M = 0.25
SPLINE_MIN_SAMPLES = 16


@dataclass(frozen=True)
class Path:
    """A polyline with its arc length, tangents and curvature.

    Points (J, 3), cumulative arc length (J,), unit tangents at the points (J, 3) and the
    curvature of each piece (J - 1,). Beyond its ends it continues straight.
    """

    points: FloatArray
    arc_m: FloatArray
    tangents: FloatArray
    curvature: FloatArray

    @classmethod
    def line(cls, start: FloatArray, heading_rad: float) -> Path:
        """Straight line from ``start`` along a horizontal heading."""
        direction = np.array([np.cos(heading_rad), np.sin(heading_rad), 0.0])
        start = np.asarray(start, dtype=np.float64)
        return cls(points=np.stack([start, start + direction]), arc_m=np.array([0.0, 1.0]),
                   tangents=np.stack([direction, direction]), curvature=np.zeros(1))

    @classmethod
    def polyline(cls, points: FloatArray) -> Path:
        """Straight pieces between consecutive points (which must differ)."""
        chords = np.diff(points, axis=0)
        lengths = np.linalg.norm(chords, axis=1)
        directions = chords / lengths[:, None]
        # Tangent at a point: of the piece that starts there (the last point: of the last piece).
        tangents = np.vstack([directions, directions[-1:]])
        return cls(points=np.asarray(points, dtype=np.float64),
                   arc_m=np.concatenate([[0.0], np.cumsum(lengths)]), tangents=tangents,
                   curvature=np.zeros(len(chords)))

    @classmethod
    def spline(cls, points: FloatArray) -> tuple[Path, FloatArray]:
        """Sample a natural cubic spline through the points (chord-length parameter) densely.

        Returns the path and the arc length at each of the given points.
        """
        chords = np.linalg.norm(np.diff(points, axis=0), axis=1)
        knots = np.concatenate([[0.0], np.cumsum(chords)])
        curve = CubicSpline(knots, points, bc_type="natural")
        per_piece = np.maximum(SPLINE_MIN_SAMPLES, np.ceil(chords / SPLINE_STEP_M)).astype(int)
        params = np.concatenate(
            [np.linspace(a, b, n, endpoint=False) for a, b, n in
             zip(knots[:-1], knots[1:], per_piece, strict=True)] + [knots[-1:]]
        )
        samples = curve(params)
        d1 = curve(params, 1)
        d2 = curve(params, 2)
        speed = np.linalg.norm(d1, axis=1)
        tangents = d1 / speed[:, None]
        planar = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        kappa = planar / np.maximum(np.hypot(d1[:, 0], d1[:, 1]) ** 3, 1e-300)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(samples, axis=0), axis=1))])
        at_points = arc[np.searchsorted(params, knots)]
        return cls(points=samples, arc_m=arc, tangents=tangents,
                   curvature=0.5 * (kappa[:-1] + kappa[1:])), at_points


@dataclass(frozen=True)
class TravelLaw:
    """Arc length over time: from ``knots_s[k]`` on, ``s = s0 + v0 dt + a dt^2 / 2``.

    ``knots_s[0]`` is 0 (the scene start); the last piece lasts forever.
    """

    knots_s: FloatArray
    s0_m: FloatArray
    v0_mps: FloatArray
    a_mps2: FloatArray

    @classmethod
    def pieces(cls, knots_s: list[float], speeds_mps: list[float],
               accels_mps2: list[float]) -> TravelLaw:
        """Chain pieces given their start times, start speeds and accelerations."""
        s0 = [0.0]
        for k in range(1, len(knots_s)):
            dt = knots_s[k] - knots_s[k - 1]
            s0.append(s0[-1] + speeds_mps[k - 1] * dt + 0.5 * accels_mps2[k - 1] * dt * dt)
        return cls(knots_s=np.asarray(knots_s, float), s0_m=np.asarray(s0),
                   v0_mps=np.asarray(speeds_mps, float), a_mps2=np.asarray(accels_mps2, float))


@dataclass(frozen=True)
class LaneChange:
    """Lateral shift by ``offset_m`` (positive left) from ``start_s`` over ``duration_s``."""

    start_s: float
    duration_s: float
    offset_m: float


@dataclass(frozen=True)
class Trajectory:
    """One object's path, travel law and lane changes."""

    path: Path
    law: TravelLaw
    lane_changes: tuple[LaneChange, ...] = ()


@dataclass(frozen=True)
class Motion:
    """Position, velocity, acceleration (each ``(F, K, 3)``) and path tangent of K objects."""

    position_m: FloatArray
    velocity_mps: FloatArray
    acceleration_mps2: FloatArray
    tangent: FloatArray


class TrajectorySet:
    """Trajectories of K objects stacked for vectorized evaluation."""

    def __init__(self, trajectories: list[Trajectory]) -> None:
        self.count = len(trajectories)
        self._paths = [t.path for t in trajectories]
        self._laws = [t.law for t in trajectories]
        sizes = np.array([p.arc_m.size for p in self._paths])
        self._path_start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self._points = np.concatenate([p.points for p in self._paths])
        self._arc = np.concatenate([p.arc_m for p in self._paths])
        self._tangents = np.concatenate([p.tangents for p in self._paths])
        # Curvature per point (of the piece starting there; 0 after the last point).
        self._kappa = np.concatenate([np.append(p.curvature, 0.0) for p in self._paths])
        law_sizes = np.array([law.knots_s.size for law in self._laws])
        self._law_start = np.concatenate([[0], np.cumsum(law_sizes)[:-1]])
        self._knots = np.concatenate([law.knots_s for law in self._laws])
        self._s0 = np.concatenate([law.s0_m for law in self._laws])
        self._v0 = np.concatenate([law.v0_mps for law in self._laws])
        self._a = np.concatenate([law.a_mps2 for law in self._laws])
        width = max((len(t.lane_changes) for t in trajectories), default=0)
        self._lc = np.zeros((3, width, self.count))
        self._lc[1] = 1.0  # padding: zero offset over a unit duration
        for k, traj in enumerate(trajectories):
            for i, lc in enumerate(traj.lane_changes):
                self._lc[:, i, k] = (lc.start_s, lc.duration_s, lc.offset_m)

    def evaluate(self, t_s: FloatArray) -> Motion:
        """Evaluate all objects at times ``t_s`` (shape (F,)); arrays are ``(F, K, ...)``."""
        t = np.broadcast_to(np.asarray(t_s, dtype=np.float64)[:, None], (t_s.size, self.count))
        s, ds, dds = self._travel(t)
        # Paths have at least two points and the lookup stops one short of the end.
        j = piece_index([p.arc_m for p in self._paths], s) + self._path_start
        arc_j = self._arc[j]
        piece = self._arc[j + 1] - arc_j
        frac = np.clip((s - arc_j) / piece, 0.0, 1.0)[..., None]
        chord = (self._points[j + 1] - self._points[j]) / piece[..., None]
        base = self._points[j] + (s - arc_j)[..., None] * chord
        tangent = (1.0 - frac) * self._tangents[j] + frac * self._tangents[j + 1]
        tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
        kappa = self._kappa[j]
        normal = np.stack([-tangent[..., 1], tangent[..., 0], np.zeros_like(s)], axis=-1)
        normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
        lat, dlat, ddlat = self._lateral(t)
        # Frenet frame: dT/dt = kappa s' N and dN/dt = -kappa s' T (planar curvature).
        along = 1.0 - kappa * lat
        position = base + lat[..., None] * normal
        velocity = (ds * along)[..., None] * tangent + dlat[..., None] * normal
        accel_t = dds * along - 2.0 * kappa * ds * dlat
        accel_n = kappa * ds * ds * along + ddlat
        acceleration = accel_t[..., None] * tangent + accel_n[..., None] * normal
        return Motion(position_m=position, velocity_mps=velocity, acceleration_mps2=acceleration,
                      tangent=tangent)

    def _travel(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = piece_index([law.knots_s for law in self._laws], t) + self._law_start
        dt = t - self._knots[k]
        a = self._a[k]
        return self._s0[k] + self._v0[k] * dt + 0.5 * a * dt * dt, self._v0[k] + a * dt, a

    def _lateral(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        start, duration, offset = self._lc[:, None]  # each (1, width, K)
        tau = np.clip((t[:, None, :] - start) / duration, 0.0, 1.0)
        ramp = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
        slope = 30.0 * tau * tau * (1.0 - tau) ** 2 / duration
        bend = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / duration**2
        return ((offset * ramp).sum(axis=1), (offset * slope).sum(axis=1),
                (offset * bend).sum(axis=1))
