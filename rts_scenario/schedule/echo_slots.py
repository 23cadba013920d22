"""Echo-slot assignment: which targets an FE channel can play when it has too few echoes.

Each FE channel produces at most ``echoes_per_channel`` echoes per frame. Rule: a target keeps
its echoes when, on every FE it uses, fewer than that many nearer targets (range; ties: larger
RCS, then lower index) use the FE in that frame; otherwise it is flagged ``NO_ECHO_SLOT`` and
not emitted (a partial set of channels would move its angle).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..kinematics import Tracks
from .model import Status

IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def assign_echo_slots(fe: IntArray, using: BoolArray, tracks: Tracks, per_channel: int,
                      n_fe: int) -> NDArray[np.uint16]:
    """Flag the entries that get no echo slot on one of their FEs.

    Parameters
    ----------
    fe : ndarray of int, shape (F, K, 4)
        Rig FE index of each channel of each frame and target.
    using : ndarray of bool, shape (F, K, 4)
        Channels that would emit an echo (entries already blocked for another reason excluded).
    tracks : Tracks
        Ground truth of the same F frames and K targets; ``range_m`` and ``rcs_dbsm`` rank
        the targets competing for an FE.
    per_channel : int
        Echoes one FE channel can produce per frame.
    n_fe : int
        Number of FEs in the rig.

    Returns
    -------
    ndarray of uint16, shape (F, K)
        ``Status.NO_ECHO_SLOT`` where a target is not among the ``per_channel`` most relevant
        (nearest; ties: larger RCS, then lower index) targets on one of its FEs, else 0.
    """
    n_frames, n_targets = tracks.range_m.shape
    frame = np.broadcast_to(np.arange(n_frames)[:, None, None], fe.shape)
    target = np.broadcast_to(np.arange(n_targets)[None, :, None], fe.shape)
    sel = using.ravel()
    # Usually every channel has slots enough: one count settles it.
    load = np.bincount(frame.ravel()[sel] * n_fe + fe.ravel()[sel], minlength=1)
    if load.max(initial=0) <= per_channel:
        return np.zeros((n_frames, n_targets), dtype=np.uint16)
    f, k, q = frame.ravel()[sel], target.ravel()[sel], fe.ravel()[sel]
    rng = tracks.range_m[f, k]
    rcs = tracks.rcs_dbsm[f, k]
    # Sort by (frame, FE, range, -rcs, target); the rank within each (frame, FE) group is the
    # number of more relevant targets on that FE.
    order = np.lexsort((k, -rcs, rng, q, f))
    group = f[order] * n_fe + q[order]
    first = np.r_[True, group[1:] != group[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(group.size), 0))
    rank = np.empty(group.size, dtype=np.int64)
    rank[order] = np.arange(group.size) - start
    over = np.zeros((n_frames, n_targets), dtype=bool)
    np.logical_or.at(over, (f, k), rank >= per_channel)
    return np.where(over, Status.NO_ECHO_SLOT, 0).astype(np.uint16)


__all__ = ["assign_echo_slots"]
