"""The paper's evaluation grid and the angles the independent peak search sees there.

The reference against which solver methods, the bench table and calibration are measured:
set angles on the paper's grid (azimuth -3..3 deg, 6 values; elevation -6..6 deg, 5 values)
and where the Bartlett peak search of `rts_scenario.peak_search`, which knows nothing of the solver,
finds the synthesized targets.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .arrays import VirtualArray
from .peak_search import find_peak, snapshot
from .rig import Rig
from .solver import WeightSolution, solve_weights

FloatArray = NDArray[np.float64]

GRID_AZ_DEG = np.linspace(-3.0, 3.0, 6)
GRID_EL_DEG = np.linspace(-6.0, 6.0, 5)


def evaluation_grid() -> tuple[FloatArray, FloatArray]:
    """Return the paper's 6 x 5 grid of set angles, flattened: ``(az_deg, el_deg)``."""
    az, el = np.meshgrid(GRID_AZ_DEG, GRID_EL_DEG)
    return az.ravel(), el.ravel()


def synthesized_angles(
    solution: WeightSolution, rig: Rig, array: VirtualArray
) -> tuple[FloatArray, FloatArray]:
    """Where the radar's Bartlett beamformer sees each feasible target: ``(az_deg, el_deg)``."""
    ok = solution.feasible
    fes = rig.quads[solution.quad[ok]]
    x = snapshot(array, solution.weights[ok], rig.az_deg[fes], rig.el_deg[fes])
    lo_az, hi_az = rig.az_deg.min() - 10.0, rig.az_deg.max() + 10.0
    lo_el, hi_el = rig.el_deg.min() - 10.0, rig.el_deg.max() + 10.0
    return find_peak(array, x, az_range_deg=(lo_az, hi_az), el_range_deg=(lo_el, hi_el))


def angle_errors(
    method: str, array: VirtualArray, rig: Rig
) -> tuple[WeightSolution, FloatArray, FloatArray]:
    """Solve the evaluation grid; return the solution and the az/el errors of feasible points."""
    az, el = evaluation_grid()
    sol = solve_weights(az, el, rig=rig, array=array, method=method)
    peak_az, peak_el = synthesized_angles(sol, rig, array)
    return sol, peak_az - az[sol.feasible], peak_el - el[sol.feasible]
