"""The exact method's compiled kernel against its numpy reference, and the peak it puts.

The kernel (rts_scenario/solver/_exact_kernel.py) follows the numpy code step for step, so the
weights agree to rounding (~1e-15; the bound 1e-12 leaves room for the secant iteration, which
amplifies rounding by its conditioning) and every reason is the same. Targets are spread over
each rig and a margin around it, so infeasible, split and retried targets are compared too.
"""

import os
import subprocess
import sys

import numpy as np
import pytest
from cascade_arrays import compact_cascade, ti_cascade

import rts_scenario as rs
from rts_scenario.arrays import direction_cosines
from rts_scenario.radar import RadarProfile
from rts_scenario.schedule.build import solver_inputs
from rts_scenario.solver import compiled, solver_plan

numba = pytest.importorskip(
    "numba", reason="numba (the 'fast' extra) is not installed: the compiled kernel is not used"
)

# Weights are normalized to a largest weight of 1: an absolute bound is a relative one.
WEIGHT_TOL = 1e-12


def kernel_or_skip():
    kernel = compiled.exact_kernel()
    if kernel is None:
        pytest.skip("the compiled kernel is unavailable here (RTS_SCENARIO_JIT off, or no "
                    "writable numba cache)")
    return kernel


def modeled():
    return solver_inputs(RadarProfile.preset("awr1843boost"), "modeled")


# A quad 4 deg x 6 deg wide (the benchmark's): narrow enough for the cascades' sharp beams.
NARROW = rs.Rig.from_angles([-2.0, 2.0, -2.0, 2.0], [-3.0, -3.0, 3.0, 3.0], name="narrow")

def _grid_3x3():
    """A centro-symmetric 3 x 3 grid: its centre element is its own mirror."""
    lam = rs.VirtualArray.preset("paper").wavelength_m
    y, z = np.meshgrid(np.arange(-1, 2) * lam / 2, np.arange(-1, 2) * lam / 2)
    return rs.VirtualArray(y_m=y.ravel(), z_m=z.ravel(), wavelength_m=lam, name="grid-3x3")


def _grid_5x4():
    """A centro-symmetric 5 x 4 grid: an odd number of y computed (0, d, 2d), none at z = 0."""
    lam = rs.VirtualArray.preset("paper").wavelength_m
    y, z = np.meshgrid(np.arange(-2, 3) * lam / 2, (np.arange(4) - 1.5) * lam / 2)
    return rs.VirtualArray(y_m=y.ravel(), z_m=z.ravel(), wavelength_m=lam, name="grid-5x4")


def _doubled_grid():
    """The paper's array with every element twice."""
    paper = rs.VirtualArray.preset("paper")
    return rs.VirtualArray.from_positions(np.r_[paper.y_m, paper.y_m], np.r_[paper.z_m, paper.z_m],
                                          wavelength_m=paper.wavelength_m, name="paper x2")


def _scattered_pairs():
    """Centro-symmetric but no grid: five elements and their mirrors, in shuffled order."""
    lam = rs.VirtualArray.preset("paper").wavelength_m
    rng = np.random.default_rng(7)
    y, z = rng.uniform(-1.2, 1.2, 5) * lam, rng.uniform(-0.8, 0.8, 5) * lam
    y, z = np.concatenate([y, -y]), np.concatenate([z, -z])
    order = rng.permutation(y.size)
    return rs.VirtualArray(y_m=y[order], z_m=z[order], wavelength_m=lam, name="pairs")


def _paper_with(extra):
    """The paper's array with copies of the elements ``extra`` (indices) added."""
    paper = rs.VirtualArray.preset("paper")
    y, z = paper.y_m, paper.z_m
    return rs.VirtualArray.from_positions(np.r_[y, y[extra]], np.r_[z, z[extra]],
                                          wavelength_m=paper.wavelength_m, name="paper+copies")


def _mirror_of(array, i):
    return int(np.argmin(np.abs(array.y_m + array.y_m[i]) + np.abs(array.z_m + array.z_m[i])))


def _duplicated_pair():
    """Centro-symmetric with two elements at one place and two at its mirror."""
    return _paper_with([0, _mirror_of(rs.VirtualArray.preset("paper"), 0)])


def _doubled_centre():
    """The 3 x 3 grid with a second element on the centre."""
    grid = _grid_3x3()
    return rs.VirtualArray.from_positions(np.r_[grid.y_m, 0.0], np.r_[grid.z_m, 0.0],
                                          wavelength_m=grid.wavelength_m, name="grid+centre")


