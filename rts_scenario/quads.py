"""Which quad of a rig encloses each target (point in quadrilateral, in angle space).

The geometry depends only on the rig's FE angles and grid shape; it is computed once per set of
values (never stored on a rig, so a rig changed with ``dataclasses.replace`` gets its own).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from .rig import Rig

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Relative tolerance on the edge tests: a target on a quad's edge or corner belongs to it.
EDGE_TOL_DEG = 1e-9
# A quad with less area (deg^2) than this has collapsed onto a line; targets off the line but
# within max(REACH_DEG, REACH * its length) of it are reported as degenerate, not outside.
DEGENERATE_AREA_DEG2 = 1e-9
DEGENERATE_REACH_DEG = 1.0
DEGENERATE_REACH = 0.25


def quad_polygons(rig: Rig) -> FloatArray:
    """Corners of every quad in angle space, shape ``(Q, 4, 2)``, counter-clockwise.

    Corner order is FE 0, 1, 3, 2 (around the cell), coordinates ``(az_deg, el_deg)``.
    """
    corners = rig.quads[:, [0, 1, 3, 2]]
    return np.stack([rig.az_deg[corners], rig.el_deg[corners]], axis=-1)


def quad_widths_deg(rig: Rig) -> tuple[FloatArray, FloatArray]:
    """Smallest azimuth width and elevation height of every quad, degrees, shape ``(Q,)``."""
    q = rig.quads
    width = np.minimum(rig.az_deg[q[:, 1]] - rig.az_deg[q[:, 0]],
                       rig.az_deg[q[:, 3]] - rig.az_deg[q[:, 2]])
    height = np.minimum(rig.el_deg[q[:, 2]] - rig.el_deg[q[:, 0]],
                        rig.el_deg[q[:, 3]] - rig.el_deg[q[:, 1]])
    return width, height


def edge_lines(polygons: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inner-normal line coefficients and bounding boxes of quads ``(Q, 4, 2)``.

    Returns ``lines`` of shape ``(Q, 4, 3)`` with ``nx * az + ny * el + c`` the signed distance
    (deg) to each edge, positive inside (zero-length edges: all zero), and ``boxes`` of shape
    ``(Q, 4)``: ``az_min, az_max, el_min, el_max``.
    """
    a = polygons
    d = np.roll(polygons, -1, axis=1) - a
    length = np.hypot(d[..., 0], d[..., 1])
    safe = np.where(length > 0.0, length, 1.0)
    nx = np.where(length > 0.0, -d[..., 1] / safe, 0.0)
    ny = np.where(length > 0.0, d[..., 0] / safe, 0.0)
    c = -(nx * a[..., 0] + ny * a[..., 1])
    boxes = np.stack([a[..., 0].min(axis=1), a[..., 0].max(axis=1),
                      a[..., 1].min(axis=1), a[..., 1].max(axis=1)], axis=1)
    return np.stack([nx, ny, c], axis=-1), boxes


def inside_quads(
    az_deg: FloatArray, el_deg: FloatArray, quad: NDArray[np.int64] | int, lines: FloatArray,
    boxes: FloatArray, margin_deg: float = 0.0,
) -> NDArray[np.bool_]:
    """Whether target ``i`` lies in quad ``quad[i]`` (see `edge_lines` for the tables).

    ``margin_deg`` grows every quad outward by that distance from its edges.
    """
    slack = EDGE_TOL_DEG + margin_deg
    inside = (az_deg >= boxes[quad, 0] - slack) & (az_deg <= boxes[quad, 1] + slack)
    inside &= (el_deg >= boxes[quad, 2] - slack) & (el_deg <= boxes[quad, 3] + slack)
    for i in range(4):
        dist = lines[quad, i, 0] * az_deg + lines[quad, i, 1] * el_deg + lines[quad, i, 2]
        inside &= dist >= -slack
    return inside


