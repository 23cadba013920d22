"""The split check covers the radar's whole field of view, not just the quad's neighbourhood.

The references here are brute-force scans of ``|B(u, s)| = |a(u, s)^H x|`` written with numpy
from the definition (DESIGN.md section 5.1); they share no code with the solver.
"""

import numpy as np
import pytest
from cascade_arrays import cascade_like, compact_cascade, ti_cascade
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from scene_helpers import write_scene

import rts_scenario as rs
from rts_scenario.solver import globalmax
from rts_scenario.solver.exact import ExactQuad
from rts_scenario.solver.globalmax import GlobalMaxCheck

# The search region of the radar's Bartlett estimator (radar/angle.py), in direction cosines.
U_MAX, S_MAX = 0.8, 0.6
# Reference grid: points per resolution cell (wavelength / extent) along each axis.
REFERENCE_PER_CELL = 16
# The solver samples |B| on probes and may miss a far peak between them by its sampling loss
# (1.5 %); a feasible target's set direction must out-shine every far direction to that.
SAMPLING_TOL = 0.015


def cosines(az_deg, el_deg):
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.cos(el) * np.sin(az), np.sin(el)


def snapshots(array, amplitudes, fe_az_deg, fe_el_deg):
    """Array snapshots of the superposed FE echoes, shape (N, M)."""
    k = 2 * np.pi / array.wavelength_m
    fu, fs = cosines(fe_az_deg, fe_el_deg)
    return amplitudes @ np.exp(1j * k * (np.outer(fu, array.y_m) + np.outer(fs, array.z_m)))


def beam(array, x, u, s):
    """|B| = |a(u, s)^H x| of each snapshot at its own direction, shape (N,)."""
    k = 2 * np.pi / array.wavelength_m
    return np.abs(np.sum(x * np.exp(-1j * k * (np.outer(u, array.y_m)
                                               + np.outer(s, array.z_m))), axis=1))


def brute_force(array, amplitudes, fe_az_deg, fe_el_deg, u, s):
    """|B| at the set directions and the strongest far direction over the field of view.

    Far means beyond half a resolution cell (wavelength / element extent per axis) of the set
    direction. Returns ``(at_set, far_max, far_u, far_s)``, each of shape (N,).
    """
    k = 2 * np.pi / array.wavelength_m
    y, z = array.y_m, array.z_m
    x = snapshots(array, amplitudes, fe_az_deg, fe_el_deg)
    cell_u, cell_s = array.wavelength_m / np.ptp(y), array.wavelength_m / np.ptp(z)
    gu = np.linspace(-U_MAX, U_MAX, int(2 * U_MAX / cell_u * REFERENCE_PER_CELL) + 1)
    gs = np.linspace(-S_MAX, S_MAX, int(2 * S_MAX / cell_s * REFERENCE_PER_CELL) + 1)
    look_u = np.exp(-1j * k * np.outer(gu, y))
    look_s = np.exp(-1j * k * np.outer(z, gs))
    at_set = beam(array, x, u, s)
    out = []
    for xn, un, sn in zip(x, u, s, strict=True):
        power = np.abs((look_u * xn) @ look_s)
        near = ((gu[:, None] - un) / cell_u) ** 2 + ((gs[None, :] - sn) / cell_s) ** 2 <= 0.25
        power[near] = 0.0
        i, j = np.unravel_index(np.argmax(power), power.shape)
        out.append((power[i, j], gu[i], gs[j]))
    far_max, far_u, far_s = np.array(out).T
    return at_set, far_max, far_u, far_s


@st.composite
def layouts(draw):
    """>= 12 TX and 16 RX on a lambda/2 grid over 3..5 cm, some TX raised."""
    rx_span = draw(st.integers(16, 20))
    rx = draw(st.lists(st.integers(0, rx_span - 1), min_size=16, max_size=16, unique=True))
    n_tx = draw(st.integers(12, 14))
    tx_y = draw(st.lists(st.integers(0, 6), min_size=n_tx, max_size=n_tx))
    raised = draw(st.lists(st.sampled_from([1, 2, 3, 4, 6]), min_size=1, max_size=4))
    return cascade_like(tx_y, raised + [0] * (n_tx - len(raised)), rx)


@st.composite
def quads(draw):
    """One quad of FEs 3..8 deg apart, its corners jittered by up to 0.5 deg."""
    az0, el0 = draw(st.floats(-20, 20)), draw(st.floats(-10, 10))
    d_az, d_el = draw(st.floats(3, 8)), draw(st.floats(3, 8))
    jitter = draw(st.lists(st.floats(-0.5, 0.5), min_size=8, max_size=8))
    az = az0 + np.array([-0.5, 0.5, -0.5, 0.5]) * d_az + jitter[:4]
    el = el0 + np.array([-0.5, -0.5, 0.5, 0.5]) * d_el + jitter[4:]
    return rs.Rig.from_angles(az, el)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(array=layouts(), rig=quads(),
       corners=st.lists(st.tuples(st.floats(0.05, 0.95), st.floats(0.05, 0.95)),
                        min_size=6, max_size=6))