def _nearly_centrosymmetric():
    """The paper's array with every position off by up to 1e-10 wavelength (centro-symmetric
    within `VirtualArray.is_centrosymmetric`'s tolerance, 1e-9 wavelength)."""
    paper = rs.VirtualArray.preset("paper")
    rng = np.random.default_rng(4)
    off = rng.uniform(-1e-10, 1e-10, (2, paper.n_elements)) * paper.wavelength_m
    return rs.VirtualArray.from_positions(paper.y_m + off[0], paper.z_m + off[1],
                                          wavelength_m=paper.wavelength_m, name="paper-near")


def _uneven_mirror_counts():
    """Every element has a mirror, but three places hold two elements and their mirrors one:
    not centro-symmetric (the response is complex)."""
    lam = rs.VirtualArray.preset("paper").wavelength_m
    ang = np.radians([0.0, 120.0, 240.0])
    y, z = 0.6 * lam * np.cos(ang), 0.6 * lam * np.sin(ang)
    return rs.VirtualArray.from_positions(np.r_[y, y, -y], np.r_[z, z, -z], wavelength_m=lam,
                                          name="uneven")


def _two_rows(row0, row1, dz=0.5, name="two rows"):
    """Two rows of elements (y in half wavelengths), the second ``dz`` half wavelengths up."""
    lam = rs.VirtualArray.preset("awr1843boost").wavelength_m
    y = np.r_[row0, row1] * lam / 2
    z = np.r_[np.zeros(len(row0)), np.full(len(row1), dz)] * lam / 2
    return rs.VirtualArray.from_positions(y, z, wavelength_m=lam, name=name)


def _rows_with_centres():
    """Odd rows (an element at each centre, two at one), centres apart in y and z."""
    return _two_rows([-2, -1, 0, 1, 2], [0.5, 1.5, 1.5, 2.5], dz=0.7, name="odd rows")


def _rows_uneven_offsets():
    """Rows whose offsets from their centres are no progression (0.5, 1.5, 4)."""
    return _two_rows([-4, -1.5, -0.5, 0.5, 1.5, 4], [-0.5, 0.5], name="uneven rows")


def _doubled_awr():
    """The AWR1843BOOST's array with every element twice."""
    awr = rs.VirtualArray.preset("awr1843boost")
    return rs.VirtualArray.from_positions(np.r_[awr.y_m, awr.y_m], np.r_[awr.z_m, awr.z_m],
                                          wavelength_m=awr.wavelength_m, name="awr x2")


def _asymmetric_row():
    """Two rows, the second not symmetric in y: summed element by element."""
    return _two_rows([0, 1, 2, 3], [0, 1, 3], name="asymmetric row")


CASES = {
    "paper": lambda: (rs.Rig.preset("kit-table1"), rs.VirtualArray.preset("paper"), None),
    "awr1843boost": lambda: (rs.Rig.preset("kit-table1"), rs.VirtualArray.preset("awr1843boost"),
                             None),
    "ti-cascade": lambda: (NARROW, ti_cascade(), None),
    "compact-cascade": lambda: (NARROW, compact_cascade(), None),
    "modeled": lambda: (rs.Rig.preset("kit-table1"), *modeled()),
    "wide-3x5 awr1843boost": lambda: (rs.Rig.preset("wide-3x5"),
                                      rs.VirtualArray.preset("awr1843boost"), None),
    "wide-3x5 paper": lambda: (rs.Rig.preset("wide-3x5"), rs.VirtualArray.preset("paper"), None),
    # Centro-symmetric layouts other than the paper's (the kernel folds mirror pairs).
    "grid-3x3": lambda: (rs.Rig.preset("kit-table1"), _grid_3x3(), None),
    "grid-5x4": lambda: (rs.Rig.preset("kit-table1"), _grid_5x4(), None),
    "doubled grid": lambda: (rs.Rig.preset("kit-table1"), _doubled_grid(), None),
    "scattered pairs": lambda: (NARROW, _scattered_pairs(), None),
    # Several elements at one place, and positions within the tolerance of a mirror's.
    "duplicated pair": lambda: (rs.Rig.preset("kit-table1"), _duplicated_pair(), None),
    "doubled centre": lambda: (rs.Rig.preset("kit-table1"), _doubled_centre(), None),
    "nearly centro-symmetric": lambda: (rs.Rig.preset("kit-table1"),
                                        _nearly_centrosymmetric(), None),
    "uneven mirror counts": lambda: (rs.Rig.preset("kit-table1"), _uneven_mirror_counts(), None),
    # Complex responses summed row by row (`exact.RowFactors`), and layouts that are not.
    "odd rows": lambda: (rs.Rig.preset("kit-table1"), _rows_with_centres(), None),
    "uneven rows": lambda: (NARROW, _rows_uneven_offsets(), None),
    "doubled awr1843boost": lambda: (rs.Rig.preset("kit-table1"), _doubled_awr(), None),
    "asymmetric row": lambda: (rs.Rig.preset("kit-table1"), _asymmetric_row(), None),
}
# Layouts whose complex responses of plane-wave FEs the kernel sums row by row.
ROW_LAYOUTS = {"awr1843boost", "wide-3x5 awr1843boost", "odd rows", "uneven rows",
               "doubled awr1843boost"}


