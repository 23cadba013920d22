"""The aware phase search chooses exactly what the straightforward search chooses.

Reference: `reference_phase_settings` below, the search written out directly (every
combination's beamformer output and its derivatives formed in full, one Newton step each).
The product's search may compute the same predictions differently, but its choices, and the
schedule that follows from them, must be the reference's.
"""

import dataclasses

import numpy as np
import pytest
from test_schedule import RADAR, rig_with, tracks

from rts_scenario.arrays import angles_from_cosines
from rts_scenario.beamformer import newton_step
from rts_scenario.radar import RadarProfile
from rts_scenario.rig import Rig
from rts_scenario.schedule import build as schedule_build
from rts_scenario.schedule import build_schedule, quantization

OTHERS = np.array([[c for c in range(4) if c != q] for q in range(4)])


def reference_costs(resp, weights, phase, limits, u, s):
    """Every combination's predicted angle error (deg; inf: no peak), shape (N, 27)."""
    nearest = limits.phase_setting(phase)
    n = np.arange(len(phase))
    others = OTHERS[np.argmax(weights, axis=1)]
    share = resp * (weights * np.exp(1j * (nearest - phase))).T[None]
    turns = np.exp(1j * np.radians(limits.phase_step_deg) * np.arange(-1.0, 2.0))
    beam = share.sum(axis=1)[:, :, None, None, None]
    for i in range(3):
        moved = share[:, others[:, i], n][:, :, None] * (turns - 1.0)
        beam = beam + moved.reshape(*moved.shape[:2], *np.roll([3, 1, 1], i))
    beam = beam.reshape(6, len(phase), -1)
    du, ds, has_peak = newton_step(*beam)
    az0, el0 = angles_from_cosines(u, s)
    az1, el1 = angles_from_cosines(u[:, None] + du, s[:, None] + ds)
    err = np.degrees(np.hypot(az1 - az0[:, None], el1 - el0[:, None]))
    return np.where(has_peak, err, np.inf)


def reference_phase_settings(resp, weights, phase, limits, mode, u, s):
    """The aware phase search, every combination's beam formed in full."""
    nearest = limits.phase_setting(phase)
    step = limits.phase_step_deg
    if step <= 0.0 or mode != "aware" or len(phase) == 0:
        return nearest
    n = np.arange(len(phase))
    others = OTHERS[np.argmax(weights, axis=1)]
    cost = reference_costs(resp, weights, phase, limits, u, s)
    centre = cost.shape[1] // 2
    best = np.argmin(cost, axis=1)
    best = np.where(cost[n, best] < cost[:, centre] - quantization.ANGLE_TIE_DEG, best, centre)
    steps = np.stack(np.unravel_index(best, (3, 3, 3)), axis=1) - 1.0
    chosen = nearest.copy()
    np.put_along_axis(chosen, others, limits.phase_setting(
        np.take_along_axis(nearest, others, axis=1) + np.radians(step) * steps), axis=1)
    return chosen


def assert_same_choice(args, chosen, jit):
    """``chosen`` is the reference's choice (numpy: exactly; compiled: up to rounding).

    Returns the number of entries where it is not (where compiled, the predictions tie).

    The compiled search forms the same predictions in another order of operations: where two
    combinations' predicted errors agree to rounding (a channel of weight 1e-17 turned, say)
    it may take the other; both then predict the same error to 1e-12 deg.
    """
    expected = reference_phase_settings(*args)
    if jit == "off":
        np.testing.assert_array_equal(chosen, expected)
        return 0
    differ = np.flatnonzero((chosen != expected).any(axis=1))
    resp, weights, phase, limits, _, u, s = args
    cost = reference_costs(resp, weights, phase, limits, u, s)
    nearest = limits.phase_setting(phase)
    step = np.radians(limits.phase_step_deg)
    others = OTHERS[np.argmax(weights, axis=1)]
    for i in differ:
        def index(setting, i=i):
            turn = np.angle(np.exp(1j * (setting[others[i]] - nearest[i, others[i]])))
            k = np.round(turn / step).astype(int) + 1
            return k[0] * 9 + k[1] * 3 + k[2]
        assert abs(cost[i, index(chosen[i])] - cost[i, index(expected[i])]) <= 1e-12
    return differ.size


def _calibrated(name, cal_phase_deg=(10.0, -47.0, 100.3, 2.0)):
    """A shipped rig with calibration phases (cycled over its FEs): exact phases off the steps."""
    rig = Rig.preset(name)
    return dataclasses.replace(rig, cal_phase_deg=list(np.resize(cal_phase_deg, rig.n_front_ends)))


