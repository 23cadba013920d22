"""Trajectories of many objects, evaluated for all frames at once.

Every motion of the scene vocabulary compiles to the same three parts:

- a path: points in 3-D with their cumulative arc length and the tangents at both ends of
  each piece (a straight line for the simple motions; the waypoints' polyline; a dense
  sampling of a cubic spline with its exact tangents, split into one spline per stretch where
  the path reverses), cubic Hermite between the points, and the way the body faces on each
  piece (along the direction of travel, or against it while it backs out after a reversal),
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

from ..piecewise import piece_index

FloatArray = NDArray[np.float64]

# Spline paths are sampled at about this spacing (m), with at least SPLINE_MIN_SAMPLES per piece.
SPLINE_STEP_M = 0.25
SPLINE_MIN_SAMPLES = 16

# A spline path reverses (has a cusp) at a waypoint where its direction turns by more than this
# (deg): the angle between the chord arriving at the waypoint and the chord leaving it.
REVERSAL_DEG = 90.0


def reversal_waypoints(points: FloatArray) -> list[int]:
    """Return the inner waypoints (indices) where a spline path reverses.

    There the path turns by more than `REVERSAL_DEG`.
    """
    chords = np.diff(np.asarray(points, dtype=np.float64), axis=0)
    cos = (chords[:-1] * chords[1:]).sum(axis=1) / (
        np.linalg.norm(chords[:-1], axis=1) * np.linalg.norm(chords[1:], axis=1))
    # A hair above the limit: a right angle stays a turn when its cosine rounds below 0.
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return [int(i) + 1 for i in np.flatnonzero(angle > REVERSAL_DEG + 1e-9)]


@dataclass(frozen=True)
class Path:
    """Points (J, 3), their cumulative arc length (J,) and unit tangents per piece.

    ``tangent_start`` and ``tangent_end`` (J - 1, 3) are the directions of travel at both ends
    of each piece. Between points the path is the cubic Hermite curve matching points and
    tangents (a straight piece when both point along it); beyond its ends it continues
    straight. ``facing`` (J - 1,) is +1 where the body faces its direction of travel and -1
    where it faces against it (backing out after a reversal).
    """

    points: FloatArray
    arc_m: FloatArray
    tangent_start: FloatArray
    tangent_end: FloatArray
    facing: FloatArray

    @classmethod
    def line(cls, start: FloatArray, heading_rad: float) -> Path:
        """Straight line from ``start`` along a horizontal heading."""
        direction = np.array([np.cos(heading_rad), np.sin(heading_rad), 0.0])
        start = np.asarray(start, dtype=np.float64)
        return cls(points=np.stack([start, start + direction]), arc_m=np.array([0.0, 1.0]),
                   tangent_start=direction[None], tangent_end=direction[None],
                   facing=np.ones(1))

    @classmethod
    def polyline(cls, points: FloatArray) -> Path:
        """Straight pieces between consecutive points (which must differ)."""
        chords = np.diff(points, axis=0)
        lengths = np.linalg.norm(chords, axis=1)
        directions = chords / lengths[:, None]
        return cls(points=np.asarray(points, dtype=np.float64),
                   arc_m=np.concatenate([[0.0], np.cumsum(lengths)]),
                   tangent_start=directions, tangent_end=directions,
                   facing=np.ones(len(directions)))

    @classmethod
    def spline(cls, points: FloatArray) -> tuple[Path, FloatArray]:
        """Sample cubic splines through the points (chord-length parameter) densely.

        Without a reversal (`reversal_waypoints`) this is one natural cubic spline through all
        points. A reversal waypoint is a cusp: the path stops there and doubles back. It splits
        the path into stretches, each its own cubic spline (natural at the path's ends), which
        meet at the cusp on one line: the bisector of the chord arriving and the reversed chord
        leaving, along which the stretch before arrives and the stretch after leaves, the
        other way. The body keeps facing the same way through a cusp: it faces its direction
        of travel on the first stretch, against it on the second (backing out), and so on.

        Returns the path and the arc length at each of the given points.
        """
        points = np.asarray(points, dtype=np.float64)
        cusps = reversal_waypoints(points)
        bounds = [0, *cusps, len(points) - 1]
        lines = {}
        for i in cusps:
            arrive = points[i] - points[i - 1]
            leave = points[i + 1] - points[i]
            bisector = arrive / np.linalg.norm(arrive) - leave / np.linalg.norm(leave)
            lines[i] = bisector / np.linalg.norm(bisector)
        samples, tangents, arc, facing, at_points = [], [], [], [], [np.zeros(1)]
        start_arc = 0.0
        for n, (first, last) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
            stretch = points[first:last + 1]
            start_bc = (1, -lines[first]) if first in lines else (2, np.zeros(3))
            end_bc = (1, lines[last]) if last in lines else (2, np.zeros(3))
            p, d1, s, s_at = _sample_spline(stretch, start_bc, end_bc)
            skip = 1 if n else 0  # the cusp's sample ends one stretch and starts the next
            samples.append(p[skip:])
            tangents.append((d1[:-1], d1[1:]))
            arc.append(start_arc + s[skip:])
            facing.append(np.full(len(p) - 1, 1.0 if n % 2 == 0 else -1.0))
            at_points.append(start_arc + s_at[1:])
            start_arc += s[-1]
        return cls(points=np.concatenate(samples), arc_m=np.concatenate(arc),
                   tangent_start=np.concatenate([t[0] for t in tangents]),
                   tangent_end=np.concatenate([t[1] for t in tangents]),
                   facing=np.concatenate(facing)), np.concatenate(at_points)


def _sample_spline(
    points: FloatArray, start_bc: tuple[int, FloatArray], end_bc: tuple[int, FloatArray]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Sample a cubic spline through ``points`` (chord-length parameter) with the end conditions.

    Returns the samples, their unit tangents, their cumulative arc length and the arc length at
    each of the points.
    """
    chords = np.linalg.norm(np.diff(points, axis=0), axis=1)
    knots = np.concatenate([[0.0], np.cumsum(chords)])
    from scipy.interpolate import CubicSpline  # scipy when needed: see `check._assign`

    curve = CubicSpline(knots, points, bc_type=(start_bc, end_bc))
    per_piece = np.maximum(SPLINE_MIN_SAMPLES, np.ceil(chords / SPLINE_STEP_M)).astype(int)
    params = np.concatenate(
        [np.linspace(a, b, n, endpoint=False) for a, b, n in
         zip(knots[:-1], knots[1:], per_piece, strict=True)] + [knots[-1:]]
    )
    samples = curve(params)
    d1 = curve(params, 1)
    tangents = d1 / np.linalg.norm(d1, axis=1)[:, None]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(samples, axis=0), axis=1))])
    return samples, tangents, arc, arc[np.searchsorted(params, knots)]


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

    @classmethod
    def speed_profile(cls, times_s: list[float], speeds_mps: list[float]) -> TravelLaw:
        """Speed linear between points at increasing times, constant before and after them."""
        knots, v0, acc = [0.0], [speeds_mps[0]], [0.0]
        for i, t in enumerate(times_s):
            nxt = ((speeds_mps[i + 1] - speeds_mps[i]) / (times_s[i + 1] - t)
                   if i + 1 < len(times_s) else 0.0)
            if t == 0.0:
                acc[0] = nxt
            else:
                knots.append(t)
                v0.append(speeds_mps[i])
                acc.append(nxt)
        return cls.pieces(knots, v0, acc)


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
    """Position, velocity, acceleration (each ``(F, K, 3)``) and path tangent of K objects.

    ``tangent`` is the unit direction the body faces along its path: the direction of travel,
    or against it while it backs out after a reversal of a spline path.
    """

    position_m: FloatArray
    velocity_mps: FloatArray
    acceleration_mps2: FloatArray | None
    tangent: FloatArray