def targets(rig, n, seed, margin_deg=2.0):
    rng = np.random.default_rng(seed)
    az = rng.uniform(rig.az_deg.min() - margin_deg, rig.az_deg.max() + margin_deg, n)
    el = rng.uniform(rig.el_deg.min() - margin_deg, rig.el_deg.max() + margin_deg, n)
    return az, el


@pytest.mark.parametrize("case", list(CASES))
def test_kernel_matches_numpy_path(case, monkeypatch):
    kernel_or_skip()
    rig, array, model = CASES[case]()
    az, el = targets(rig, 3000, seed=len(case), margin_deg=0.5)
    kwargs = {"rig": rig, "array": array, "model": model}
    fast = rs.solve_weights(az, el, **kwargs)
    monkeypatch.setenv(compiled.JIT_ENV, "off")
    reference = rs.solve_weights(az, el, **kwargs)
    np.testing.assert_array_equal(fast.reason, reference.reason)
    np.testing.assert_array_equal(fast.quad, reference.quad)
    np.testing.assert_allclose(fast.weights, reference.weights, rtol=0, atol=WEIGHT_TOL)
    assert fast.feasible.sum() >= 30  # the comparison covers solved targets, not only misses


# Centro-symmetric layouts whose real responses the kernel sums as products over y and over z.
GRIDS = {"paper", "wide-3x5 paper", "grid-3x3", "grid-5x4", "doubled grid"}


@pytest.mark.parametrize("case", list(CASES))
def test_the_grid_sums_are_taken_on_full_grids_only(case):
    """Full grids (every place held by as many elements) take the grid's factored sums; other
    layouts, and a grid off by more than rounding from its mirror, keep the folded sums."""
    rig, array, model = CASES[case]()
    tables = solver_plan(rig, array, "exact", model).exact_tables
    assert (tables.sep_z_re.shape[2] > 0) == (case in GRIDS)


@pytest.mark.parametrize("case", list(CASES))
def test_the_row_sums_are_taken_on_symmetric_rows_of_plane_waves_only(case):
    """Two rows, each symmetric in y, with plane-wave FEs: summed by rows. Modeled responses
    (the "modeled" case), other row counts and a row not symmetric keep the element sums."""
    rig, array, model = CASES[case]()
    rows = solver_plan(rig, array, "exact", model).exact_tables.rows
    assert (rows.z.size > 0) == (case in ROW_LAYOUTS)


@pytest.mark.parametrize("case", ["awr1843boost", "odd rows", "uneven rows",
                                  "doubled awr1843boost"])