# (radar, rig, targets' azimuth and elevation half-spans, seed, range span)
KIT = _calibrated("kit-table1")
CASES = {
    "paper-6bit": (RADAR, rig_with(KIT, attenuation_step_db=0.5, phase_step_deg=5.625,
                                   echoes_per_channel=64), 2.9, 5.9, 1, (3.0, 60.0)),
    "awr-6bit-continuous-att": (RadarProfile.preset("awr1843boost"),
                                rig_with(_calibrated("kit-table1", (-33.0, 71.5, 4.0, 170.0)),
                                         phase_step_deg=5.625, echoes_per_channel=64),
                                3.5, 7.0, 2, (3.0, 60.0)),
    "awr-2bit": (RadarProfile.preset("awr1843boost"),
                 rig_with(KIT, attenuation_step_db=1.0, phase_step_deg=90.0,
                          echoes_per_channel=64), 3.5, 7.0, 3, (3.0, 60.0)),
    "awr-1bit": (RadarProfile.preset("awr1843boost"),
                 rig_with(_calibrated("kit-table1", (0.0, 95.0, -100.0, 40.0)),
                          phase_step_deg=180.0, echoes_per_channel=64), 3.5, 7.0, 4, (3.0, 60.0)),
    # Weak targets on the wide grid: channels off (weight 0) among those that may turn.
    "grid-channels-off": (RadarProfile.preset("awr1843boost"),
                          rig_with(_calibrated("wide-3x5", (12.0, -60.0, 151.0, 3.0, 80.0)),
                                   attenuation_step_db=0.5, phase_step_deg=11.25,
                                   echoes_per_channel=64, attenuation_max_db=75.0),
                          19.0, 7.5, 5, (5.0, 120.0)),
}


def _case(name, n=400):
    radar, rig, az_max, el_max, seed, (r0, r1) = CASES[name]
    rng = np.random.default_rng(seed)
    az, el = rng.uniform(-az_max, az_max, n), rng.uniform(-el_max, el_max, n)
    return radar, rig, tracks(az[None], el[None], range_m=rng.uniform(r0, r1, n)[None])


def _schedule(name):
    radar, rig, trk = _case(name)
    return build_schedule(trk, rig, radar, quantization="aware", fe_responses="plane-wave",
                          angle_tolerance_deg=(0.3, 0.6))


@pytest.fixture(params=["off", "on"], ids=["numpy", "compiled"])
def jit(request, monkeypatch):
    """The search as numpy runs it, and compiled (numba; skipped where it is missing)."""
    if request.param == "on" and quantization.compiled_phase_search() is None:
        pytest.skip("the compiled phase search needs numba (pip install numba)")
    monkeypatch.setenv("RTS_SCENARIO_JIT", request.param)
    return request.param


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_phase_search_chooses_what_the_reference_chooses(name, jit, monkeypatch):
    calls = []

    def record(*args):
        chosen = quantization.phase_settings(*args)
        calls.append((args, chosen))
        return chosen

    monkeypatch.setattr(schedule_build, "phase_settings", record)
    _schedule(name)
    assert calls
    moved = differ = entries = 0
    for args, chosen in calls:
        differ += assert_same_choice(args, chosen, jit)
        entries += len(chosen)
        moved += int((chosen != args[3].phase_setting(args[2])).any(axis=1).sum())
    assert moved > 0  # some entries take a neighbouring step: the search is exercised
    # Ties to rounding are rare; which way one goes may differ from one process to another
    # (seen: 0 or 5 of 400 on the 1-bit shifter). Every such entry's two predictions agree to
    # 1e-12 deg (above).
    assert differ <= 0.05 * entries


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_schedule_is_what_the_reference_search_gives(name, jit, monkeypatch):
    fast = _schedule(name)
    monkeypatch.setattr(schedule_build, "phase_settings", reference_phase_settings)
    slow = _schedule(name)
    # Compiled, the sums run in another order: where two combinations tie to rounding (on
    # another CPU, or in another process, too) the other may be chosen; such entries are
    # rare (at most 5 %, as above), the rest identical.
    same = np.ones(fast.status.shape, dtype=bool)
    if jit == "on":
        same = np.all((fast.phase_rad == slow.phase_rad)
                      | (np.isnan(fast.phase_rad) & np.isnan(slow.phase_rad)), axis=-1)
        assert (~same).sum() <= 0.05 * same.size
    for field in ("quad", "fe", "weight", "attenuation_db", "phase_rad", "status",
                  "angle_error_deg", "active"):
        np.testing.assert_array_equal(getattr(fast, field)[same], getattr(slow, field)[same],
                                      err_msg=field)


def test_ties_with_channels_that_change_nothing_keep_the_nearest_steps(jit):
    # A channel with weight 0 turns nothing: its three turns are exact ties, the first wins
    # in the reference; entries where nothing moves at all keep the nearest steps.
    radar, rig, _ = _case("paper-6bit", 1)
    rng = np.random.default_rng(9)
    n = 200
    u, s = rng.uniform(-0.05, 0.05, n), rng.uniform(-0.1, 0.1, n)
    resp = (rng.normal(size=(6, 4, n)) + 1j * rng.normal(size=(6, 4, n)))
    resp[0] += 3.0  # a definite peak for most entries
    weights = rng.uniform(0.1, 1.0, (n, 4))
    weights[np.arange(n // 2), rng.integers(0, 4, n // 2)] = 0.0
    weights[n // 4 : n // 2, :] = 0.0
    weights[n // 4 : n // 2, 0] = 1.0
    phase = rng.uniform(-np.pi, np.pi, (n, 4))
    args = (resp, weights, phase, rig.limits, "aware", u, s)
    assert assert_same_choice(args, quantization.phase_settings(*args), jit) <= 2
