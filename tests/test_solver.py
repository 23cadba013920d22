from decimal import Decimal, getcontext

import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.evaluation import angle_errors
from rts_scenario.peak_search import find_peak, snapshot
from rts_scenario.solver.paper import sinc_slope

METHODS = ["paper", "exact"]
SQUARE = rs.Rig.from_angles([-5.0, 5.0, -5.0, 5.0], [-8.0, -8.0, 8.0, 8.0])


def peak_errors(sol, rig, array, az, el, window=12.0, step=0.25):
    """Errors (deg) of the independent Bartlett peak against the set angles, feasible rows."""
    ok = sol.feasible
    fes = rig.quads[sol.quad[ok]]
    x = snapshot(array, sol.weights[ok], rig.az_deg[fes], rig.el_deg[fes])
    lo_az, hi_az = rig.az_deg.min() - window, rig.az_deg.max() + window
    lo_el, hi_el = rig.el_deg.min() - window, rig.el_deg.max() + window
    p_az, p_el = find_peak(array, x, az_range_deg=(lo_az, hi_az), el_range_deg=(lo_el, hi_el),
                           grid_step_deg=step)
    return p_az - np.asarray(az)[ok], p_el - np.asarray(el)[ok]


# --- acceptance figures on the paper's grid ----------------------------------------------


def test_paper_method_reproduces_papers_misalignment_error(kit_rig):
    sol, err_az, err_el = angle_errors("paper", rs.VirtualArray.preset("paper"), kit_rig)
    rms_az, rms_el = np.sqrt(np.mean(err_az**2)), np.sqrt(np.mean(err_el**2))
    # DESIGN.md 5.2: about 0.23 deg rms in azimuth, 0.33 deg in elevation, max about 0.57 deg,
    # to the figures' last digit (measured 0.2266, 0.3279, 0.5723).
    assert sol.feasible.all()
    assert rms_az == pytest.approx(0.23, abs=0.005)
    assert rms_el == pytest.approx(0.33, abs=0.005)
    assert max(np.abs(err_az).max(), np.abs(err_el).max()) == pytest.approx(0.57, abs=0.005)


def test_exact_method_hits_the_set_angle_on_the_grid(kit_rig, array):
    sol, err_az, err_el = angle_errors("exact", array, kit_rig)
    assert sol.feasible.all()
    # DESIGN.md 5.3: the Bartlett peak on the set angle to < 1e-4 deg.
    assert np.abs(err_az).max() < 1e-4
    assert np.abs(err_el).max() < 1e-4


# --- targets on and next to an FE ----------------------------------------------------------


@pytest.mark.parametrize("fe", range(4))
@pytest.mark.parametrize("offset_deg", [0.0, 1e-9, -1e-9])
def test_exact_on_and_next_to_each_fe(kit_rig, array, fe, offset_deg):
    # Positive offsets step into the quad, negative ones out of it.
    az = kit_rig.az_deg[fe] + offset_deg * (1 if fe in (0, 2) else -1)
    el = kit_rig.el_deg[fe] + offset_deg * (1 if fe in (0, 1) else -1)
    sol = rs.solve_weights([az], [el], rig=kit_rig, array=array, method="exact")
    if offset_deg < 0 and sol.reason[0] == rs.Reason.OUTSIDE:
        return
    assert sol.feasible[0], sol.explain(0)
    assert np.all(np.isfinite(sol.weights)) and sol.weights.max() == 1.0
    assert sol.weights[0, fe] == pytest.approx(1.0)
    err_az, err_el = peak_errors(sol, kit_rig, array, [az], [el])
    assert max(abs(err_az[0]), abs(err_el[0])) <= 1e-3


def test_exact_weights_are_continuous_at_an_fe(kit_rig, array):
    az0, el0 = kit_rig.az_deg[3], kit_rig.el_deg[3]
    sol = rs.solve_weights([az0, az0 - 1e-9, az0, az0 - 1e-7], [el0, el0, el0 - 1e-9, el0 - 1e-7],
                           rig=kit_rig, array=array, method="exact")
    assert sol.feasible.all()
    np.testing.assert_allclose(sol.weights[1:3], sol.weights[[0, 0]], atol=1e-6)
    np.testing.assert_allclose(sol.weights[3], sol.weights[0], atol=1e-4)