def test_row_sums_are_the_responses_summed_element_by_element(case):
    """`_row_sums` against ``f_q = sum_v exp(j k (y_v (u_q - u) + z_v (s_q - s)))`` and its
    derivatives in u and s (times ``-j k y_v`` and ``-j k z_v``), rotated by ``exp(-j phi)``,
    summed element by element here from the array's positions and the FEs' directions."""
    from rts_scenario.solver import exact

    kernel = kernel_or_skip()
    # The tables are shaped by exact's constants, the kernel's loops unrolled by its own.
    assert (exact.ROWS, exact.OFFSETS) == (kernel.ROWS, kernel.OFFSETS)
    rig, array, model = CASES[case]()
    tables = solver_plan(rig, array, "exact", model).exact_tables
    rows, k = tables.rows, array.wavenumber_rad_per_m
    u_q, s_q = direction_cosines(np.radians(rig.az_deg[rig.quads[0]]),
                                 np.radians(rig.el_deg[rig.quads[0]]))
    rng = np.random.default_rng(3)
    block = kernel._BLOCK
    u, s = rng.uniform(-0.3, 0.3, block), rng.uniform(-0.3, 0.3, block)
    phi = rng.uniform(-np.pi, np.pi, block)
    acc_re, acc_im = np.full((24, block), np.nan), np.full((24, block), np.nan)
    trig = np.empty((2 * kernel.OFFSETS + 2 * kernel.ROWS, block))
    kernel._row_sums(acc_re, acc_im, u, s, phi, k, rows.z, rows.y, rows.centre, rows.offsets,
                     rows.offset_step, rows.pair[0], rows.p_re[0], rows.p_im[0], trig, block)
    phase = k * (array.y_m[None, :, None] * (u_q[:, None, None] - u[None, None, :])
                 + array.z_m[None, :, None] * (s_q[:, None, None] - s[None, None, :]))
    terms = np.exp(1j * (phase - phi[None, None, :]))  # (fe, element, target)
    expected = np.concatenate([
        terms.sum(axis=1),
        (-1j * k * array.y_m[None, :, None] * terms).sum(axis=1),
        (-1j * k * array.z_m[None, :, None] * terms).sum(axis=1),
    ])
    got = acc_re[:12] + 1j * acc_im[:12]
    scale = array.n_elements * np.r_[1.0, k * np.abs(array.y_m).max(),
                                     k * np.abs(array.z_m).max()].repeat(4)[:, None]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13 * scale.max())
    assert np.all(np.abs(got - expected) <= 1e-13 * scale)


@pytest.mark.parametrize("case", ["awr1843boost", "wide-3x5 awr1843boost"])
def test_kernel_matches_numpy_path_with_many_iterating_targets(case, monkeypatch):
    """Targets whose phase iterates are solved in batches of up to a block per quad and span.
    40,000 targets cross span boundaries (16,384 targets each), and their iterating targets
    (about 15 % on the AWR1843BOOST's quad) fill batches to the brim on one quad."""
    kernel_or_skip()
    rig, array, model = CASES[case]()
    az, el = targets(rig, 40_000, seed=5, margin_deg=0.0)
    fast = rs.solve_weights(az, el, rig=rig, array=array)
    monkeypatch.setenv(compiled.JIT_ENV, "off")
    reference = rs.solve_weights(az, el, rig=rig, array=array)
    np.testing.assert_array_equal(fast.reason, reference.reason)
    np.testing.assert_array_equal(fast.quad, reference.quad)  # located span by span
    np.testing.assert_allclose(fast.weights, reference.weights, rtol=0, atol=WEIGHT_TOL)
    assert fast.feasible.mean() > 0.5


@pytest.mark.parametrize("elements", [12, 13])
@pytest.mark.parametrize("iterations", [1, 2, 60])
@pytest.mark.parametrize("imaginary", [1e-2, 0.3, 1.0])
def test_batched_iteration_is_the_target_by_target_iteration(elements, iterations, imaginary):
    """`_iterate_batch` against `_solve_one` on the same random responses, bit for bit: every
    way out of the iteration (converged, no solution, out of iterations) and every reason."""
    kernel = kernel_or_skip()
    from rts_scenario.solver.exact import _CODES, _TOLERANCES

    rng = np.random.default_rng(elements * 100 + iterations)
    block, m = kernel._BLOCK, elements
    table = rng.normal(size=(24, m)) + 1j * imaginary * rng.normal(size=(24, m))
    look = np.exp(1j * rng.uniform(-np.pi, np.pi, size=(m, block)))
    t_re, t_im = np.ascontiguousarray(table.real), np.ascontiguousarray(table.imag)
    l_re, l_im = np.ascontiguousarray(look.real), np.ascontiguousarray(look.imag)
    tol = _TOLERANCES.copy()
    tol[kernel._ITERATIONS] = iterations
    # What `_solve_one` reads: every row complex. What the kernel's block pass has: f complex,
    # the derivatives' real parts, and the weights and phase residual at phase 0 from them.
    acc_re, acc_im = np.zeros((24, block)), np.zeros((24, block))
    kernel._complex_sums(acc_re, acc_im, t_re, t_im, l_re, l_im, 0, 12, m, block)
    part_re, part_im = np.zeros((24, block)), np.zeros((24, block))
    kernel._complex_sums(part_re, part_im, t_re, t_im, l_re, l_im, 0, 4, m, block)
    kernel._real_sums(part_re, t_re, t_im, l_re, l_im, 4, 12, m, block)
    np.testing.assert_array_equal(part_re[:12], acc_re[:12])
    work = np.empty((7, block))
    kernel._max_gain_weights_block(part_re, block, 1.0, tol, work)
    iterating = []
    for b in range(block):
        w = tuple(work[:4, b])
        work[5, b] = kernel._atan_small(kernel._dot(tuple(part_im[:4, b]), w),
                                        kernel._dot(tuple(part_re[:4, b]), w))
        if work[4, b] != 0.0 and not abs(work[5, b]) <= tol[kernel._PHASE]:
            iterating.append(b)
    n = len(iterating)
    assert n > 20

    def outputs():
        return np.full((block, 4), -1.0), np.full(block, 255, np.uint8), np.full(block, 5.0)

    w_one, r_one, m_one = outputs()
    for b in iterating:
        kernel._solve_one(b, acc_re, acc_im, b, tuple(work[:4, b]), True, work[5, b], False,
                          False, 1.0, tol, _CODES, w_one, r_one, m_one)
    w_all, r_all, m_all = outputs()
    index = np.array(iterating, dtype=np.int64)
    pend_n = np.zeros(block, dtype=np.int64)
    pend_n[:n] = index
    pend_re, pend_im = np.zeros((m, block)), np.zeros((m, block))
    pend_re[:, :n], pend_im[:, :n] = l_re[:, index], l_im[:, index]
    state = np.zeros((6, block))
    state[:, :n] = work[:6, index]
    kernel._iterate_batch(pend_n, pend_re, pend_im, state, n, t_re, t_im, m,
                          np.empty((5, 12, block)), 1.0, tol, _CODES, w_all, r_all, m_all,
                          False)
    np.testing.assert_array_equal(w_all, w_one)
    np.testing.assert_array_equal(r_all, r_one)
    np.testing.assert_array_equal(m_all, m_one)
    assert (r_all[index] != 255).all()  # every iterating target written, no other
    assert (np.delete(r_all, index) == 255).all()
    if iterations == 1:
        assert (r_all == _CODES[kernel._NOT_CONVERGED]).any()
    if iterations == 60:
        assert (r_all == _CODES[kernel._OK]).any()


