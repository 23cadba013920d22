"""The paper's weights: eq. (eq_atten_a)/(eq_atten_b) with the sinc model, as written.

The paper models each FE's beamformer response as a product of two sincs,
``g_q[alpha] = sinc(N_rx d_y / lambda (sin theta_q - sin alpha))`` (and likewise in elevation with
``N_tx d_z``), averages the FE angles into left/right (``theta_l = mean(theta_0, theta_2)``, ...)
and bottom/top, and asks the derivative of the superposition to vanish at the set angle:

    A_l g'_l(alpha) + A_r g'_r(alpha) = 0,     A_b g'_b(beta) + A_t g'_t(beta) = 0,
    A_0 = A_b A_l,  A_1 = A_b A_r,  A_2 = A_t A_l,  A_3 = A_t A_r.

The derivative formula is 0/0 where ``sin theta_q = sin alpha``: a target at the averaged azimuth
(or elevation) of a pair, on an FE of an aligned quad. It is evaluated through the sinc slope,
with a Taylor series near zero instead of the difference of two large terms; there the far
pair's amplitude is 0, which rounding must not turn into a refusal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..arrays import VirtualArray
from ..errors import SolverError
from ..rig import Rig
from .reasons import Reason

FloatArray = NDArray[np.float64]

# Below |pi x| = 0.5 the series (terms to x^13) is exact to double precision; above, the closed
# form loses at most one digit to cancellation.
_SERIES_LIMIT = 0.5 / np.pi
# d/dx sinc(x) = sum_{n>=1} (-1)^n 2n pi^(2n) x^(2n-1) / (2n+1)!, coefficients of x^(2n-1).
_SERIES = [(-1) ** n * 2 * n * np.pi ** (2 * n) / float(np.prod(np.arange(1, 2 * n + 2)))
           for n in range(1, 8)]


def sinc_slope(x: FloatArray) -> FloatArray:
    """Return the derivative of the normalized sinc, ``d/dx sin(pi x)/(pi x)``, stable at 0."""
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < _SERIES_LIMIT
    x_safe = np.where(small, 1.0, x)
    px = np.pi * x_safe
    closed = (px * np.cos(px) - np.sin(px)) / (np.pi * x_safe * x_safe)
    x2 = x * x
    series = np.full_like(x, _SERIES[-1])
    for coef in _SERIES[-2::-1]:
        series = series * x2 + coef
    return np.where(small, series * x, closed)


def sinc_derivative(
    theta_rad: float | FloatArray, alpha_rad: FloatArray, aperture_wl: float
) -> FloatArray:
    """Return the paper's ``dg_q[alpha]/d alpha`` for an FE at ``theta``, aperture ``N d / lambda``.

    Equals, term for term, ``cos(a) sin(pi c D)/(pi c D^2) - cos(a) cos(pi c D)/D`` with
    ``D = sin(theta) - sin(alpha)`` and ``c = aperture_wl``, i.e. ``-c cos(alpha) sinc'(c D)``.
    """
    x = aperture_wl * (np.sin(theta_rad) - np.sin(alpha_rad))
    return -aperture_wl * np.cos(alpha_rad) * sinc_slope(x)


# Relative size below which a negative amplitude is rounding of a zero one (see pair_weights);
# it moves the synthesized angle by ~1e-11 deg at most.
_ROUNDING = 1e-12


def pair_weights(
    d_low: FloatArray, d_high: FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Solve ``A_low d_low + A_high d_high = 0`` for amplitudes with max 1.

    ``d_low`` is the derivative of the response of the FE pair at the smaller angle. Returns
    ``(A_low, A_high, ok)``; ``ok`` is False where the solution needs a negative amplitude (the
    angle lies outside the pair). Both derivatives zero (target on two coincident FEs) gives 1, 1.
    """
    a_low = d_high
    a_high = -d_low
    # On the pair's averaged angle the far derivative is 0 in the paper, and here the residue
    # of rounding the angles' sines (~1e-16 of the near one), of either sign: an amplitude that
    # negative is the paper's 0, not a target outside the pair.
    residue = _ROUNDING * np.maximum(np.abs(a_low), np.abs(a_high))
    a_low = np.where((a_low < 0.0) & (a_low >= -residue), 0.0, a_low)
    a_high = np.where((a_high < 0.0) & (a_high >= -residue), 0.0, a_high)
    both_zero = (a_low == 0.0) & (a_high == 0.0)
    ok = (a_low >= 0.0) & (a_high >= 0.0)
    scale = np.maximum(a_low, a_high)
    scale = np.where(ok & ~both_zero, scale, 1.0)
    a_low = np.where(both_zero, 1.0, a_low / scale)
    a_high = np.where(both_zero, 1.0, a_high / scale)
    return a_low, a_high, ok


@dataclass(frozen=True)
class PaperQuad:
    """Per-quad constants of the paper method: averaged angles and sinc apertures."""

    theta_l: float
    theta_r: float
    psi_b: float
    psi_t: float
    aperture_y_wl: float
    aperture_z_wl: float

    @classmethod
    def build(cls, rig: Rig, array: VirtualArray, fes: NDArray[np.int64]) -> PaperQuad:
        """Average the quad's FE angles as the paper assumes."""
        az = np.radians(rig.az_deg[fes])
        el = np.radians(rig.el_deg[fes])
        ap_y, ap_z = array.sinc_aperture_m()
        if ap_y == 0.0 or ap_z == 0.0:
            raise SolverError(
                f"array {array.name!r}: the paper method needs at least two distinct element "
                f"positions along y and along z, got apertures {ap_y:g} m and {ap_z:g} m"
            )
        return cls(
            theta_l=(az[0] + az[2]) / 2, theta_r=(az[1] + az[3]) / 2,
            psi_b=(el[0] + el[1]) / 2, psi_t=(el[2] + el[3]) / 2,
            aperture_y_wl=ap_y / array.wavelength_m, aperture_z_wl=ap_z / array.wavelength_m,
        )

    def solve(
        self, az_rad: FloatArray, el_rad: FloatArray
    ) -> tuple[FloatArray, NDArray[np.uint8]]:
        """Return ``(weights (N, 4), reason (N,))`` for targets in this quad."""
        a_l, a_r, ok_az = pair_weights(
            sinc_derivative(self.theta_l, az_rad, self.aperture_y_wl),
            sinc_derivative(self.theta_r, az_rad, self.aperture_y_wl),
        )
        a_b, a_t, ok_el = pair_weights(
            sinc_derivative(self.psi_b, el_rad, self.aperture_z_wl),
            sinc_derivative(self.psi_t, el_rad, self.aperture_z_wl),
        )
        weights = np.stack([a_b * a_l, a_b * a_r, a_t * a_l, a_t * a_r], axis=1)
        # Between the pair yet a negative amplitude: the sinc slopes changed sign, i.e. the FEs
        # are farther apart than the main lobe and the echoes split.
        within = ((az_rad >= self.theta_l) & (az_rad <= self.theta_r)
                  & (el_rad >= self.psi_b) & (el_rad <= self.psi_t))
        reason = np.where(
            ok_az & ok_el, Reason.OK, np.where(within, Reason.SPLIT, Reason.NO_SOLUTION)
        ).astype(np.uint8)
        return weights, reason