@pytest.mark.parametrize("fe", range(4))
def test_paper_on_each_fe_of_an_aligned_quad(fe):
    array = rs.VirtualArray.preset("paper")
    az, el = SQUARE.az_deg[fe], SQUARE.el_deg[fe]
    on = rs.solve_weights([az], [el], rig=SQUARE, array=array, method="paper")
    expected = np.eye(4)[fe]
    np.testing.assert_array_equal(on.weights[0], expected)
    # 1e-9 deg inside: the far weights grow linearly from 0, no 0/0 blow-up.
    step = 1e-9
    near = rs.solve_weights([az + (step if fe in (0, 2) else -step)],
                            [el + (step if fe in (0, 1) else -step)],
                            rig=SQUARE, array=array, method="paper")
    assert near.feasible[0]
    np.testing.assert_allclose(near.weights[0], expected, atol=1e-8)
    assert np.all(near.weights[0] > 0)


def _sinc_slope_reference(x: float) -> float:
    """(pi x cos(pi x) - sin(pi x)) / (pi x^2) in 60-digit decimal arithmetic."""
    getcontext().prec = 60
    pi = Decimal("3.14159265358979323846264338327950288419716939937510582097494")
    xd = Decimal(repr(x))
    t = pi * xd

    def series(z: Decimal, start: int) -> Decimal:  # sin (start=1) or cos (start=0)
        total, term, n = Decimal(0), (z if start else Decimal(1)), start
        while abs(term) > Decimal(10) ** -70:
            total += term
            term = -term * z * z / ((n + 1) * (n + 2))
            n += 2
        return total

    return float((t * series(t, 0) - series(t, 1)) / (pi * xd * xd))


@pytest.mark.parametrize("x", [1e-15, -1e-12, 1e-9, 3e-6, 1e-3, 0.1, -0.159, 0.16, 0.5, 1.3, -7.7])
def test_sinc_slope_is_accurate_where_the_formula_cancels(x):
    assert sinc_slope(np.array([x]))[0] == pytest.approx(_sinc_slope_reference(x), rel=1e-13)
    assert sinc_slope(np.array([0.0]))[0] == 0.0


# --- symmetric mid-points -------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_centre_of_a_square_quad_has_equal_weights(method):
    array = rs.VirtualArray.preset("paper")
    sol = rs.solve_weights([0.0], [0.0], rig=SQUARE, array=array, method=method)
    np.testing.assert_allclose(sol.weights[0], [1, 1, 1, 1], rtol=1e-12)


def test_paper_edge_midpoints_of_a_square_quad_use_two_fes():
    array = rs.VirtualArray.preset("paper")
    sol = rs.solve_weights([0.0, 0.0, -5.0, 5.0], [-8.0, 8.0, 0.0, 0.0], rig=SQUARE, array=array,
                           method="paper")
    expected = [[1, 1, 0, 0], [0, 0, 1, 1], [1, 0, 1, 0], [0, 1, 0, 1]]
    np.testing.assert_allclose(sol.weights, expected, atol=1e-12)


def test_exact_edge_midpoints_of_a_square_quad():
    array = rs.VirtualArray.preset("paper")
    # Bottom and top edges: the pair shares its elevation, so two FEs reach the midpoint.
    sol = rs.solve_weights([0.0, 0.0], [-8.0, 8.0], rig=SQUARE, array=array, method="exact")
    np.testing.assert_allclose(sol.weights, [[1, 1, 0, 0], [0, 0, 1, 1]], atol=1e-12)
    # Side edges: FEs at az -5 deg and el +-8 deg sit at u = cos(8 deg) sin(-5 deg), closer to
    # boresight than u = sin(-5 deg) of the target at el 0: no superposition reaches it.
    side = rs.solve_weights([-5.0, 5.0], [0.0, 0.0], rig=SQUARE, array=array, method="exact")
    assert np.all(side.reason == rs.Reason.NO_SOLUTION)
    inside = rs.solve_weights([-4.9, 4.9], [0.0, 0.0], rig=SQUARE, array=array, method="exact")
    assert inside.feasible.all()


