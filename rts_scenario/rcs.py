"""Radar cross section series: constant, aspect-angle tables, Swerling 1 and 3 fluctuation.

Fluctuation draws are counter-based: each (seed, target, frame) has its own uniform numbers,
computed by a SplitMix64 hash of those indices, so a scene evaluated in batches of frames (a
streaming run) draws exactly what it draws in one piece.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .piecewise import piece_index
from .scenario.model import RcsModel

FloatArray = NDArray[np.float64]


def rcs_series(models: list[RcsModel], aspect_deg: FloatArray, seed: int,
               frame_index: NDArray[np.int64]) -> FloatArray:
    """RCS in dBsm per frame and target, shape ``(F, K)``.

    Parameters
    ----------
    models : list of RcsModel
        One per target (K).
    aspect_deg : ndarray, shape (F, K)
        Aspect angle of the radar as seen from each target (0: from the front).
    seed : int
        Seed of the fluctuation; the same seed gives the same series.
    frame_index : ndarray of int, shape (F,)
        Index of each frame in the scene (the fluctuation is a function of it).
    """
    n_frames, n_targets = aspect_deg.shape
    out = np.empty((n_frames, n_targets))
    constant = [k for k, m in enumerate(models) if m.aspect_deg is None]
    if constant:
        out[:, constant] = np.array([models[k].rcs_dbsm[0] for k in constant])
    table = [k for k, m in enumerate(models) if m.aspect_deg is not None]
    if table:
        out[:, table] = _interpolate_tables([models[k] for k in table], aspect_deg[:, table])
    for kind, draw in (("swerling1", _swerling1), ("swerling3", _swerling3)):
        idx = [k for k, m in enumerate(models) if m.fluctuation == kind]
        if idx:
            frames = np.asarray(frame_index, dtype=np.uint64)[:, None]
            out[:, idx] += 10.0 * np.log10(draw(seed, frames, np.array(idx, dtype=np.uint64)))
    return out


def _swerling1(seed: int, frame: NDArray[np.uint64], target: NDArray[np.uint64]) -> FloatArray:
    # Chi-square with 2 degrees of freedom, mean 1: exponential power, frame to frame.
    return -np.log1p(-uniforms(seed, frame, target, 0))


def _swerling3(seed: int, frame: NDArray[np.uint64], target: NDArray[np.uint64]) -> FloatArray:
    # Chi-square with 4 degrees of freedom, mean 1: the mean of two exponentials.
    return -0.5 * (np.log1p(-uniforms(seed, frame, target, 1))
                   + np.log1p(-uniforms(seed, frame, target, 2)))


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def uniforms(seed: int, frame: NDArray[np.uint64], target: NDArray[np.uint64],
             stream: int) -> FloatArray:
    """Uniform numbers in [0, 1), one per (frame, target) (broadcast), for ``seed`` and ``stream``.

    SplitMix64 of a key made of the four indices: independent of how frames are batched.
    """
    with np.errstate(over="ignore"):  # modular arithmetic is the point
        key = (np.uint64(seed & 0xFFFFFFFF) * _MIX1 + np.uint64(stream) * _MIX2
               + target * _GOLDEN) ^ (frame * _MIX1 + _GOLDEN)
        z = key + _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * _MIX1
        z = (z ^ (z >> np.uint64(27))) * _MIX2
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def _interpolate_tables(models: list[RcsModel], aspect_deg: FloatArray) -> FloatArray:
    """Periodic linear interpolation of each target's table at its own aspect angles."""
    angles, values = [], []
    for m in models:  # per target table set-up, not per frame
        assert m.aspect_deg is not None
        angles.append(np.concatenate([m.aspect_deg[-1:] - 360.0, m.aspect_deg,
                                      m.aspect_deg[:1] + 360.0]))
        values.append(np.concatenate([m.rcs_dbsm[-1:], m.rcs_dbsm, m.rcs_dbsm[:1]]))
    query = np.mod(aspect_deg, 360.0)
    j = piece_index(angles, query)
    starts = np.concatenate([[0], np.cumsum([a.size for a in angles])[:-1]])
    flat_a, flat_v = np.concatenate(angles), np.concatenate(values)
    lo = j + starts
    frac = (query - flat_a[lo]) / (flat_a[lo + 1] - flat_a[lo])
    return flat_v[lo] + frac * (flat_v[lo + 1] - flat_v[lo])