SQUARE = rs.Rig.from_angles([-5.0, 5.0, -5.0, 5.0], [-8.0, -8.0, 8.0, 8.0])
EQUAL_AZ = rs.Rig.from_angles([2.0, 2.0, 2.0, 2.0], [-8.0, -8.0, 8.0, 8.0])
EQUAL_EL = rs.Rig.from_angles([-5.0, 5.0, -5.0, 5.0], [3.0, 3.0, 3.0, 3.0])


@pytest.mark.parametrize("array_name", ["paper", "awr1843boost"])
@pytest.mark.parametrize("rig, az, el", [
    # Corners, edge midpoints (two FEs reach them; a side edge no superposition reaches).
    (SQUARE, [-5.0, 5.0, 0.0, 0.0, -5.0, 5.0, -4.9, 4.9], [-8.0, 8.0, -8.0, 8.0, 0, 0, 0, 0]),
    # Collapsed quads: on the line they span, beside it (degenerate), far away (outside).
    (EQUAL_AZ, [2.0, 2.0, 2.0, 1.0, 3.0, 2.5, 30.0], [-4.0, 0.0, 7.0, 0.0, 0.0, -4.0, 0.0]),
    (EQUAL_EL, [-4.0, 0.0, 3.0, 0.0, 0.0, 4.0, 0.0], [3.0, 3.0, 3.0, 2.0, 4.0, 3.5, -30.0]),
], ids=["square-edges", "equal-azimuths", "equal-elevations"])
def test_kernel_matches_numpy_path_on_edges_and_degenerate_quads(array_name, rig, az, el,
                                                                 monkeypatch):
    kernel_or_skip()
    array = rs.VirtualArray.preset(array_name)
    fast = rs.solve_weights(az, el, rig=rig, array=array)
    monkeypatch.setenv(compiled.JIT_ENV, "off")
    reference = rs.solve_weights(az, el, rig=rig, array=array)
    np.testing.assert_array_equal(fast.reason, reference.reason)
    np.testing.assert_array_equal(fast.quad, reference.quad)
    np.testing.assert_allclose(fast.weights, reference.weights, rtol=0, atol=WEIGHT_TOL)