def test_exact_puts_square_edge_midpoints_on_the_set_angle():
    array = rs.VirtualArray.preset("paper")
    az, el = [0.0, -5.0, 2.5], [-8.0, 0.0, 4.0]
    sol = rs.solve_weights(az, el, rig=SQUARE, array=array, method="exact")
    err_az, err_el = peak_errors(sol, SQUARE, array, az, el)
    assert np.abs(err_az).max() <= 1e-3 and np.abs(err_el).max() <= 1e-3


# --- degenerate quads -----------------------------------------------------------------------

EQUAL_AZ = rs.Rig.from_angles([2.0, 2.0, 2.0, 2.0], [-8.0, -8.0, 8.0, 8.0])
EQUAL_EL = rs.Rig.from_angles([-5.0, 5.0, -5.0, 5.0], [3.0, 3.0, 3.0, 3.0])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("rig, on_line, off_line", [
    (EQUAL_AZ, ([2.0, 2.0, 2.0], [-4.0, 0.0, 7.0]), ([1.0, 3.0, 2.5], [0.0, 0.0, -4.0])),
    (EQUAL_EL, ([-4.0, 0.0, 3.0], [3.0, 3.0, 3.0]), ([0.0, 0.0, 4.0], [2.0, 4.0, 3.5])),
], ids=["equal-azimuths", "equal-elevations"])
def test_degenerate_quads(array, method, rig, on_line, off_line):
    off = rs.solve_weights(*off_line, rig=rig, array=array, method=method)
    assert np.all(off.reason == rs.Reason.DEGENERATE)
    assert "degenerate" in off.explain(0)
    assert np.all(off.weights == 0.0)
    on = rs.solve_weights(*on_line, rig=rig, array=array, method=method)
    assert np.all(on.reason != rs.Reason.DEGENERATE)
    assert np.all(np.isfinite(on.weights)) and np.all(on.weights >= 0)
    if method == "exact":
        # Never a wrong angle: whatever is feasible is exact.
        err_az, err_el = peak_errors(on, rig, array, *on_line)
        assert np.all(np.abs(err_az) <= 1e-3) and np.all(np.abs(err_el) <= 1e-3)


def test_equal_elevation_line_is_synthesized_exactly_by_a_symmetric_array():
    array = rs.VirtualArray.preset("paper")
    az, el = [-4.0, 0.0, 3.0], [3.0, 3.0, 3.0]
    sol = rs.solve_weights(az, el, rig=EQUAL_EL, array=array, method="exact")
    assert sol.feasible.all()
    err_az, err_el = peak_errors(sol, EQUAL_EL, array, az, el)
    assert np.abs(err_az).max() <= 1e-3 and np.abs(err_el).max() <= 1e-3


# --- FEs too far apart: split echoes ----------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_fe_spacing_wider_than_main_lobe_is_flagged_split(method):
    array = rs.VirtualArray.preset("awr1843boost")
    rig = rs.Rig.from_angles([-30.0, 30.0, -30.0, 30.0], [-20.0, -20.0, 20.0, 20.0])
    az, el = (g.ravel() for g in np.meshgrid(np.linspace(-29, 29, 15), np.linspace(-19, 19, 9)))
    sol = rs.solve_weights(az, el, rig=rig, array=array, method=method)
    assert np.sum(sol.reason == rs.Reason.SPLIT) > len(az) // 5
    assert "split" in rs.Reason.SPLIT.description
    centre = rs.solve_weights([0.0], [0.0], rig=rig, array=array, method=method)
    assert centre.reason[0] in (rs.Reason.SPLIT, rs.Reason.NO_SOLUTION)
    if method == "exact":
        # Whatever is still called feasible really peaks at the set angle (global search).
        err_az, err_el = peak_errors(sol, rig, array, az, el, window=30.0, step=0.5)
        assert np.abs(err_az).max() <= 1e-3 and np.abs(err_el).max() <= 1e-3


# --- coverage, invalid input, sizes -------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_targets_outside_every_quad(kit_rig, array, method):
    sol = rs.solve_weights([10.0, 0.0, -10.0, 0.0], [0.0, 20.0, -20.0, -9.5], rig=kit_rig,
                           array=array, method=method)
    assert np.all(sol.reason == rs.Reason.OUTSIDE)
    assert np.all(sol.quad == -1) and np.all(sol.weights == 0.0)
    assert sol.explain(0) == "outside every quad of the rig"