def test_feasible_targets_are_the_global_peak_over_the_field_of_view(array, rig, corners):
    a, b = np.array(corners).T
    p0, p1, p2, p3 = (np.array([rig.az_deg[i], rig.el_deg[i]]) for i in range(4))
    # Bilinear points inside the quad (corners in paper order: 0, 1 bottom; 2, 3 top).
    pts = (((1 - a) * (1 - b))[:, None] * p0 + (a * (1 - b))[:, None] * p1
           + ((1 - a) * b)[:, None] * p2 + (a * b)[:, None] * p3)
    az, el = pts[:, 0], pts[:, 1]
    sol = rs.solve_weights(az, el, rig=rig, array=array, method="exact")
    assert np.all(sol.weights[~sol.feasible] == 0.0)
    assert all(sol.explain(i) for i in np.flatnonzero(~sol.feasible))
    ok = np.flatnonzero(sol.feasible)
    event(f"feasible targets: {ok.size > 0}")
    if ok.size == 0:
        return
    u, s = cosines(az[ok], el[ok])
    fes = rig.quads[sol.quad[ok]]
    amplitudes = np.zeros((ok.size, rig.az_deg.size))
    np.put_along_axis(amplitudes, fes, sol.weights[ok], axis=1)
    at_set, far_max, _, _ = brute_force(array, amplitudes, rig.az_deg, rig.el_deg, u, s)
    assert np.all(far_max <= at_set * (1 + SAMPLING_TOL)), (far_max / at_set, az[ok], el[ok])


# A quad where the compact cascade's grating lobe, two thirds of the field of view below the
# target, lies far outside the quad's neighbourhood that the old check probed.
REGRESSION_AZ_DEG = [-2.0, 2.0, -2.0, 2.0]
REGRESSION_EL_DEG = [4.0, 4.0, 9.0, 9.0]
REGRESSION_TARGET_DEG = (0.5, 7.0)


def test_grating_lobe_far_from_the_quad_is_flagged_split(monkeypatch):
    array = compact_cascade()
    rig = rs.Rig.from_angles(REGRESSION_AZ_DEG, REGRESSION_EL_DEG)
    fes = rig.quads[0]
    az, el = (np.array([v]) for v in REGRESSION_TARGET_DEG)
    weights, reason = ExactQuad.build(rig, array, fes).solve(np.radians(az), np.radians(el))
    assert reason[0] == rs.Reason.OK  # a local maximum on the set angle ...
    u, s = cosines(az, el)
    _, _, far_u, far_s = brute_force(array, weights, rig.az_deg[fes], rig.el_deg[fes], u, s)
    # ... and just as strong two thirds of the field of view below it (the strongest far
    # direction of the scan): the radar may see the target there.
    np.testing.assert_allclose([far_u[0], far_s[0]], [u[0], s[0] - 2 / 3], atol=0.02)
    x = snapshots(array, weights, rig.az_deg[fes], rig.el_deg[fes])
    np.testing.assert_allclose(beam(array, x, u, s - 2 / 3), beam(array, x, u, s), rtol=1e-9)
    # The old check probed the quad's FEs extended by one resolution cell, which is what the
    # field of view shrunk to nothing leaves: it passed the target.
    monkeypatch.setattr(globalmax, "FIELD_OF_VIEW", (0.0, 0.0))
    neighbourhood = GlobalMaxCheck.build(rig, array, fes)
    assert neighbourhood.probe_s.min() > far_s[0] + neighbourhood.cell_s
    assert not neighbourhood.splits(np.radians(az), np.radians(el), weights)[0]
    monkeypatch.undo()
    assert GlobalMaxCheck.build(rig, array, fes).splits(np.radians(az), np.radians(el),
                                                        weights)[0]
    sol = rs.solve_weights(az, el, rig=rig, array=array, method="exact")
    assert sol.reason[0] == rs.Reason.SPLIT