class TrajectorySet:
    """Trajectories of K objects stacked for vectorized evaluation."""

    def __init__(self, trajectories: list[Trajectory]) -> None:
        self.count = len(trajectories)
        if not trajectories:  # an empty scene: tables of one dummy object, never evaluated
            trajectories = [Trajectory(Path.line(np.zeros(3), 0.0),
                                       TravelLaw.pieces([0.0], [0.0], [0.0]))]
        self._paths = [t.path for t in trajectories]
        self._laws = [t.law for t in trajectories]
        sizes = np.array([p.arc_m.size for p in self._paths])
        self._path_start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self._points = np.concatenate([p.points for p in self._paths])
        self._arc = np.concatenate([p.arc_m for p in self._paths])
        self._piece_start = self._path_start - np.arange(self.count)
        self._tangent_start = np.concatenate([p.tangent_start for p in self._paths])
        self._tangent_end = np.concatenate([p.tangent_end for p in self._paths])
        self._facing = np.concatenate([p.facing for p in self._paths])
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

    def evaluate(self, t_s: FloatArray, acceleration: bool = True) -> Motion:
        """Evaluate all objects at times ``t_s`` (shape (F,)); arrays are ``(F, K, ...)``.

        Without ``acceleration`` the motion's acceleration is left out (None), which saves the
        path's third derivative.
        """
        if self.count == 0:
            empty = np.zeros((np.size(t_s), 0, 3))
            return Motion(empty, empty, empty if acceleration else None, empty)
        t = np.broadcast_to(np.asarray(t_s, dtype=np.float64)[:, None], (t_s.size, self.count))
        s, ds, dds = self._travel(t)
        g, g1, g2, g3, facing = self._path(s, third=acceleration)
        lat, dlat, ddlat = self._lateral(t)
        # Left of the body: against the direction of travel while it backs out.
        n, n1, n2 = _left_normal(facing * g1, facing * g2, None if g3 is None else facing * g3)
        # Chain rule with s(t): d/dt = s' d/ds, d2/dt2 = s'' d/ds + s'^2 d2/ds2.
        ds_, dds_ = ds[..., None], dds[..., None]
        lat_, dlat_, ddlat_ = lat[..., None], dlat[..., None], ddlat[..., None]
        position = g + lat_ * n
        velocity = ds_ * g1 + dlat_ * n + lat_ * ds_ * n1
        accel = None
        if acceleration:
            assert n2 is not None
            accel = (dds_ * g1 + ds_ * ds_ * g2 + ddlat_ * n + 2.0 * dlat_ * ds_ * n1
                     + lat_ * (dds_ * n1 + ds_ * ds_ * n2))
        tangent = facing * g1 / np.linalg.norm(g1, axis=-1, keepdims=True)
        return Motion(position_m=position, velocity_mps=velocity, acceleration_mps2=accel,
                      tangent=tangent)

    def _path(
        self, s: FloatArray, third: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None, FloatArray]:
        """Hermite path position, its arc-length derivatives (the third one if asked), facing.

        ``facing`` (``(..., 1)``) is +1 where the body faces the direction of travel, -1 where
        it backs out.
        """
        # Paths have at least two points and the lookup stops one short of the end.
        piece = piece_index([p.arc_m for p in self._paths], s)
        j = piece + self._path_start
        k = piece + self._piece_start
        length = (self._arc[j + 1] - self._arc[j])[..., None]
        f = (s[..., None] - self._arc[j][..., None]) / length
        fc = np.clip(f, 0.0, 1.0)
        # Beyond the ends the path goes on straight along the end tangent.
        beyond = (f - fc) * length
        p0 = self._points[j]
        chord = self._points[j + 1] - p0
        m0, m1 = self._tangent_start[k] * length, self._tangent_end[k] * length
        f2 = fc * fc
        # Hermite form p0 + h01 (p1 - p0) + h10 m0 + h11 m1 (as h00 + h01 = 1).
        g = p0 + (3 * f2 - 2 * f2 * fc) * chord + (f2 * fc - 2 * f2 + fc) * m0 + (f2 * fc - f2) * m1
        g1 = ((6 * fc - 6 * f2) * chord + (3 * f2 - 4 * fc + 1) * m0 + (3 * f2 - 2 * fc) * m1
              ) / length
        inside = beyond == 0.0
        g2 = ((6 - 12 * fc) * chord + (6 * fc - 4) * m0 + (6 * fc - 2) * m1) / length**2 * inside
        g3 = ((6 * (m0 + m1) - 12 * chord) / length**3 * inside) if third else None
        return g + beyond * g1, g1, g2, g3, self._facing[k][..., None]

    def _travel(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = piece_index([law.knots_s for law in self._laws], t, open_end=True) + self._law_start
        dt = t - self._knots[k]
        a = self._a[k]
        return self._s0[k] + self._v0[k] * dt + 0.5 * a * dt * dt, self._v0[k] + a * dt, a

    def _lateral(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        start, duration, offset = self._lc[:, None]  # each (1, width, K)
        tau = np.clip((t[:, None, :] - start) / duration, 0.0, 1.0)
        ramp = lane_change_ramp(tau)
        slope = 30.0 * tau * tau * (1.0 - tau) ** 2 / duration
        bend = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / duration**2
        return ((offset * ramp).sum(axis=1), (offset * slope).sum(axis=1),
                (offset * bend).sum(axis=1))


def lane_change_ramp(tau: FloatArray) -> FloatArray:
    """Return a lane change's share of its offset at ``tau`` (its quintic: 0 before, 1 after)."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))


def _left_normal(
    g1: FloatArray, g2: FloatArray, g3: FloatArray | None
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """Horizontal left normal of a path with derivative ``g1`` and its s-derivatives.

    The second derivative needs ``g3``; without it it is None.
    """
    # n = perp(h) / |h| with h the horizontal part of g1 and perp(x, y) = (-y, x).
    def perp(v: FloatArray) -> FloatArray:
        return np.stack([-v[..., 1], v[..., 0], np.zeros_like(v[..., 0])], axis=-1)

    h, h1 = (np.concatenate([v[..., :2], np.zeros_like(v[..., :1])], axis=-1) for v in (g1, g2))
    length = np.linalg.norm(h, axis=-1, keepdims=True)
    # A vertical path has no horizontal left: take world +y there (it only matters for lateral
    # offsets of a vertically moving object).
    vertical = length < 1e-9
    norm = np.where(vertical, 1.0, length)
    a = (h * h1).sum(-1, keepdims=True)  # h . h'
    n = np.where(vertical, np.array([0.0, 1.0, 0.0]), perp(h) / norm)
    n1 = np.where(vertical, 0.0, perp(h1) / norm - perp(h) * a / norm**3)
    n2 = None
    if g3 is not None:
        h2 = np.concatenate([g3[..., :2], np.zeros_like(g3[..., :1])], axis=-1)
        b = (h1 * h1 + h * h2).sum(-1, keepdims=True)  # (h . h')'
        n2 = np.where(vertical, 0.0, perp(h2) / norm - 2.0 * perp(h1) * a / norm**3
                      - perp(h) * (b / norm**3 - 3.0 * a * a / norm**5))
    return n, n1, n2