@pytest.mark.parametrize("method", METHODS)
def test_elevations_near_the_poles(kit_rig, array, method):
    el = [90.0, -90.0, 89.999999, -89.999999, 90.0]
    sol = rs.solve_weights([0.0, 0.0, 45.0, -45.0, 89.0], el, rig=kit_rig, array=array,
                           method=method)
    assert np.all(sol.reason == rs.Reason.OUTSIDE)
    assert np.all(np.isfinite(sol.weights))


def test_quad_near_the_zenith(array):
    rig = rs.Rig.from_angles([-30.0, 30.0, -30.0, 30.0], [78.0, 78.0, 86.0, 86.0])
    az, el = [0.0, -20.0, 10.0, 0.0], [80.0, 82.0, 85.0, 86.0]
    sol = rs.solve_weights(az, el, rig=rig, array=array, method="exact")
    assert np.all(np.isfinite(sol.weights))
    assert sol.feasible.sum() >= 3
    err_az, err_el = peak_errors(sol, rig, array, az, el, window=3.0, step=0.1)
    # Near the zenith azimuth is compressed by cos(el): compare on the sphere.
    assert np.all(np.abs(err_el) <= 1e-3)
    assert np.all(np.abs(err_az) * np.cos(np.radians(np.asarray(el)[sol.feasible])) <= 1e-3)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_angles_are_a_clear_error(kit_rig, bad):
    array = rs.VirtualArray.preset("paper")
    with pytest.raises(rs.SolverError, match=r"el_deg\[2\]: must be a finite angle"):
        rs.solve_weights([0.0, 1.0, 2.0], [0.0, 1.0, bad], rig=kit_rig, array=array)


def test_other_bad_calls(kit_rig):
    array = rs.VirtualArray.preset("paper")
    with pytest.raises(rs.SolverError, match="valid methods: paper, exact"):
        rs.solve_weights([0.0], [0.0], rig=kit_rig, array=array, method="fast")
    with pytest.raises(rs.SolverError, match="same length"):
        rs.solve_weights([0.0, 1.0], [0.0], rig=kit_rig, array=array)
    with pytest.raises(rs.SolverError, match="within -90..90"):
        rs.solve_weights([0.0], [91.0], rig=kit_rig, array=array)
    with pytest.raises(rs.SolverError, match=r"az_deg\[1\]: must be within -90..90"):
        rs.solve_weights([90.0, -90.5], [0.0, -90.0], rig=kit_rig, array=array)
    with pytest.raises(rs.SolverError, match="must be numbers"):
        rs.solve_weights(["left"], [0.0], rig=kit_rig, array=array)
    line = rs.VirtualArray.from_positions([0.0, 0.002, 0.004], [0.0, 0.0, 0.0], wavelength_m=0.004)
    for method in METHODS:
        with pytest.raises(rs.SolverError, match="along z"):
            rs.solve_weights([0.0], [0.0], rig=kit_rig, array=line, method=method)


@pytest.mark.parametrize("method", METHODS)
def test_bad_angles_in_later_chunks_are_named_by_their_index_in_all(kit_rig, method):
    # Angles are range-checked chunk by chunk on the worker threads: the error still names the
    # first bad angle of all of them, and counts them all, whichever chunk found one first.
    from rts_scenario.solver import CHUNK

    n = 3 * CHUNK + 5
    az, el = np.zeros(n), np.zeros(n)
    az[[2 * CHUNK + 7, 3 * CHUNK + 1]] = np.nan
    el[CHUNK + 3] = 95.0  # az is checked first, as before
    array = rs.VirtualArray.preset("paper")
    with pytest.raises(rs.SolverError, match=(rf"^az_deg\[{2 * CHUNK + 7}\]: must be a finite "
                                              rf"angle in degrees, got nan \(2 non-finite")):
        rs.solve_weights(az, el, rig=kit_rig, array=array, method=method)
    az[:] = 0.0
    with pytest.raises(rs.SolverError, match=rf"^el_deg\[{CHUNK + 3}\]: must be within "):
        rs.solve_weights(az, el, rig=kit_rig, array=array, method=method)
    el[CHUNK + 3] = 0.0
    sol = rs.solve_weights(az, el, rig=kit_rig, array=array, method=method)
    assert sol.feasible.all() and (sol.quad == 0).all()