@pytest.mark.parametrize("case", ["paper", "awr1843boost", "cascade"])
def test_pruned_probes_decide_as_all_probes(case, kit_rig):
    """Skipping probes whose bound cannot reach the limit changes no verdict (the cascade on
    a wide quad: ghosts that only a weaker peak gives)."""
    rng = np.random.default_rng(7)
    if case == "cascade":
        array = ti_cascade()
        rig = rs.Rig.from_angles([-21.0, -10.5, -21.0, -10.5], [-9.0, -9.0, 0.0, 0.0])
        az, el = np.radians(rng.uniform(-21, -10.5, 300)), np.radians(rng.uniform(-9, 0, 300))
    else:
        array, rig = rs.VirtualArray.preset(case), kit_rig
        az, el = np.radians(rng.uniform(-3, 3, 300)), np.radians(rng.uniform(-6, 6, 300))
    fes = rig.quads[0]
    check = GlobalMaxCheck.build(rig, array, fes)
    assert np.all(np.diff(check.bound) <= 0.0)
    weights = rng.uniform(0.0, 1.0, (300, 4)) ** 3  # lopsided weights split often
    u, s = cosines(np.degrees(az), np.degrees(el))
    f = check.probe_re + 1j * check.probe_im
    b = check.response.evaluate(u, s, terms=1)[0]
    at_set = np.abs(np.einsum("qn,nq->n", b, weights))
    far = (((check.probe_u - u[:, None]) / check.cell_u) ** 2
           + ((check.probe_s - s[:, None]) / check.cell_s) ** 2) > globalmax.EXCLUSION_CELLS**2
    level = np.abs(weights @ f) ** 2
    strongest = np.where(far, level, 0.0).max(axis=1)
    brighter = strongest >= (at_set * (1 - globalmax.SAMPLING_LOSS)) ** 2
    # Ghosts, over every probe: far local maxima of the probe grid of at least GHOST_POWER of
    # the set direction's power where the array's own pattern stays below it. The grid is
    # rebuilt from the probes' own directions, not from the check's bookkeeping.
    gu, gs = np.unique(check.probe_u), np.unique(check.probe_s)
    n_u, n_s = gu.size, gs.size
    grid = np.full((300, n_u + 2, n_s + 2), -np.inf)
    iu, js = np.searchsorted(gu, check.probe_u), np.searchsorted(gs, check.probe_s)
    grid[:, iu + 1, js + 1] = level
    around = np.max([grid[:, 1 + a : 1 + a + n_u, 1 + b : 1 + b + n_s][:, iu, js]
                     for a in (-1, 0, 1) for b in (-1, 0, 1) if a or b], axis=0)
    rows, cols = np.nonzero(far & (level >= around) & (
        level >= globalmax.GHOST_POWER * (at_set[:, None] * (1 - globalmax.SAMPLING_LOSS)) ** 2))
    du, ds = check.probe_u[cols] - u[rows], check.probe_s[cols] - s[rows]
    own = np.abs(np.exp(1j * array.wavenumber_rad_per_m * (
        du[:, None] * array.y_m + ds[:, None] * array.z_m)).mean(axis=1)) ** 2
    ghost = np.zeros(300, dtype=bool)
    ghost[rows[own < globalmax.GHOST_POWER]] = True
    expected = brighter | ghost
    assert 0 < expected.sum() < expected.size
    if case == "cascade":
        assert np.any(ghost & ~brighter)  # the pruning is tested for ghosts alone too
    np.testing.assert_array_equal(check.splits(az, el, weights), expected)


def test_probes_cover_the_field_of_view(kit_rig):
    array = rs.VirtualArray.preset("awr1843boost")
    check = GlobalMaxCheck.build(kit_rig, array, kit_rig.quads[0])
    u_max, s_max = globalmax.FIELD_OF_VIEW
    assert check.probe_u.min() <= -u_max and check.probe_u.max() >= u_max
    assert check.probe_s.min() <= -s_max and check.probe_s.max() >= s_max


def spectrum_peaks(array, x, u, s):
    """Local maxima of ``|B|^2`` over the field of view beyond half a resolution cell.

    The brute-force reference of the ghost test: the snapshot ``x`` (shape (M,)) scanned on a
    grid of `REFERENCE_PER_CELL` points per cell, a point a peak where it is at least each of
    its eight neighbours. Returns ``(power, du, ds)`` of each far peak, offsets from ``(u, s)``.
    """
    k = 2 * np.pi / array.wavelength_m
    y, z = array.y_m, array.z_m
    cell_u, cell_s = array.wavelength_m / np.ptp(y), array.wavelength_m / np.ptp(z)
    gu = np.linspace(-U_MAX, U_MAX, int(2 * U_MAX / cell_u * REFERENCE_PER_CELL) + 1)
    gs = np.linspace(-S_MAX, S_MAX, int(2 * S_MAX / cell_s * REFERENCE_PER_CELL) + 1)
    look_u, look_s = np.exp(-1j * k * np.outer(gu, y)), np.exp(-1j * k * np.outer(z, gs))
    power = np.abs((look_u * x) @ look_s) ** 2
    padded = np.pad(power, 1, constant_values=-np.inf)
    around = np.max([padded[1 + a : 1 + a + gu.size, 1 + b : 1 + b + gs.size]
                     for a in (-1, 0, 1) for b in (-1, 0, 1) if a or b], axis=0)
    i, j = np.nonzero(power >= around)
    du, ds = gu[i] - u, gs[j] - s
    far = (du / cell_u) ** 2 + (ds / cell_s) ** 2 > 0.25
    return power[i, j][far], du[far], ds[far]