def test_kernel_differs_only_among_failures_where_the_iteration_is_chaotic(monkeypatch):
    """A quad far wider than the array's beam: almost nothing can be synthesized, and the
    phase iteration hops between weight patterns for many steps. There rounding can end it
    differently (no solution, split or not converged: all infeasible), rarely; the feasible
    targets and their weights are the same."""
    kernel_or_skip()
    rig, array = rs.Rig.preset("kit-table1"), compact_cascade()
    az, el = targets(rig, 3000, seed=11)
    fast = rs.solve_weights(az, el, rig=rig, array=array)
    monkeypatch.setenv(compiled.JIT_ENV, "off")
    reference = rs.solve_weights(az, el, rig=rig, array=array)
    np.testing.assert_array_equal(fast.feasible, reference.feasible)
    np.testing.assert_allclose(fast.weights, reference.weights, rtol=0, atol=WEIGHT_TOL)
    assert np.mean(fast.reason != reference.reason) < 2e-3


@pytest.mark.parametrize("case", ["awr1843boost", "compact-cascade", "modeled"])
def test_kernel_curvature_matches_numpy_path(case):
    """With the local-maximum test on (as the plan's survey runs it) margins agree too."""
    kernel_or_skip()
    rig, array, model = CASES[case]()
    quad = solver_plan(rig, array, "exact", model).kernels[0]
    az, el = targets(rig, 2000, seed=7, margin_deg=0.0)
    w, reason, margin = quad.solve_with_curvature(np.radians(az), np.radians(el), True)
    w_ref, reason_ref, margin_ref = quad.solve_numpy(np.radians(az), np.radians(el), True)
    np.testing.assert_array_equal(reason, reason_ref)
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=WEIGHT_TOL)
    # Where the iteration stopped without a solution the margin is of an arbitrary iterate.
    solved = np.isin(reason_ref, [rs.Reason.OK, rs.Reason.SPLIT])
    # The margin is a difference of curvatures: relative to the curvature scale, not itself.
    scale = np.abs(margin_ref[solved]).max()
    np.testing.assert_allclose(margin[solved], margin_ref[solved], rtol=0, atol=1e-10 * scale)


def bartlett(array, sources, weights, u, s):
    """``|a(u, s)^H sum_q w_q r_q|`` by a direct sum over the elements."""
    k = array.wavenumber_rad_per_m
    look = np.exp(-1j * k * (array.y_m * u + array.z_m * s))
    return np.abs(look @ (sources @ weights))


@pytest.mark.parametrize("case", ["paper", "awr1843boost", "modeled", "wide-3x5 awr1843boost",
                                  "duplicated pair", "doubled centre", "uneven mirror counts"])
def test_kernel_weights_put_the_bartlett_peak_on_the_set_angle(case):
    """Independent check: the Bartlett spectrum of the weighted FE responses peaks on target.

    The peak is located by a Newton step on a quadratic fitted to ``|B|`` around the set
    angle (step 1e-3 deg: |B| changes by ~1e-7 there, so rounding moves the fit ~1e-9 deg).
    """
    kernel_or_skip()
    rig, array, model = CASES[case]()
    az, el = targets(rig, 60, seed=3, margin_deg=-0.5)
    sol = rs.solve_weights(az, el, rig=rig, array=array, model=model)
    assert sol.feasible.mean() > 0.8
    h = 1e-3
    k = array.wavenumber_rad_per_m
    for i in np.flatnonzero(sol.feasible):
        fes = rig.quads[sol.quad[i]]
        if model is None:
            u_q, s_q = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
            sources = np.exp(1j * k * (np.outer(array.y_m, u_q) + np.outer(array.z_m, s_q)))
        else:
            sources = model.vectors(rig, fes, array)

        def level(d_az, d_el, i=i, sources=sources):
            u, s = direction_cosines(np.radians(az[i] + d_az), np.radians(el[i] + d_el))
            return bartlett(array, sources, sol.weights[i], u, s)

        b0 = level(0, 0)
        g = np.array([level(h, 0) - level(-h, 0), level(0, h) - level(0, -h)]) / (2 * h)
        h_aa = (level(h, 0) - 2 * b0 + level(-h, 0)) / h**2
        h_ee = (level(0, h) - 2 * b0 + level(0, -h)) / h**2
        h_ae = (level(h, h) - level(h, -h) - level(-h, h) + level(-h, -h)) / (4 * h**2)
        hessian = np.array([[h_aa, h_ae], [h_ae, h_ee]])
        assert np.all(np.linalg.eigvalsh(hessian) < 0), "not a maximum"
        offset = -np.linalg.solve(hessian, g)
        assert np.abs(offset).max() < 1e-6, (case, i, offset)


def test_turned_off_by_environment(monkeypatch):
    monkeypatch.setenv(compiled.JIT_ENV, "off")
    assert compiled.exact_kernel() is None


