"""Check that the synthesized peak is the global maximum of |B| (else the echoes split).

The radar's estimator searches its whole field of view, so a second peak anywhere in it counts:
for a sparse or large array (grating lobes, high sidelobes) it can lie far from the quad. For
each quad a grid of probe directions covers the field of view `FIELD_OF_VIEW` (and the quad's
FEs extended by one resolution cell, should they lie outside it), and the FEs' responses at the
probes are precomputed. A solution splits when a probe farther than half a resolution cell from
the set direction sees ``|B|`` within the probe grid's sampling loss of the set direction's
``|B|`` (closer than that, a second peak could not be resolved by the radar and the
local-maximum test of the method applies).

A weaker second peak splits the target too when the radar would report it: its estimator
reports secondary peaks of at least `GHOST_POWER` of the strongest one's power (the default
``peak_ratio`` of `rts_scenario.radar.angle.Bartlett2D`). Such a ghost is a local maximum of
``|B|`` on the probe grid, farther than `EXCLUSION_CELLS` from the set direction, that a real
target in the set direction would not show: the array's own pattern (a plane wave from the set
direction) stays below `GHOST_POWER` there. Sidelobes and grating lobes of the radar's own
array are the radar's, not the synthesis's, and do not count.

Evaluating every probe for every target would cost ``probes x 4`` per target, tens of thousands
on a large array. Since ``|B(p)| <= sum_q w_q |f_q(p)| <= sum(w) * max_q |f_q(p)|``, a probe
whose bound ``max_q |f_q(p)|`` is below ``limit / sum(w)`` cannot reach the target's limit. The
probes are stored by decreasing bound, so each target needs only a prefix of them: the FEs' main
lobes and grating lobes, evaluated in blocks until the target splits or its prefix ends. The
result is the same as evaluating every probe.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..arrays import SourceResponse, VirtualArray, direction_cosines, plane_waves
from ..rig import Rig

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# Direction cosines (u = cos el sin az, s = sin el) the radar's estimator searches, |u| <= u_max
# and |s| <= s_max: the default search region of `rts_scenario.radar.angle.Bartlett2D`.
FIELD_OF_VIEW = (0.8, 0.6)
PROBES_PER_CELL = 8
EXCLUSION_CELLS = 0.5
# A peak between probes is at most this much higher than the best probe near it: a main lobe
# ``1 - k^2 sigma^2 d^2 / 2`` (sigma the rms element offset along the axis) half a step ``d`` off
# along each axis. Every 1/8 cell is fine enough for a filled row (a sinc main lobe); sparse rows
# (elements bunched at the ends) get a finer step from this budget.
SAMPLING_LOSS = 0.015
# A secondary local maximum of at least this fraction of the set direction's power (with the
# same sampling slack) is a second target to the radar, unless its own pattern puts one there.
GHOST_POWER = 0.5
# Targets x probes evaluated at once (bounds the temporary arrays to a few tens of MB).
BLOCK_ELEMENTS = 1 << 20
_MIN_BLOCK = 64


@dataclass(frozen=True)
class GlobalMaxCheck:
    """Precomputed probe responses of one quad, probes sorted by decreasing bound.

    Attributes
    ----------
    response : SourceResponse
        Response of the quad's four FEs (paper order).
    probe_u, probe_s : ndarray, shape (P,)
        Probe directions (direction cosines).
    probe_re, probe_im : ndarray, shape (4, P)
        Real and imaginary parts of ``f_q`` at the probes.
    bound : ndarray, shape (P,)
        ``max_q |f_q|`` at each probe, non-increasing.
    cell_u, cell_s : float
        Resolution cell (wavelength / aperture) along u and s.
    y_m, z_m : ndarray, shape (M,)
        The virtual array's element positions (its own pattern, for ghosts).
    wavenumber : float
        2 pi / wavelength, rad/m.
    probe_cell : ndarray, shape (P,)
        Flat index of each probe in the probe grid of shape `grid_shape` (row: u, column: s).
    probe_at : ndarray, shape (grid_shape[0] * grid_shape[1],)
        Probe index of each grid point, -1 where the grid point is not visible.
    grid_shape : tuple of int
        Probes along u and along s before the invisible ones are dropped.
    """

    response: SourceResponse
    probe_u: FloatArray
    probe_s: FloatArray
    probe_re: FloatArray
    probe_im: FloatArray
    bound: FloatArray
    cell_u: float
    cell_s: float
    y_m: FloatArray
    z_m: FloatArray
    wavenumber: float
    probe_cell: NDArray[np.int64]
    probe_at: NDArray[np.int64]
    grid_shape: tuple[int, int]

    @classmethod
    def build(
        cls,
        rig: Rig,
        array: VirtualArray,
        fes: NDArray[np.int64],
        vectors: ComplexArray | None = None,
    ) -> GlobalMaxCheck:
        """Lay the probe grid over the field of view for the quad ``fes`` and ``array``.

        ``vectors`` (shape ``(M, 4)``): the FEs' response vectors on the array, when modeled
        (`rts_scenario.responses`); default their plane-wave steering vectors.
        """
        u, s = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
        ap_y, ap_z = array.sinc_aperture_m()
        cell_u = array.wavelength_m / ap_y if ap_y > 0 else 2.0
        cell_s = array.wavelength_m / ap_z if ap_z > 0 else 2.0
        k = array.wavenumber_rad_per_m
        grids = []
        for pos, cell, half, rms in (
            (u, cell_u, FIELD_OF_VIEW[0], np.sqrt(np.mean(array.y_m**2))),
            (s, cell_s, FIELD_OF_VIEW[1], np.sqrt(np.mean(array.z_m**2))),
        ):
            step = cell / PROBES_PER_CELL
            if rms > 0:
                step = min(step, 2.0 * np.sqrt(SAMPLING_LOSS) / (k * rms))
            lo = max(min(-half, pos.min() - cell), -1.0)
            hi = min(max(half, pos.max() + cell), 1.0)
            grids.append(np.linspace(lo, hi, int(np.ceil((hi - lo) / step)) + 1))
        # On a grid the steering vector factors into a row along u and a column along s, so
        # the response at all probes is one matrix product per FE.
        src = plane_waves(array, u, s) if vectors is None else vectors
        look_u = np.exp(-1j * k * np.outer(grids[0], array.y_m))
        look_s = np.exp(-1j * k * np.outer(array.z_m, grids[1]))
        f = np.stack([((look_u * src[:, q]) @ look_s).ravel() for q in range(src.shape[1])])
        pu, ps = (g.ravel() for g in np.meshgrid(*grids, indexing="ij"))
        visible = pu * pu + ps * ps < 1.0
        visible_at = np.flatnonzero(visible)
        pu, ps, f = pu[visible], ps[visible], f[:, visible]
        bound = np.abs(f).max(axis=0)
        order = np.argsort(-bound, kind="stable")
        f = f[:, order]
        probe_at = np.full(visible.size, -1, dtype=np.int64)
        probe_at[visible_at[order]] = np.arange(order.size)
        return cls(
            response=array.source_response(u, s, vectors), probe_u=pu[order], probe_s=ps[order],
            probe_re=np.ascontiguousarray(f.real), probe_im=np.ascontiguousarray(f.imag),
            bound=bound[order], cell_u=cell_u, cell_s=cell_s,
            y_m=np.asarray(array.y_m, dtype=np.float64),
            z_m=np.asarray(array.z_m, dtype=np.float64),
            wavenumber=float(k), probe_cell=visible_at[order].astype(np.int64), probe_at=probe_at,
            grid_shape=(grids[0].size, grids[1].size),
        )

    @property
    def n_probes(self) -> int:
        """Number of probe directions P."""
        return int(self.probe_u.size)

    def splits(
        self, az_rad: FloatArray, el_rad: FloatArray, weights: FloatArray, margin: float = 0.0
    ) -> NDArray[np.bool_]:
        """Whether another direction out-shines the set one or shows a ghost, shape ``(N,)``.

        ``weights`` has shape ``(N, 4)``, >= 0. With ``margin`` a direction counts already
        when it comes within that fraction more of the set direction's ``|B|`` (a ghost: of
        `GHOST_POWER` of its power).
        """
        u, s = direction_cosines(az_rad, el_rad)
        at_target = np.abs(np.einsum("qn,nq->n", self.response.evaluate(u, s, terms=1)[0], weights))
        limit = at_target * (1.0 - SAMPLING_LOSS - margin)
        ghost = limit * np.sqrt(GHOST_POWER)
        total = weights.sum(axis=1)
        # Probes below the bound cannot reach the ghost level; a hair of slack covers the
        # rounding of the products below, so pruning never changes the outcome.
        floor = np.where(total > 0.0, ghost / np.where(total > 0.0, total, 1.0), 0.0)
        reach = np.searchsorted(-self.bound, -floor * (1.0 - 1e-9), side="right")
        split = np.zeros(u.shape, dtype=bool)
        active = np.flatnonzero(reach > 0)
        start = 0
        while active.size:
            stop = start + max(_MIN_BLOCK, BLOCK_ELEMENTS // active.size)
            w = weights[active]
            power = w @ self.probe_re[:, start:stop]
            power *= power
            im = w @ self.probe_im[:, start:stop]
            power += im * im
            # Few probes reach the ghost level (mostly the target's own main lobe): measure
            # distances only for those.
            rows, cols = np.nonzero(power >= (ghost[active] ** 2)[:, None])
            target = active[rows]
            probes = start + cols
            du = self.probe_u[probes] - u[target]
            ds = self.probe_s[probes] - s[target]
            far = (du / self.cell_u) ** 2 + (ds / self.cell_s) ** 2 > EXCLUSION_CELLS**2
            level = power[rows, cols]
            brighter = level >= limit[target] ** 2
            weaker = far & ~brighter
            if weaker.any():
                # A weaker peak: a ghost where it is a local maximum the radar's own pattern
                # does not explain (local maxima are few: tested first).
                weaker[weaker] = self._peak(weights[target[weaker]], probes[weaker],
                                            level[weaker])
                weaker[weaker] = self._own_lobe(du[weaker], ds[weaker]) < GHOST_POWER
            hit = np.zeros(active.size, dtype=bool)
            hit[rows[(far & brighter) | weaker]] = True
            split[active[hit]] = True
            active = active[~hit & (reach[active] > stop)]
            start = stop
        return split

    def _peak(
        self, weights: FloatArray, probes: NDArray[np.intp], level: FloatArray
    ) -> NDArray[np.bool_]:
        """Whether ``|B|^2`` at ``probes`` is at least that at their eight grid neighbours.

        ``level`` is ``|B|^2`` at the probes with ``weights`` (shape ``(C, 4)``); neighbours
        off the grid or not visible do not count.
        """
        n_u, n_s = self.grid_shape
        iu, js = np.divmod(self.probe_cell[probes], n_s)
        nu = iu[:, None] + _NEIGHBOURS[:, 0]
        ns = js[:, None] + _NEIGHBOURS[:, 1]
        inside = (nu >= 0) & (nu < n_u) & (ns >= 0) & (ns < n_s)
        at = np.where(inside, self.probe_at[np.where(inside, nu * n_s + ns, 0)], -1)
        cols = np.maximum(at, 0)  # (C, 8)
        re = np.einsum("cq,qck->ck", weights, self.probe_re[:, cols])
        im = np.einsum("cq,qck->ck", weights, self.probe_im[:, cols])
        around = np.where(at >= 0, re * re + im * im, -np.inf)
        return np.all(level[:, None] >= around, axis=1)

    def _own_lobe(self, du: FloatArray, ds: FloatArray) -> FloatArray:
        """Power of the array's own pattern ``(du, ds)`` off a plane wave, relative to its peak."""
        beam = np.exp(1j * self.wavenumber * (np.outer(du, self.y_m) + np.outer(ds, self.z_m)))
        return np.abs(beam.mean(axis=1)) ** 2


# Offsets of a probe's eight neighbours on the grid (along u, along s).
_NEIGHBOURS = np.array([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if a or b], dtype=np.intp)