@pytest.mark.parametrize("method", METHODS)
def test_no_targets(kit_rig, method):
    sol = rs.solve_weights([], [], rig=kit_rig, array=rs.VirtualArray.preset("paper"),
                           method=method)
    assert sol.weights.shape == (0, 4) and sol.quad.shape == (0,) and sol.feasible.shape == (0,)


def test_scalar_target(kit_rig):
    sol = rs.solve_weights(1.0, 2.0, rig=kit_rig, array=rs.VirtualArray.preset("paper"))
    assert sol.weights.shape == (1, 4) and sol.feasible[0]


@pytest.mark.parametrize("method", METHODS)
def test_ten_million_targets(kit_rig, method):
    array = rs.VirtualArray.preset("paper")
    rng = np.random.default_rng(7)
    n = 10**7
    az = rng.uniform(-3.0, 3.0, n)
    el = rng.uniform(-6.0, 6.0, n)
    sol = rs.solve_weights(az, el, rig=kit_rig, array=array, method=method)
    assert sol.weights.shape == (n, 4)
    assert sol.feasible.all()
    assert np.isfinite(sol.weights).all()
    np.testing.assert_array_equal(sol.weights.max(axis=1), 1.0)
    # Chunking and threads change nothing: a sample solved on its own agrees to rounding.
    pick = rng.choice(n, 50, replace=False)
    alone = rs.solve_weights(az[pick], el[pick], rig=kit_rig, array=array, method=method)
    np.testing.assert_allclose(alone.weights, sol.weights[pick], rtol=1e-12, atol=1e-14)


# --- grid rigs ----------------------------------------------------------------------------------


def test_grid_rig_crossing_quad_borders_keeps_the_angle(array):
    rig = rs.Rig.preset("wide-3x5")
    az = np.linspace(-20.0, 20.0, 161)
    el = np.full_like(az, 3.3)
    sol = rs.solve_weights(az, el, rig=rig, array=array, method="exact")
    assert sol.feasible.all()
    assert len(set(sol.quad.tolist())) == 4
    err_az, err_el = peak_errors(sol, rig, array, az, el)
    assert np.abs(err_az).max() <= 1e-3 and np.abs(err_el).max() <= 1e-3
    # At a shared column the far FEs carry (almost) nothing: the hand-over is smooth.
    border = np.isclose(az, 0.0)
    fes = rig.quads[sol.quad[border]][0]
    far = [i for i, fe in enumerate(fes) if not np.isclose(rig.az_deg[fe], 0.0)]
    assert sol.weights[border][0, far].max() < 0.05


def test_wide_rig_covers_its_field(array):
    rig = rs.Rig.preset("wide-3x5")
    az, el = (g.ravel() for g in np.meshgrid(np.linspace(-20, 20, 81), np.linspace(-8, 8, 33)))
    for method in METHODS:
        sol = rs.solve_weights(az, el, rig=rig, array=array, method=method)
        assert sol.feasible.all(), sol.counts()


def test_modeled_bench_leaves_no_gap_between_stacked_quads():
    # On the modeled bench the edge of a quad's region moves with B's phase, and the phase
    # map's phase is off by ~5e-4 rad near it: judged there, a band ~0.0007 deg wide between
    # the two lower rows' quads was synthesized by neither. Judged at the phase fixed point,
    # every target across it is.
    from rts_scenario.schedule.build import solver_inputs

    radar, rig = rs.RadarProfile.preset("awr1843boost"), rs.Rig.preset("wide-3x5")
    array, model = solver_inputs(radar, "modeled")  # what a run's schedule solves with
    el = np.linspace(0.15, 0.20, 1001)  # across the border of the two lower rows' quads
    for az0 in (-15.0, -5.0, 1.8144, 5.0, 15.0):
        sol = rs.solve_weights(np.full_like(el, az0), el, rig=rig, array=array,
                               method="exact", model=model)
        assert sol.feasible.all(), (az0, el[~sol.feasible])