def test_no_writable_cache_falls_back_to_numpy():
    """Where numba finds no place for its cache, the numpy code runs: no error, same weights."""
    if not hasattr(numba.config, "CACHE_LOCATOR_CLASSES"):
        pytest.skip("this numba cannot be told to find no cache locator")
    code = (
        "import numpy as np, rts_scenario as rs\n"
        "from rts_scenario.solver import compiled\n"
        "assert compiled.exact_kernel() is None\n"
        "sol = rs.solve_weights([1.0, 30.0], [2.0, 0.0], rig=rs.Rig.preset('kit-table1'),\n"
        "                       array=rs.VirtualArray.preset('awr1843boost'))\n"
        "assert sol.feasible.tolist() == [True, False]\n"
    )
    # Only the zip-file locator: none applies to a source file, as when nothing is writable.
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "ZipCacheLocator"}
    env.pop("NUMBA_CACHE_DIR", None)
    subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=120)


def test_auto_mode_loads_the_kernel_after_enough_targets():
    code = (
        "import sys, numpy as np, rts_scenario as rs\n"
        "from rts_scenario.solver import compiled\n"
        "rig, array = rs.Rig.preset('kit-table1'), rs.VirtualArray.preset('awr1843boost')\n"
        "compiled.LOAD_AFTER_TARGETS = 1500\n"
        "az = np.linspace(-2, 2, 1000)\n"
        "first = rs.solve_weights(az, az, rig=rig, array=array)\n"
        "assert 'numba' not in sys.modules\n"
        "second = rs.solve_weights(az, az, rig=rig, array=array)\n"
        "assert compiled._loaded and compiled._loaded[0] is not None\n"
        "assert np.abs(first.weights - second.weights).max() < 1e-12\n"
    )
    env = {**os.environ, compiled.JIT_ENV: "auto"}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=120)


