"""Echo-slot assignment: which targets an FE channel can play when it has too few echoes.

Each FE channel produces at most ``echoes_per_channel`` echoes per frame. Rule: targets take
their echoes in order of relevance (nearest first; ties: larger RCS, then lower index); a
target keeps them when every FE it uses has a slot left after the more relevant targets that
kept theirs, otherwise it is flagged ``NO_ECHO_SLOT`` and not emitted at all (a partial set of
channels would move its angle) and leaves its other FEs' slots to the targets after it.
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
        ``Status.NO_ECHO_SLOT`` where a target finds no slot left on one of its FEs, taking
        the targets in order of relevance (nearest; ties: larger RCS, then lower index), else 0.

    Notes
    -----
    Decided in rounds, each vectorized over every frame: an undecided target is kept when, on
    each of its FEs, fewer than ``per_channel`` more relevant targets are still in play (none
    of them can take its slot then), and dropped when ``per_channel`` more relevant targets
    already kept theirs on one of its FEs. Each round decides at least the most relevant
    undecided target of every frame, so the rounds end; the result is that of taking the
    targets one by one.
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
    # Entries sorted by (frame, FE, range, -rcs, target): within each (frame, FE) group, the
    # entries before one are its more relevant targets on that FE.
    order = np.lexsort((k, -rcs, rng, q, f))
    f, k, q = f[order], k[order], q[order]
    group = f * n_fe + q
    first = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    start = np.repeat(first, np.diff(np.r_[first, group.size]))
    # The targets' states: 0 undecided, 1 kept, 2 dropped (by frame and target).
    state = np.zeros((n_frames, n_targets), dtype=np.int8)

    def before(flag: BoolArray) -> IntArray:
        """How many entries before each in its group have ``flag``."""
        count = np.cumsum(flag, dtype=np.int64)
        return count - flag - (count[start] - flag[start])

    while True:
        entry_state = state[f, k]
        open_ = entry_state == 0
        if not open_.any():
            break
        in_play = before(entry_state != 2) < per_channel
        full = before(entry_state == 1) >= per_channel
        # Kept: no FE of the target lacks a slot however the undecided ones before it go.
        blocked = np.zeros((n_frames, n_targets), dtype=bool)
        np.logical_or.at(blocked, (f[open_], k[open_]), ~in_play[open_])
        dropped = np.zeros((n_frames, n_targets), dtype=bool)
        np.logical_or.at(dropped, (f[open_], k[open_]), full[open_])
        undecided = state == 0
        touched = np.zeros((n_frames, n_targets), dtype=bool)
        touched[f[open_], k[open_]] = True
        state[undecided & touched & dropped] = 2
        state[undecided & touched & ~dropped & ~blocked] = 1
    return np.where(state == 2, Status.NO_ECHO_SLOT, 0).astype(np.uint16)


__all__ = ["assign_echo_slots"]
