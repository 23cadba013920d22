"""Which quad of a rig encloses each target (point in quadrilateral, in angle space)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..rig import Rig

FloatArray = NDArray[np.float64]

# Relative tolerance on the edge tests: a target on a quad's edge or corner belongs to it.
EDGE_TOL_DEG = 1e-9
# An angle-space quad thinner than this (deg) has collapsed onto a line or a point.
DEGENERATE_WIDTH_DEG = 1e-6


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


def inside_polygon(
    az_deg: FloatArray, el_deg: FloatArray, polygon: FloatArray, margin_deg: float = 0.0
) -> NDArray[np.bool_]:
    """Whether each point lies in the convex ``polygon`` (shape ``(4, 2)``, counter-clockwise).

    ``margin_deg`` grows the polygon outward by that distance from every edge.
    """
    slack = margin_deg + EDGE_TOL_DEG
    lo = polygon.min(axis=0) - slack
    hi = polygon.max(axis=0) + slack
    # The bounding box matters for quads collapsed onto a line, where every edge test passes.
    inside = (az_deg >= lo[0]) & (az_deg <= hi[0]) & (el_deg >= lo[1]) & (el_deg <= hi[1])
    for i in range(4):
        ax, ay = polygon[i]
        bx, by = polygon[(i + 1) % 4]
        length = np.hypot(bx - ax, by - ay)
        if length == 0.0:
            continue
        # Signed distance to the edge line, positive on the inner (left) side.
        dist = ((bx - ax) * (el_deg - ay) - (by - ay) * (az_deg - ax)) / length
        inside &= dist >= -slack
    return inside


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
