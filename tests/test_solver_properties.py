"""Numerical invariants of the solver over random targets and random misaligned quads."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rts_scenario as rs
from rts_scenario.peak_search import find_peak, snapshot

ARRAYS = {name: rs.VirtualArray.preset(name) for name in ("paper", "awr1843boost")}
KIT = rs.Rig.preset("kit-table1")

angles = st.floats(allow_nan=False, allow_infinity=False)
common = settings(max_examples=60, deadline=None,
                  suppress_health_check=[HealthCheck.too_slow])


@st.composite
def misaligned_quads(draw):
    """A quad roughly square, each FE moved by up to 2 deg, paper order kept."""
    half_az = draw(st.floats(3.0, 8.0))
    half_el = draw(st.floats(5.0, 10.0))
    centre_az = draw(st.floats(-15.0, 15.0))
    centre_el = draw(st.floats(-6.0, 6.0))
    jitter = [draw(st.floats(-2.0, 2.0)) for _ in range(8)]
    az = centre_az + np.array([-half_az, half_az, -half_az, half_az]) + jitter[:4]
    el = centre_el + np.array([-half_el, -half_el, half_el, half_el]) + jitter[4:]
    return rs.Rig.from_angles(az, el)


def assert_weights_well_formed(sol):
    w = sol.weights
    assert np.all(np.isfinite(w))
    assert np.all(w >= 0.0)
    np.testing.assert_array_equal(w[sol.feasible].max(axis=1), 1.0)
    assert np.all(w[~sol.feasible] == 0.0)
    assert np.all((sol.quad >= 0) | (sol.reason == rs.Reason.OUTSIDE))


@common
@given(
    az=st.lists(angles.map(lambda v: v % 16 - 8), min_size=1, max_size=20),
    data=st.data(),
    method=st.sampled_from(["paper", "exact"]),
    array_name=st.sampled_from(sorted(ARRAYS)),
)
def test_weights_are_finite_non_negative_and_normalized(az, data, method, array_name):
    el = data.draw(st.lists(angles.map(lambda v: v % 24 - 12), min_size=len(az),
                            max_size=len(az)))
    sol = rs.solve_weights(az, el, rig=KIT, array=ARRAYS[array_name], method=method)
    assert_weights_well_formed(sol)


def _assert_exact_peaks(sol, rig, array, az, el):
    ok = sol.feasible
    if not ok.any():
        return
    fes = rig.quads[sol.quad[ok]]
    x = snapshot(array, sol.weights[ok], rig.az_deg[fes], rig.el_deg[fes])
    p_az, p_el = find_peak(
        array, x,
        az_range_deg=(rig.az_deg.min() - 10, rig.az_deg.max() + 10),
        el_range_deg=(rig.el_deg.min() - 10, rig.el_deg.max() + 10),
    )
    np.testing.assert_allclose(p_az, np.asarray(az)[ok], atol=1e-3, rtol=0)
    np.testing.assert_allclose(p_el, np.asarray(el)[ok], atol=1e-3, rtol=0)


@common
@given(
    a=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=8),
    data=st.data(),
    array_name=st.sampled_from(sorted(ARRAYS)),
)
def test_exact_feasible_targets_peak_at_the_set_angle(a, data, array_name):
    b = data.draw(st.lists(st.floats(0.0, 1.0), min_size=len(a), max_size=len(a)))
    az = -5.4 + np.array(a) * 9.9
    el = -8.8 + np.array(b) * 18.7
    array = ARRAYS[array_name]
    sol = rs.solve_weights(az, el, rig=KIT, array=array, method="exact")
    assert_weights_well_formed(sol)
    _assert_exact_peaks(sol, KIT, array, az, el)


@common
@given(rig=misaligned_quads(), a=st.floats(0.1, 0.9), b=st.floats(0.1, 0.9),
       array_name=st.sampled_from(sorted(ARRAYS)))
def test_exact_on_random_misaligned_quads(rig, a, b, array_name):
    # A point inside the quad by bilinear interpolation of its corners.
    az0, az1, az2, az3 = rig.az_deg
    el0, el1, el2, el3 = rig.el_deg
    az = (1 - a) * (1 - b) * az0 + a * (1 - b) * az1 + (1 - a) * b * az2 + a * b * az3
    el = (1 - a) * (1 - b) * el0 + a * (1 - b) * el1 + (1 - a) * b * el2 + a * b * el3
    array = ARRAYS[array_name]
    sol = rs.solve_weights([az], [el], rig=rig, array=array, method="exact")
    # Away from the edges (whose exact reach bows by the cos(el) coupling) every point of a
    # quad narrower than the main lobe is synthesizable.
    assert sol.feasible[0], sol.explain(0)
    assert_weights_well_formed(sol)
    _assert_exact_peaks(sol, rig, array, [az], [el])