@pytest.mark.parametrize("jit", ["on", "off"])
def test_plane_waves_leave_no_gap_between_the_slanted_quads_of_lab_2x3(jit, monkeypatch):
    # The two quads of lab-2x3 share a slanted column of FEs (0.1, -7.9) .. (-0.2, 8.3) deg.
    # Within 0.2 .. 0.55 mdeg of it on the second quad's side (the first's is outside), the
    # awr1843boost's phase fixed point lies 0.01 .. 0.03 rad from the phase map's: a target
    # stopped at 0.01 rad was synthesized by neither (a few udeg wide, at most points along
    # the column). Every target across it is, by the numpy path and the kernel alike.
    from pathlib import Path

    from rts_scenario.solver import compiled

    monkeypatch.setenv(compiled.JIT_ENV, jit)
    rig = rs.Rig.from_file(Path(__file__).parents[1] / "scenarios/rigs/lab-2x3.rig.yaml")
    array = rs.VirtualArray.preset("awr1843boost")
    p0 = np.array([rig.az_deg[1], rig.el_deg[1]])
    d = np.array([rig.az_deg[4], rig.el_deg[4]]) - p0
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)
    offset = np.arange(-6e-4, 2e-4, 2e-6)  # deg across the column
    points = np.concatenate([p0 + t * d + offset[:, None] * normal
                             for t in np.linspace(0.02, 0.98, 49)])
    sol = rs.solve_weights(points[:, 0], points[:, 1], rig=rig, array=array, method="exact")
    assert sol.feasible.all(), points[~sol.feasible]
    # The independent Bartlett peak on the set angle, for every 40th target.
    few = points[::40]
    some = rs.solve_weights(few[:, 0], few[:, 1], rig=rig, array=array, method="exact")
    err_az, err_el = peak_errors(some, rig, array, few[:, 0], few[:, 1])
    assert np.abs(err_az).max() <= 1e-4 and np.abs(err_el).max() <= 1e-4


def _in_triangle(p, a, b, c):
    def cross(o, u, v):
        return (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])
    d1, d2, d3 = cross(a, b, p), cross(b, c, p), cross(c, a, p)
    return not ((d1 < 0 or d2 < 0 or d3 < 0) and (d1 > 0 or d2 > 0 or d3 > 0))


def test_quad_assignment_on_a_measured_skewed_grid(rng):
    from pathlib import Path

    from rts_scenario.quads import distance_to_polygon
    from rts_scenario.solver import RETRY_MARGIN_DEG
    rig = rs.Rig.from_file(Path(__file__).parents[1] / "scenarios/rigs/lab-2x3.rig.yaml")
    az = rng.uniform(-12.0, 12.0, 400)
    el = rng.uniform(-10.0, 10.0, 400)
    sol = rs.solve_weights(az, el, rig=rig, array=rs.VirtualArray.preset("paper"), method="paper")
    for i in range(len(az)):
        owners = []
        for q, fes in enumerate(rig.quads):
            corners = [(rig.az_deg[f], rig.el_deg[f]) for f in fes[[0, 1, 3, 2]]]
            p = (az[i], el[i])
            if _in_triangle(p, *corners[:3]) or _in_triangle(p, corners[0], *corners[2:]):
                owners.append(q)
        if owners:
            if sol.quad[i] not in owners:
                # Only a target the enclosing quad cannot synthesize moves to a neighbour
                # within the retry margin.
                assert sol.feasible[i]
                fes = rig.quads[sol.quad[i]][[0, 1, 3, 2]]
                polygon = np.stack([rig.az_deg[fes], rig.el_deg[fes]], axis=1)
                dist = distance_to_polygon(az[i : i + 1], el[i : i + 1], polygon)[0]
                assert dist <= RETRY_MARGIN_DEG
                alone = rs.solve_weights(az[i], el[i], rig=rs.Rig.from_angles(
                    rig.az_deg[rig.quads[owners[0]]], rig.el_deg[rig.quads[owners[0]]]),
                    array=rs.VirtualArray.preset("paper"), method="paper")
                assert not alone.feasible[0]
        else:
            assert sol.reason[i] == rs.Reason.OUTSIDE and sol.quad[i] == -1, (az[i], el[i])
