"""The beamformer-peak Newton step against analytic references."""

import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.beamformer import hessian_step, newton_step

ARRAY = rs.VirtualArray.preset("paper")


def plane_wave_derivatives(u, s, u0, s0):
    """B = a(u, s)^H a(u0, s0) and its derivatives in (u, s), written out element by element."""
    k = 2.0 * np.pi / ARRAY.wavelength_m
    y, z = ARRAY.y_m[:, None], ARRAY.z_m[:, None]
    terms = np.exp(1j * k * (y * (u0 - u) + z * (s0 - s)))  # (elements, N)
    dy, dz = -1j * k * y, -1j * k * z
    return [np.sum(f * terms, axis=0) for f in (1.0, dy, dz, dy * dy, dy * dz, dz * dz)]


def test_newton_step_on_a_plane_wave_converges_quadratically():
    # P = |B|^2 / 2 for a plane wave on M elements at positions r_v: |B| <= M and each
    # directional derivative of B of order n is at most M (k R)^n (R = largest |r_v|), so the
    # Hessian of P is Lipschitz with L = 4 M^2 (k R)^3 (P''' = Re(3 conj(B') B'' + conj(B) B''')).
    # At the peak B' = 0 and the Hessian is -M k^2 sum_v r_v r_v^T, whose inverse is bounded by
    # beta = 1 / (M k^2 lambda_min). Newton's theorem (Dennis & Schnabel 5.2.1): from within
    # 1 / (2 beta L) of the peak, one step leaves an error below beta L |e0|^2.
    m = ARRAY.n_elements
    k = 2.0 * np.pi / ARRAY.wavelength_m
    positions = np.stack([ARRAY.y_m, ARRAY.z_m], axis=1)
    radius = np.max(np.hypot(ARRAY.y_m, ARRAY.z_m))
    lambda_min = np.linalg.eigvalsh(positions.T @ positions)[0]
    lipschitz = 4.0 * m**2 * (k * radius) ** 3
    beta = 1.0 / (m * k**2 * lambda_min)
    reach = 1.0 / (2.0 * beta * lipschitz)

    u0, s0 = np.sin(np.radians(2.0)) * np.cos(np.radians(-3.0)), np.sin(np.radians(-3.0))
    size = reach * np.array([0.95, 0.5, 0.2, 0.05])[:, None]
    heading = np.radians(np.arange(0.0, 360.0, 30.0))[None, :]
    u = (u0 + size * np.cos(heading)).ravel()
    s = (s0 + size * np.sin(heading)).ravel()
    e0 = np.hypot(u - u0, s - s0)

    du, ds, ok = newton_step(*plane_wave_derivatives(u, s, u0, s0))

    e1 = np.hypot(u + du - u0, s + ds - s0)
    assert ok.all()
    assert np.all(e1 <= beta * lipschitz * e0**2)


def test_newton_step_is_exact_on_a_quadratic_power():
    # B linear in (u, s): |B|^2 is a quadratic with its minimum where B = 0, which one step
    # must reach from anywhere (to rounding); |B|^2 curves up there, so not ok.
    rng = np.random.default_rng(7)
    n = 200
    b0, b_u, b_s = (rng.normal(size=n) + 1j * rng.normal(size=n) for _ in range(3))
    u, s = rng.uniform(-1.0, 1.0, (2, n))
    zero = np.zeros(n, complex)
    # B(u*, s*) = 0: two real equations in u*, s*.
    system = np.stack([np.stack([b_u.real, b_s.real], -1), np.stack([b_u.imag, b_s.imag], -1)], 1)
    target = np.linalg.solve(system, -np.stack([b0.real, b0.imag], -1)[..., None])[..., 0]

    du, ds, ok = newton_step(b0 + b_u * u + b_s * s, b_u, b_s, zero, zero, zero)

    np.testing.assert_allclose(np.stack([u + du, s + ds], -1), target, rtol=1e-9, atol=1e-9)
    assert not ok.any()


@pytest.mark.parametrize("curvature", ["down", "saddle"])
def test_hessian_step_reaches_the_stationary_point_of_a_quadratic(curvature):
    # f(x) = c + (x - x*)^T H (x - x*) / 2 has gradient H (x - x*): the step is x* - x exactly
    # when H is definite; a saddle (indefinite H) gives no step.
    rng = np.random.default_rng(11)
    n = 100
    rotation = rng.uniform(0.0, np.pi, n)
    eig = -rng.uniform(0.1, 10.0, (2, n))
    if curvature == "saddle":
        eig[1] *= -1.0
    c, sn = np.cos(rotation), np.sin(rotation)
    h_uu = eig[0] * c * c + eig[1] * sn * sn
    h_ss = eig[0] * sn * sn + eig[1] * c * c
    h_us = (eig[0] - eig[1]) * c * sn
    offset = rng.normal(size=(2, n))
    g_u = h_uu * offset[0] + h_us * offset[1]
    g_s = h_us * offset[0] + h_ss * offset[1]

    du, ds, ok = hessian_step(g_u, g_s, h_uu, h_us, h_ss)

    if curvature == "down":
        np.testing.assert_allclose(np.stack([du, ds]), -offset, rtol=1e-9, atol=1e-12)
        assert ok.all()
    else:
        assert np.all((du == 0.0) & (ds == 0.0)) and not ok.any()
