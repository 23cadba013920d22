"""Check that the synthesized peak is the global maximum of |B| (else the echoes split).

For each quad a grid of probe directions is laid over the FEs' region, extended by one
resolution cell, and the FEs' responses at the probes are precomputed. A solution splits when a
probe farther than half a resolution cell from the set direction sees ``|B|`` within the probe
grid's sampling loss of the set direction's ``|B|`` (closer than that, a second peak could not
be resolved by the radar and the local-maximum test of the method applies).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..arrays import SourceResponse, VirtualArray, direction_cosines
from ..rig import Rig

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

PROBES_PER_CELL = 8
EXCLUSION_CELLS = 0.5
# A peak between probes is at most this much higher than the best probe near it (a sinc main
# lobe sampled every 1/8 cell, worst case half a diagonal step off).
SAMPLING_LOSS = 0.015


@dataclass(frozen=True)
class GlobalMaxCheck:
    """Precomputed probe responses of one quad."""

    response: SourceResponse
    probe_u: FloatArray
    probe_s: FloatArray
    probe_f: ComplexArray
    cell_u: float
    cell_s: float

    @classmethod
    def build(cls, rig: Rig, array: VirtualArray, fes: NDArray[np.int64]) -> GlobalMaxCheck:
        """Lay the probe grid over the quad's FEs for ``array``."""
        u, s = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
        ap_y, ap_z = array.sinc_aperture_m()
        cell_u = array.wavelength_m / ap_y if ap_y > 0 else 2.0
        cell_s = array.wavelength_m / ap_z if ap_z > 0 else 2.0
        grids = []
        for pos, cell in ((u, cell_u), (s, cell_s)):
            lo, hi = pos.min() - cell, pos.max() + cell
            count = int(np.ceil((hi - lo) / cell * PROBES_PER_CELL)) + 1
            grids.append(np.linspace(max(lo, -1.0), min(hi, 1.0), count))
        pu, ps = (g.ravel() for g in np.meshgrid(*grids))
        visible = pu * pu + ps * ps < 1.0
        pu, ps = pu[visible], ps[visible]
        response = array.source_response(u, s)
        return cls(
            response=response, probe_u=pu, probe_s=ps,
            probe_f=response.evaluate(pu, ps, terms=1)[0].T,
            cell_u=cell_u, cell_s=cell_s,
        )

    def splits(
        self, az_rad: FloatArray, el_rad: FloatArray, weights: FloatArray
    ) -> NDArray[np.bool_]:
        """Whether another direction out-shines the set one, shape ``(N,)``."""
        u, s = direction_cosines(az_rad, el_rad)
        at_target = np.abs(np.einsum("qn,nq->n", self.response.evaluate(u, s, terms=1)[0], weights))
        at_probes = np.abs(weights @ self.probe_f.T)
        far = (((self.probe_u[None, :] - u[:, None]) / self.cell_u) ** 2
               + ((self.probe_s[None, :] - s[:, None]) / self.cell_s) ** 2) > EXCLUSION_CELLS**2
        strongest_far = np.where(far, at_probes, 0.0).max(axis=1, initial=0.0)
        return strongest_far >= at_target * (1.0 - SAMPLING_LOSS)
