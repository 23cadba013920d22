"""Radar cross section series: constant, aspect-angle tables, Swerling 1 and 3 fluctuation."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .lookup import piece_index
from .scenario.model import RcsModel

FloatArray = NDArray[np.float64]


def rcs_series(models: list[RcsModel], aspect_deg: FloatArray,
               rng: np.random.Generator) -> FloatArray:
    """RCS in dBsm per frame and target, shape ``(F, K)``.

    Parameters
    ----------
    models : list of RcsModel
        One per target (K).
    aspect_deg : ndarray, shape (F, K)
        Aspect angle of the radar as seen from each target (0: from the front).
    rng : numpy.random.Generator
        Source of the fluctuation; the same seed gives the same series.
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
            out[:, idx] += 10.0 * np.log10(draw(rng, (n_frames, len(idx))))
    return out


def _swerling1(rng: np.random.Generator, shape: tuple[int, int]) -> FloatArray:
    # Chi-square with 2 degrees of freedom, mean 1: exponential power, frame to frame.
    return rng.exponential(1.0, shape)


def _swerling3(rng: np.random.Generator, shape: tuple[int, int]) -> FloatArray:
    # Chi-square with 4 degrees of freedom, mean 1.
    return rng.gamma(2.0, 0.5, shape)


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