def own_pattern(array, du, ds):
    """Power of the array factor ``du, ds`` off a plane wave's direction, 1 on it."""
    k = 2 * np.pi / array.wavelength_m
    return np.abs(np.exp(1j * k * (np.outer(du, array.y_m) + np.outer(ds, array.z_m)))
                  .mean(axis=1)) ** 2


# The radar's estimator reports a secondary peak of at least half the strongest one's power
# (`Bartlett2D`'s default peak_ratio): a target whose echoes show one it does not show for a
# real target comes out as two detections. The ghost test's references read both levels with
# the probe grid's sampling loss either way.
PEAK_RATIO = 0.5
GHOST_TOL = 2 * SAMPLING_TOL + 0.02


def test_a_ghost_the_radar_would_report_splits_the_target():
    """Targets on the edge of a wide quad on the cascade: two FEs 9 deg apart in elevation, less
    than the cascade's elevation cell, synthesize the peak and a weaker ghost beside it."""
    array = ti_cascade()
    rig = rs.Rig.from_angles([-21.0, -10.5, -21.0, -10.5], [-9.0, -9.0, 0.0, 0.0])
    fes = rig.quads[0]
    el = np.r_[np.linspace(-8.5, -0.5, 17), np.linspace(-8.0, -1.0, 8)]
    az = np.r_[np.full(17, -21.0), np.full(8, -15.75)]
    weights, reason = ExactQuad.build(rig, array, fes).solve(np.radians(az), np.radians(el))
    ok = np.flatnonzero(reason == rs.Reason.OK)
    split = GlobalMaxCheck.build(rig, array, fes).splits(np.radians(az[ok]), np.radians(el[ok]),
                                                         weights[ok])
    u, s = cosines(az[ok], el[ok])
    x = snapshots(array, weights[ok], rig.az_deg[fes], rig.el_deg[fes])
    at_set = beam(array, x, u, s) ** 2
    kinds = []
    for n in range(ok.size):
        power, du, ds = spectrum_peaks(array, x[n], u[n], s[n])
        ratio = power / at_set[n]
        own = own_pattern(array, du, ds)
        brighter = np.any(ratio >= 1 - GHOST_TOL)
        ghost_at = (ratio >= PEAK_RATIO * (1 - GHOST_TOL)) & (own < PEAK_RATIO * (1 + GHOST_TOL))
        clear = np.all((ratio < PEAK_RATIO * (1 + GHOST_TOL))
                       | (own >= PEAK_RATIO * (1 - GHOST_TOL)))
        if split[n]:
            assert brighter or ghost_at.any(), (az[ok][n], el[ok][n], ratio.max())
            kinds.append("brighter" if brighter else "ghost")
        else:
            assert clear and not brighter, (az[ok][n], el[ok][n], ratio[~(own >= PEAK_RATIO)])
            kinds.append("clear")
    # The set covers all three cases, the ghost alone among them.
    assert set(kinds) == {"clear", "ghost", "brighter"}, kinds


def test_a_run_names_the_ghost_a_limit_not_the_radar_s_false_detections(tmp_path):
    """The cascade straight ahead on wide-3x5: the solver's weights on the middle quads put
    a ghost 0.5 dB weaker beside the target, which the radar reported as a false detection
    every cycle; the run now says the target is not playable there: split (the quad it lies
    in cannot place it; its neighbour can, only with the ghost)."""
    path = write_scene(tmp_path, [{
        "name": "car", "kind": "car", "rcs": {"rcs_dbsm": 10.0},
        "motion": {"type": "constant_velocity", "position_m": [33.7, 0.0, 0.5827],
                   "speed_mps": 20.0}}],
        duration_s=1.0, frame_rate_hz=10.0,
        radar={"profile": "cascade-12x16", "mount": {"x_m": 3.7, "z_m": 0.5}},
        ego={"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                        "speed_mps": 20.0}})
    report = rs.run_scene(rs.load_scenario(path), rs.RunOptions()).report
    (car,) = report.targets
    assert report.false_detections == 0
    assert set(car.limits) == {"split"} and not report.passed
