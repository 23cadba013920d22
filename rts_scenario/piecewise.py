"""Vectorized lookup in many piecewise tables at once."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def piece_index(tables: list[FloatArray], query: FloatArray, open_end: bool = False) -> IntArray:
    """Index ``j`` with ``table_k[j] <= query[:, k] < table_k[j+1]`` per object k, clipped.

    Tables are increasing. Values below a table's start belong to its first piece. With
    ``open_end`` the last entry starts a piece that never ends (result up to ``len - 1``);
    otherwise entries bound pieces and values past the end extrapolate the last one (result up
    to ``len - 2``). One searchsorted for all objects: each object's table is shifted by its
    own multiple of a span larger than every value.
    """
    sizes = np.array([t.size for t in tables])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    flat = np.concatenate(tables)
    span = 4.0 * (max(np.abs(flat).max(initial=0.0), np.abs(query).max(initial=0.0)) + 1.0)
    shift = np.arange(len(tables)) * span
    keys = flat + np.repeat(shift, sizes)
    j = np.searchsorted(keys, query + shift, side="right") - 1 - starts
    return np.clip(j, 0, np.maximum(sizes - (1 if open_end else 2), 0))