def test_import_does_not_load_numba():
    code = ("import sys, rts_scenario, rts_scenario.solver\n"
            "assert 'numba' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def _bent_grid():
    """A 3 x 4 grid whose FEs sit off their columns and rows (bent edges, uneven means)."""
    rng = np.random.default_rng(7)
    az = np.array([-15.0, -5.0, 5.0, 15.0]) + rng.uniform(-1.5, 1.5, (3, 4))
    el = np.array([[-8.0], [0.0], [8.0]]) + rng.uniform(-1.0, 1.0, (3, 4))
    return rs.Rig.grid(az, el)


def _on_every_edge_and_mean(geometry, rng):
    """Directions on the quads' corners and edges, on the grid's means and beside them."""
    polygons = geometry.polygons
    if len(polygons) > 200:  # a sample of a huge grid's quads
        polygons = polygons[rng.choice(len(polygons), 200, replace=False)]
    corners = polygons.reshape(-1, 2)
    start = polygons
    end = np.roll(polygons, -1, axis=1)
    t = rng.uniform(0, 1, (*start.shape[:2], 40, 1))
    along = (start[:, :, None] + t * (end - start)[:, :, None]).reshape(-1, 2)
    points = np.concatenate([corners, along])
    az = np.concatenate([points[:, 0], np.repeat(geometry.column_az_deg, 50),
                         rng.uniform(-30, 30, 50 * geometry.row_el_deg.size)])
    el = np.concatenate([points[:, 1], rng.uniform(-12, 12, 50 * geometry.column_az_deg.size),
                         np.repeat(geometry.row_el_deg, 50)])
    tiny = np.array([0.0, 1e-12, -1e-12, 1e-9, -1e-9, 2e-9, -2e-9, 1e-7, -1e-7])
    az = (az[:, None] + tiny[None, :]).ravel()
    el = (el[:, None] + tiny[::-1][None, :]).ravel()
    return az, el


def _huge_grid():
    """200 x 200 FEs: 39,601 quads, more than a 16-bit cell could number."""
    az, el = np.meshgrid(np.linspace(-60, 60, 200), np.linspace(-30, 30, 200))
    return rs.Rig.grid(az, el)


@pytest.mark.parametrize("rig", [rs.Rig.preset("wide-3x5"), _bent_grid(), _huge_grid()],
                         ids=["wide-3x5", "bent 3x4", "200x200"])
def test_the_raster_locates_as_the_candidate_and_its_test(rig):
    """`_locate` on a grid reads certain cells of `quads.locate_raster` and tests the rest: its
    quads are those of `candidate_quads` and `inside_quads` (numpy) everywhere, on edges,
    corners and grid means to within rounding, outside the raster and for NaN and infinities.
    """
    from rts_scenario.quads import EDGE_TOL_DEG, QuadGeometry, candidate_quads

    kernel = kernel_or_skip()
    geometry = QuadGeometry.of(rig)
    assert geometry.raster.size  # a grid of quads has one
    rng = np.random.default_rng(3)
    edges_az, edges_el = _on_every_edge_and_mean(geometry, rng)
    spread_az = rng.uniform(rig.az_deg.min() - 3, rig.az_deg.max() + 3, 200_000)
    spread_el = rng.uniform(rig.el_deg.min() - 3, rig.el_deg.max() + 3, 200_000)
    odd = [np.nan, np.inf, -np.inf, 0.0, 1e300, -1e300]
    az = np.concatenate([edges_az, spread_az, odd, [0.0] * 3])
    el = np.concatenate([edges_el, spread_el, [0.0] * 3, [np.nan, np.inf, -np.inf], odd[3:]])
    candidate = candidate_quads(geometry.column_az_deg, geometry.row_el_deg, az, el)
    with np.errstate(invalid="ignore"):
        expected = np.where(geometry.within(az, el, candidate), candidate, -1)
    quad = np.full(az.size, 99, dtype=np.int64)
    kernel._locate(az, el, *(np.array(a, dtype=np.float64) for a in (
        geometry.column_az_deg, geometry.row_el_deg, geometry.lines, geometry.boxes)),
        EDGE_TOL_DEG, geometry.raster, geometry.raster_frame, quad)
    np.testing.assert_array_equal(quad, expected)
    # The edge cases reach both answers: inside and outside by rounding.
    assert (expected[: edges_az.size] >= 0).any() and (expected[: edges_az.size] < 0).any()
    # Most directions over the grid are answered by the raster itself.
    inner = (spread_az > rig.az_deg.min()) & (spread_az < rig.az_deg.max())
    cells = geometry.raster
    if len(geometry.polygons) < 1000:  # quads of many cells each
        assert (cells >= 0).sum() > 0.8 * (cells != -1).sum()
    else:  # quads numbered beyond 16 bits are answered by the raster too
        assert cells.max() > 32767
    assert (quad[edges_az.size:][: spread_az.size][inner] >= 0).mean() > 0.5


def test_the_raster_is_made_only_when_the_kernel_asks_for_it(monkeypatch):
    """A run of a few targets, on the numpy code, assigns quads without the raster (5-25 ms a
    rig); asked for, it is `locate_raster`'s of the rig's grid, read-only, made once."""
    import dataclasses
    import pickle

    from rts_scenario.arrays import VirtualArray
    from rts_scenario.quads import QuadGeometry, assign_quads, locate_raster
    from rts_scenario.rig import Rig
    from rts_scenario.solver import solve_weights

    monkeypatch.setenv("RTS_SCENARIO_JIT", "off")  # the numpy code, kernel loaded or not

    rig = Rig.preset("wide-3x5")
    geometry = QuadGeometry.build(rig)
    assert geometry._located is None
    geometry.assign(np.array([0.5, 9.0]), np.array([0.2, -3.0]))
    assert geometry._located is None
    # The shared geometry of a rig no other test uses, after a solve of a few targets.
    odd = Rig.grid(np.array([[-7.1, 0.3, 6.9], [-7.3, 0.1, 7.2]]),
                   np.array([[-2.8, -3.2, -3.0], [3.1, 2.9, 3.3]]))
    assign_quads(odd, np.array([0.5, -3.0]), np.array([0.2, 1.0]))
    solve_weights(np.array([0.5, -3.0]), np.array([0.2, 1.0]), rig=odd,
                  array=VirtualArray.preset("awr1843boost"), method="exact")
    assert QuadGeometry.of(odd)._located is None
    raster, frame = locate_raster(geometry.column_az_deg, geometry.row_el_deg, geometry.lines,
                                  geometry.boxes)
    np.testing.assert_array_equal(geometry.raster, raster)
    np.testing.assert_array_equal(geometry.raster_frame, frame)
    assert geometry.raster is geometry.raster and not geometry.raster.flags.writeable
    # A single quad has none. Pickled, made again (read-only); not copied by `replace`.
    assert QuadGeometry.build(Rig.preset("kit-table1")).raster.size == 0
    again = pickle.loads(pickle.dumps(geometry))
    assert again._located is None and not again.raster.flags.writeable
    np.testing.assert_array_equal(again.raster, raster)
    assert dataclasses.replace(geometry)._located is None