def candidate_quads(
    column_az_deg: FloatArray, row_el_deg: FloatArray, az_deg: FloatArray, el_deg: FloatArray
) -> NDArray[np.int64]:
    """Most likely enclosing quad of each target, from the grid's mean column and row angles."""
    columns, rows = column_az_deg.size, row_el_deg.size
    col = np.clip(np.searchsorted(column_az_deg, az_deg) - 1, 0, columns - 2)
    row = np.clip(np.searchsorted(row_el_deg, el_deg) - 1, 0, rows - 2)
    return row * (columns - 1) + col


# Cells of `locate_raster` along azimuth and elevation: 512 x 256 32-bit cells (512 KiB, in
# the L2 cache), of which a few per cent straddle an edge or a grid mean on the wide-3x5 grid.
RASTER_CELLS = (512, 256)
# Angle (deg) by which a cell must clear every test to be certain: far above the rounding of
# the tests (~1e-13 deg) and of a target's cell index, far below any quad.
RASTER_GUARD_DEG = 1e-7


def locate_raster(
    column_az_deg: FloatArray, row_el_deg: FloatArray, lines: FloatArray, boxes: FloatArray,
    cells: tuple[int, int] = RASTER_CELLS,
) -> tuple[NDArray[np.int32], FloatArray]:
    """Answers of `candidate_quads` and `inside_quads` on a raster of cells, where certain.

    Returns ``(raster, frame)``: ``raster`` (``cells[1] * cells[0]``, row-major by elevation)
    holds per cell the quad every direction in it is assigned (its candidate, inside it), -1
    where every direction in it is outside its candidate, and -2 where directions in it may
    differ (the test then runs per direction). ``frame`` is ``(az0, el0, 1/d_az, 1/d_el,
    columns, rows)``: the cell of ``(az, el)`` is ``floor((az - az0) / d_az)`` along azimuth.
    The raster reaches 1 deg beyond every quad; farther directions are outside.

    Certain by construction, not by sampling: a cell's candidate is fixed when no grid mean
    lies within it (`RASTER_GUARD_DEG` around it), and each test of `inside_quads` is linear in
    ``(az, el)``, so it holds (fails) over the whole cell when it holds (fails) at its four
    corners by that guard.
    """
    width, height = cells
    az0, az1 = boxes[:, 0].min() - 1.0, boxes[:, 1].max() + 1.0
    el0, el1 = boxes[:, 2].min() - 1.0, boxes[:, 3].max() + 1.0
    d_az, d_el = (az1 - az0) / width, (el1 - el0) / height
    az_lo = az0 + d_az * np.arange(width)
    el_lo = el0 + d_el * np.arange(height)
    az_hi, el_hi = az_lo + d_az, el_lo + d_el
    guard = RASTER_GUARD_DEG
    columns, rows = column_az_deg.size, row_el_deg.size

    def cell_index(means: FloatArray, lo: FloatArray, hi: FloatArray,
                   last: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        first = np.clip(np.searchsorted(means, lo - guard) - 1, 0, last)
        return first, np.clip(np.searchsorted(means, hi + guard) - 1, 0, last) == first

    col, col_fixed = cell_index(column_az_deg, az_lo, az_hi, columns - 2)
    row, row_fixed = cell_index(row_el_deg, el_lo, el_hi, rows - 2)
    candidate = row[:, None] * (columns - 1) + col[None, :]
    fixed = row_fixed[:, None] & col_fixed[None, :]
    # A row of quads covers whole rows of cells (``row`` never decreases), each column of them
    # one quad's. Each test is linear in (az, el): over a cell its least and greatest values
    # lie at the corners its coefficients' signs pick (the same sums as at those corners).
    least = np.empty((height, width))
    beyond = np.empty((height, width), dtype=bool)  # some test fails over the whole cell
    slack = EDGE_TOL_DEG
    row_at = np.searchsorted(row, np.arange(rows))
    for r in range(rows - 1):
        band = slice(row_at[r], row_at[r + 1])
        el_l, el_h = el_lo[band, None], el_hi[band, None]
        box, line = boxes[r * (columns - 1) + col], lines[r * (columns - 1) + col]
        a0, a1 = box[:, 0] - slack, box[:, 1] + slack
        e0, e1 = box[:, 2] - slack, box[:, 3] + slack
        tests = [(az_lo - a0, az_hi - a0), (a1 - az_hi, a1 - az_lo),
                 (el_l - e0, el_h - e0), (e1 - el_h, e1 - el_l)]
        for i in range(4):
            a, b, k = line[:, i, 0], line[:, i, 1], line[:, i, 2]
            up_a, up_b = a >= 0.0, b >= 0.0
            tests.append((a * np.where(up_a, az_lo, az_hi) + b * np.where(up_b, el_l, el_h)
                          + k + slack,
                          a * np.where(up_a, az_hi, az_lo) + b * np.where(up_b, el_h, el_l)
                          + k + slack))
        least[band] = np.minimum.reduce(np.broadcast_arrays(*(low for low, _ in tests)))
        beyond[band] = np.logical_or.reduce(
            np.broadcast_arrays(*(high <= -guard for _, high in tests)))
    inside = fixed & (least >= guard)
    outside = fixed & beyond
    raster = np.full((height, width), -2, dtype=np.int32)  # any number of quads
    raster[inside] = candidate[inside]
    raster[outside] = -1
    frame = np.array([az0, el0, 1.0 / d_az, 1.0 / d_el, width, height], dtype=np.float64)
    return raster.ravel(), frame


def distance_to_polygon(az_deg: FloatArray, el_deg: FloatArray, polygon: FloatArray) -> FloatArray:
    """Distance (deg, in the az/el plane) from each point to the polygon's boundary segments."""
    best = np.full(az_deg.shape, np.inf)
    for i in range(4):
        a = polygon[i]
        b = polygon[(i + 1) % 4]
        d = b - a
        length2 = float(d @ d)
        t = np.zeros(az_deg.shape) if length2 == 0.0 else np.clip(
            ((az_deg - a[0]) * d[0] + (el_deg - a[1]) * d[1]) / length2, 0.0, 1.0
        )
        best = np.minimum(best, np.hypot(az_deg - a[0] - t * d[0], el_deg - a[1] - t * d[1]))
    return best


@dataclass(frozen=True)
class QuadGeometry:
    """A rig's quads in angle space, prepared for fast point-in-quad tests.

    Attributes
    ----------
    polygons : ndarray, shape (Q, 4, 2)
        Quad corners, see `quad_polygons`.
    lines, boxes : ndarray, shapes (Q, 4, 3) and (Q, 4)
        Edge lines and bounding boxes, see `edge_lines`.
    degenerate : ndarray, shape (Q,), bool
        Quads collapsed onto a line.
    column_az_deg, row_el_deg : ndarray, shapes (columns,) and (rows,)
        Mean azimuth of every grid column and mean elevation of every grid row, degrees.
    raster, raster_frame : ndarray, shapes (cells,) and (6,)
        `locate_raster`'s cells and frame on a grid of quads; empty for a single quad. Made
        when first asked for: only the compiled kernel reads them, for many targets (a run of
        a few targets, on the numpy code, does not pay the 5-25 ms).
    """

    polygons: FloatArray
    lines: FloatArray
    boxes: FloatArray
    degenerate: NDArray[np.bool_]
    column_az_deg: FloatArray
    row_el_deg: FloatArray
    _located: tuple[NDArray[np.int32], FloatArray] | None = field(
        default=None, init=False, repr=False, compare=False)

    def __getstate__(self) -> dict[str, object]:
        # Made again where asked for (a pickled plan's raster would come back writable: to the
        # compiled kernel another type of argument, compiled once more).
        return {**vars(self), "_located": None}

    @property
    def raster(self) -> NDArray[np.int32]:
        """`locate_raster`'s cells (see the class)."""
        return self._locate()[0]

    @property
    def raster_frame(self) -> FloatArray:
        """`locate_raster`'s frame (see the class)."""
        return self._locate()[1]

    def _locate(self) -> tuple[NDArray[np.int32], FloatArray]:
        found = self._located
        if found is None:  # two threads may both make it: the same values, either kept
            if len(self.polygons) > 1:
                found = locate_raster(self.column_az_deg, self.row_el_deg, self.lines,
                                      self.boxes)
            else:
                found = np.zeros(0, dtype=np.int32), np.zeros(6)
            for value in found:
                value.setflags(write=False)
            object.__setattr__(self, "_located", found)
        return found

    @classmethod
    def of(cls, rig: Rig) -> QuadGeometry:
        """Return the geometry of ``rig`` (computed once per set of FE angles and grid shape)."""
        return _geometry(rig.az_deg.tobytes(), rig.el_deg.tobytes(), rig.rows, rig.columns)

    @classmethod
    def build(cls, rig: Rig) -> QuadGeometry:
        """Compute the geometry of ``rig`` (uncached: see `of`)."""
        polygons = quad_polygons(rig)
        lines, boxes = edge_lines(polygons)
        x, y = polygons[..., 0], polygons[..., 1]
        area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y,
                                   axis=1))
        column_az = rig.az_deg.reshape(rig.rows, rig.columns).mean(axis=0)
        row_el = rig.el_deg.reshape(rig.rows, rig.columns).mean(axis=1)
        geometry = cls(
            polygons=polygons, lines=lines, boxes=boxes, degenerate=area <= DEGENERATE_AREA_DEG2,
            column_az_deg=column_az, row_el_deg=row_el,
        )
        # Shared between every caller with the same values: nobody may change it.
        for value in (polygons, lines, boxes, geometry.degenerate, column_az, row_el):
            value.setflags(write=False)
        return geometry

    def within(self, az_deg: FloatArray, el_deg: FloatArray, quad: IntArray | int,
               margin_deg: float = 0.0) -> NDArray[np.bool_]:
        """Whether each target lies in its quad (grown by ``margin_deg``)."""
        return inside_quads(az_deg, el_deg, quad, self.lines, self.boxes, margin_deg)

    def assign(self, az_deg: FloatArray, el_deg: FloatArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Enclosing quad per target (-1: none) and whether a miss is near a degenerate quad."""
        quad = candidate_quads(self.column_az_deg, self.row_el_deg, az_deg, el_deg)
        quad[~self.within(az_deg, el_deg, quad)] = -1
        off_line = np.zeros(az_deg.shape, dtype=bool)
        # Near bent borders the guess can miss: scan every quad for those few.
        for q in range(len(self.polygons)):
            take = np.flatnonzero(quad < 0)
            if take.size == 0:
                break
            hit = self.within(az_deg[take], el_deg[take], q)
            if self.degenerate[q]:
                extent = np.ptp(self.polygons[q], axis=0).max()
                near = distance_to_polygon(az_deg[take], el_deg[take], self.polygons[q]) <= max(
                    DEGENERATE_REACH_DEG, DEGENERATE_REACH * extent
                )
                off_line[take[near & ~hit]] = True
            quad[take[hit]] = q
        off_line &= quad < 0
        return quad, off_line


def assign_quads(rig: Rig, az_deg: FloatArray, el_deg: FloatArray) -> IntArray:
    """Index of the quad enclosing each direction (-1 outside every quad), any shape."""
    az = np.asarray(az_deg, dtype=np.float64)
    el = np.asarray(el_deg, dtype=np.float64)
    quad, _ = QuadGeometry.of(rig).assign(az.ravel(), el.ravel())
    return quad.reshape(az.shape)


@lru_cache(maxsize=32)
def _geometry(az_bytes: bytes, el_bytes: bytes, rows: int, columns: int) -> QuadGeometry:
    az = np.frombuffer(az_bytes, dtype=np.float64)
    el = np.frombuffer(el_bytes, dtype=np.float64)
    return QuadGeometry.build(Rig.grid(az.reshape(rows, columns), el.reshape(rows, columns)))
