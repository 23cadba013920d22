import numpy as np
import pytest
from scene_helpers import write_scene

from rts_scenario.kinematics import compute_tracks
from rts_scenario.scenario import load_scenario

LAMBDA = 299_792_458.0 / 77.5e9


def tracks_of(tmp_path, targets, **extra):
    return compute_tracks(load_scenario(write_scene(tmp_path, targets, **extra)))


def test_straight_line_pass_by_matches_analytic_formulas(tmp_path):
    # Radar at the origin, target passing on a line parallel to y at x = d, height h.
    d, y0, h, v = 20.0, -15.0, 1.3, 3.0
    tr = tracks_of(tmp_path, [{
        "name": "passer", "rcs": {"rcs_dbsm": 10},
        "motion": {"type": "constant_velocity", "position_m": [d, y0, h], "heading_deg": 90,
                   "speed_mps": v},
    }])
    t = tr.t_s
    y = y0 + v * t
    rng = np.sqrt(d * d + y * y + h * h)
    np.testing.assert_allclose(tr.range_m[:, 0], rng, rtol=1e-9)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], y * v / rng, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(tr.az_deg[:, 0], np.degrees(np.arctan2(y, d)), rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose(tr.el_deg[:, 0], np.degrees(np.arctan2(h, np.hypot(d, y))),
                               rtol=1e-9)
    np.testing.assert_allclose(tr.doppler_hz[:, 0], -2 * y * v / rng / LAMBDA, rtol=1e-9,
                               atol=1e-9)


def test_moving_ego_with_mount_offset_and_yaw(tmp_path):
    # Ego drives along x at 10 m/s; radar 3.7 m ahead, 0.5 m up, yawed 10 deg left; a target
    # stands at (60, 4, 0.5).
    tr = tracks_of(tmp_path, [{
        "name": "post", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "stationary", "position_m": [60.0, 4.0, 0.5]},
    }], ego={"motion": {"type": "constant_velocity", "position_m": [0, 0, 0], "speed_mps": 10.0}},
        radar={"profile": "awr1843boost", "mount": {"x_m": 3.7, "z_m": 0.5, "yaw_deg": 10.0}})
    t = tr.t_s
    dx = 60.0 - 3.7 - 10.0 * t
    rng = np.hypot(dx, 4.0)
    np.testing.assert_allclose(tr.range_m[:, 0], rng, rtol=1e-9)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], -10.0 * dx / rng, rtol=1e-9)
    np.testing.assert_allclose(tr.az_deg[:, 0], np.degrees(np.arctan2(4.0, dx)) - 10.0,
                               atol=1e-9)
    np.testing.assert_allclose(tr.el_deg[:, 0], 0.0, atol=1e-9)


def test_radial_velocity_is_the_derivative_of_range(tmp_path):
    # Curved ego path (spline), speed changes, lane changes, offset and yawed mount: compare
    # the analytic range rate with a central difference of the range at +-1 us.
    targets = [
        {"name": "weaver", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "waypoints", "path": "spline", "points": [
             {"position_m": [30, 2, 0.5], "speed_mps": 8},
             {"position_m": [60, -3, 0.8], "speed_mps": 12},
             {"position_m": [90, 4, 0.5], "speed_mps": 9}]},
         "lane_changes": [{"start_s": 0.5, "duration_s": 2.0, "offset_m": 1.5}]},
        {"name": "braker", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "constant_acceleration", "position_m": [40, -3.5, 0.6],
                    "heading_deg": 5, "speed_mps": 12, "acceleration_mps2": -3}},
        {"name": "follower", "frame": "ego", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "constant_velocity", "position_m": [25, 1, 0.6], "speed_mps": 1.0}},
    ]
    ego = {"motion": {"type": "waypoints", "path": "spline", "points": [
        {"position_m": [0, 0, 0], "speed_mps": 10},
        {"position_m": [25, 3, 0], "speed_mps": 14},
        {"position_m": [50, 0, 0], "speed_mps": 11}]},
        "lane_changes": [{"start_s": 1.0, "duration_s": 1.5, "offset_m": -2.0}]}
    radar = {"profile": "awr1843boost",
             "mount": {"x_m": 3.7, "y_m": 0.4, "z_m": 0.5, "yaw_deg": 8.0, "pitch_deg": 2.0}}
    scene = load_scenario(write_scene(tmp_path, targets, ego=ego, radar=radar, duration_s=4.0,
                                      frame_rate_hz=50.0))
    # Off the frame grid, so no sample sits exactly on a lane change's start or end, where the
    # jerk jumps and a central difference (not the analytic rate) is off by delta * jump.
    t = scene.t_s[1:] + 0.00317
    delta = 1e-6
    after = compute_tracks(scene, t + delta).range_m
    before = compute_tracks(scene, t - delta).range_m
    analytic = compute_tracks(scene, t).radial_velocity_mps
    np.testing.assert_allclose((after - before) / (2 * delta), analytic, atol=1e-6)


def test_lane_change_shifts_by_offset_smoothly(tmp_path):
    tr = tracks_of(tmp_path, [{
        "name": "lc", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "constant_velocity", "position_m": [20, 0, 0], "speed_mps": 0.0},
        "lane_changes": [{"start_s": 2.0, "duration_s": 4.0, "offset_m": 3.5}],
    }], duration_s=8.0)
    y = tr.position_m[:, 0, 1]
    t = tr.t_s
    tau = np.clip((t - 2.0) / 4.0, 0, 1)
    np.testing.assert_allclose(y, 3.5 * (10 * tau**3 - 15 * tau**4 + 6 * tau**5), atol=1e-12)


def test_constant_acceleration_stops_and_stays(tmp_path):
    tr = tracks_of(tmp_path, [{
        "name": "braking", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "constant_acceleration", "position_m": [10, 0, 0],
                   "speed_mps": 10, "acceleration_mps2": -4},
    }], duration_s=6.0)
    x = tr.position_m[:, 0, 0]
    t = tr.t_s
    expect = np.where(t < 2.5, 10 + 10 * t - 2 * t * t, 10 + 12.5)
    np.testing.assert_allclose(x, expect, atol=1e-12)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], np.maximum(10 - 4 * t, 0),
                               atol=1e-12)


def test_speed_profile_integrates_piecewise(tmp_path):
    tr = tracks_of(tmp_path, [{
        "name": "prof", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "speed_profile", "position_m": [5, 0, 0], "profile": [
            {"t_s": 1.0, "speed_mps": 2.0}, {"t_s": 3.0, "speed_mps": 6.0},
            {"t_s": 4.0, "speed_mps": 6.0}]},
    }], duration_s=6.0)
    t = tr.t_s
    # 2 m/s until 1 s, then +2 m/s^2 until 3 s, then 6 m/s.
    x = np.where(t < 1, 5 + 2 * t,
                 np.where(t < 3, 7 + 2 * (t - 1) + (t - 1) ** 2, 7 + 4 + 4 + 6 * (t - 3)))
    np.testing.assert_allclose(tr.position_m[:, 0, 0], x, atol=1e-12)


def test_waypoints_arrive_on_time_and_spline_passes_through_them(tmp_path):
    points = [[10, 0, 0], [20, 0, 0], [20, 10, 0]]
    for path in ("polyline", "spline"):
        tr = tracks_of(tmp_path, [{
            "name": "wp", "rcs": {"rcs_dbsm": 0},
            "motion": {"type": "waypoints", "path": path, "start_s": 1.0,
                       "points": [{"position_m": p, "speed_mps": 2.0} for p in points]},
        }], duration_s=20.0, frame_rate_hz=100.0)
        pos = tr.position_m[:, 0]
        assert np.allclose(pos[:100], [10, 0, 0])  # waits until start_s
        # Constant 2 m/s: at arc length 10 m (second waypoint for the polyline) after 5 s.
        if path == "polyline":
            np.testing.assert_allclose(pos[600], [20, 0, 0], atol=1e-9)
            np.testing.assert_allclose(pos[1100], [20, 10, 0], atol=1e-9)
        else:
            dist = np.linalg.norm(pos - np.array([20, 10, 0]), axis=1)
            assert dist.min() < 0.02
            dist = np.linalg.norm(pos - np.array([20, 0, 0]), axis=1)
            assert dist.min() < 0.02
        speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) * 100.0
        np.testing.assert_allclose(speed[150:1000], 2.0, rtol=2e-3)


def test_target_in_ego_frame_keeps_its_distance(tmp_path):
    tr = tracks_of(tmp_path, [{
        "name": "convoy", "frame": "ego", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "stationary", "position_m": [30, 0, 0.5]},
    }], ego={"motion": {"type": "waypoints", "path": "spline", "points": [
        {"position_m": [0, 0, 0], "speed_mps": 15}, {"position_m": [80, 10, 0], "speed_mps": 20},
        {"position_m": [160, 0, 0], "speed_mps": 15}]}})
    np.testing.assert_allclose(tr.range_m[:, 0], np.hypot(30, 0.5), rtol=1e-9)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], 0.0, atol=1e-9)


def test_rcs_table_and_fluctuation(tmp_path):
    targets = [
        {"name": "front", "rcs": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]},
         "motion": {"type": "stationary", "position_m": [20, 0, 0], "heading_deg": 180}},
        {"name": "quarter", "rcs": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]},
         "motion": {"type": "stationary", "position_m": [20, 0, 0], "heading_deg": 135}},
        {"name": "s1", "rcs": {"rcs_dbsm": 0, "fluctuation": "swerling1"},
         "motion": {"type": "stationary", "position_m": [20, 0, 0]}},
        {"name": "s3", "rcs": {"rcs_dbsm": 0, "fluctuation": "swerling3"},
         "motion": {"type": "stationary", "position_m": [20, 0, 0]}},
    ]
    tr = tracks_of(tmp_path, targets, duration_s=500.0, seed=5)
    # Facing the radar: aspect 0 -> 10 dBsm; yawed 45 deg away: halfway between 10 and 20.
    np.testing.assert_allclose(tr.rcs_dbsm[:, 0], 10.0, atol=1e-12)
    np.testing.assert_allclose(tr.rcs_dbsm[:, 1], 15.0, atol=1e-12)
    s1 = 10 ** (tr.rcs_dbsm[:, 2] / 10)
    s3 = 10 ** (tr.rcs_dbsm[:, 3] / 10)
    n = len(s1)  # 10 000 draws: standard errors ~1 %
    assert abs(s1.mean() - 1) < 4 / np.sqrt(n) and abs(s1.var() - 1) < 0.1
    assert abs(s3.mean() - 1) < 4 * np.sqrt(0.5 / n) and abs(s3.var() - 0.5) < 0.05
    again = tracks_of(tmp_path, targets, duration_s=500.0, seed=5)
    np.testing.assert_array_equal(again.rcs_dbsm, tr.rcs_dbsm)
    other = tracks_of(tmp_path, targets, duration_s=500.0, seed=6)
    assert not np.array_equal(other.rcs_dbsm[:, 2], tr.rcs_dbsm[:, 2])


def test_masks(tmp_path):
    targets = [
        {"name": "late", "appear_s": 2.0, "disappear_s": 5.0, "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "stationary", "position_m": [20, 0, 0]}},
        {"name": "crossing", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "constant_velocity", "position_m": [20, -12, 0],
                    "heading_deg": 90, "speed_mps": 3.0}},
        {"name": "far", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "stationary", "position_m": [80, 0, 0]}},
        {"name": "fast", "rcs": {"rcs_dbsm": 0},
         "motion": {"type": "constant_velocity", "position_m": [10, 0, 0], "speed_mps": 12}},
    ]
    tr = tracks_of(tmp_path, targets)
    t = tr.t_s
    np.testing.assert_array_equal(tr.present[:, 0], (t >= 2.0) & (t < 5.0))
    az = tr.az_deg[:, 1]
    inside = np.abs(az) < 20.9
    outside = np.abs(az) > 21.1
    assert np.all(tr.in_coverage[inside, 1]) and not np.any(tr.in_coverage[outside, 1])
    assert not tr.in_range[:, 2].any() and tr.in_range[:, 0].all()
    assert not tr.in_velocity[:, 3].any() and tr.in_velocity[:, 0].all()
    assert not tr.checkable[:, 2].any()


@pytest.mark.parametrize("n_frames_expected, duration, rate", [(200, 10.0, 20.0), (1, 0.05, 20.0),
                                                          (1, 2.0, 0.5)])
def test_frame_count(tmp_path, n_frames_expected, duration, rate):
    tr = tracks_of(tmp_path, [{"name": "a", "rcs": {"rcs_dbsm": 0},
                               "motion": {"type": "stationary", "position_m": [20, 0, 0]}}],
                   duration_s=duration, frame_rate_hz=rate)
    assert tr.t_s.shape == (n_frames_expected,)


def test_a_target_given_in_the_ego_frame_faces_where_it_drives(tmp_path):
    # The ego drives at 20 m/s along x. Three cars ahead of it, given in its frame: one falling
    # back at 1 m/s (19 m/s forward), one keeping its distance, one closing at 1 m/s. All three
    # drive forward, so the radar behind them sees their backs: 30 dBsm in a table of 10 at
    # the front and 30 at the back. A body yaws with its velocity in the world, not with its
    # motion relative to the ego.
    table = {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]}
    targets = [{"name": name, "frame": "ego", "rcs": table,
                "motion": {"type": "constant_velocity", "position_m": [30, y, 0.5],
                           "heading_deg": heading, "speed_mps": speed}}
               for name, y, heading, speed in (("falling-back", -3.0, 180, 1.0),
                                                ("keeping", 0.0, 0, 0.0),
                                                ("closing", 3.0, 0, 1.0))]
    tr = tracks_of(tmp_path, targets, duration_s=2.0,
                   ego={"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                                   "speed_mps": 20.0}})
    # Aspect from behind, off the car's axis by the line of sight's angle: atan2(y, x) of the
    # radar (at the ego's origin) seen from the car, interpolated in the table.
    x = 30.0 + np.array([-1.0, 0.0, 1.0])[None, :] * tr.t_s[:, None]
    y = np.array([-3.0, 0.0, 3.0])
    off = np.degrees(np.arctan2(np.abs(y), x))  # degrees away from straight behind
    np.testing.assert_allclose(tr.rcs_dbsm, 30.0 - 10.0 * off / 90.0, atol=1e-9)


# -- driving backwards -------------------------------------------------------------------------

RCS_BY_ASPECT = {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]}


@pytest.mark.parametrize("motion, x_of_t, v_of_t", [
    ({"type": "constant_velocity", "speed_mps": -2.0},
     lambda t: 20.0 - 2.0 * t, lambda t: -2.0 + 0 * t),
    # Reversing and braking at 1 m/s^2: stops after 2 s and stays.
    ({"type": "constant_acceleration", "speed_mps": -2.0, "acceleration_mps2": 1.0},
     lambda t: np.where(t < 2, 20.0 - 2.0 * t + 0.5 * t * t, 18.0),
     lambda t: np.minimum(-2.0 + t, 0.0)),
    # Reversing harder and harder.
    ({"type": "constant_acceleration", "speed_mps": -1.0, "acceleration_mps2": -0.5},
     lambda t: 20.0 - t - 0.25 * t * t, lambda t: -1.0 - 0.5 * t),
    # Backs off at 2 m/s for 1 s, then drives forwards: speed -2 -> 2 m/s over 1..3 s.
    ({"type": "speed_profile", "profile": [{"t_s": 1.0, "speed_mps": -2.0},
                                           {"t_s": 3.0, "speed_mps": 2.0}]},
     lambda t: np.where(t < 1, 20.0 - 2 * t, np.where(
         t < 3, 18.0 - 2 * (t - 1) + (t - 1) ** 2, 18.0 + 2 * (t - 3))),
     lambda t: np.where(t < 1, -2.0, np.where(t < 3, -2.0 + 2 * (t - 1), 2.0))),
])
def test_a_car_driving_backwards_faces_its_heading(tmp_path, motion, x_of_t, v_of_t):
    # A car 20 m ahead, facing away from the radar (heading 0: the radar sees its back, 30
    # dBsm), backs towards it: positions and range rates by hand, and the radar keeps seeing
    # its back (a car does not turn round to reverse), also while it stands.
    tr = tracks_of(tmp_path, [{
        "name": "reversing", "rcs": RCS_BY_ASPECT,
        "motion": {**motion, "position_m": [20.0, 0.0, 0.0], "heading_deg": 0.0},
    }], duration_s=5.0)
    t = tr.t_s
    np.testing.assert_allclose(tr.position_m[:, 0, 0], x_of_t(t), atol=1e-12)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], v_of_t(t), atol=1e-12)
    np.testing.assert_allclose(tr.rcs_dbsm[:, 0], 30.0, atol=1e-12)


def test_an_ego_driving_backwards_keeps_its_radar_facing_its_heading(tmp_path):
    # The ego reverses along x at 3 m/s; its radar, mounted at the back (x -1 m, yawed 180
    # deg), looks behind it, where a post stands at (-20, 2, 0): by hand, the post comes
    # nearer at 3 m/s (less its angle's share), and stays at the same side of the radar.
    tr = tracks_of(tmp_path, [{
        "name": "post", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "stationary", "position_m": [-20.0, 2.0, 0.0]},
    }], ego={"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                        "speed_mps": -3.0}},
        radar={"profile": "awr1843boost", "mount": {"x_m": -1.0, "yaw_deg": 180.0}},
        duration_s=4.0)
    t = tr.t_s
    dx = -20.0 - (-1.0 - 3.0 * t)  # post less radar, along x (negative: behind)
    rng = np.hypot(dx, 2.0)
    np.testing.assert_allclose(tr.range_m[:, 0], rng, rtol=1e-12)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], 3.0 * dx / rng, rtol=1e-9)
    # Behind and 2 m to the ego's left: the rear radar (turned round) sees it to its right.
    np.testing.assert_allclose(tr.az_deg[:, 0], -np.degrees(np.arctan2(2.0, -dx)), atol=1e-9)


def test_spline_straight_reversal_is_the_straight_segment_and_keeps_facing(tmp_path):
    # A car drives 20 m away from the radar along its boresight, stops at 40 m and backs 15 m
    # towards it: the path doubles back on the same line. Speeds 4 -> 0 -> 3 m/s at the
    # waypoints: -0.4 m/s^2 for 10 s (20 m), then +0.3 m/s^2 backwards for 10 s (15 m).
    # The body faces away from the radar throughout (aspect 180 deg: 30 dBsm in the table).
    tr = tracks_of(tmp_path, [{
        "name": "reverser", "rcs": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]},
        "motion": {"type": "waypoints", "path": "spline", "points": [
            {"position_m": [20, 0, 0.5], "speed_mps": 4},
            {"position_m": [40, 0, 0.5], "speed_mps": 0},
            {"position_m": [25, 0, 0.5], "speed_mps": 3}]},
    }], duration_s=25.0, frame_rate_hz=20.0)
    t = tr.t_s
    x = np.where(t <= 10, 20 + 4 * t - 0.2 * t * t,
                 np.where(t <= 20, 40 - 0.15 * (t - 10) ** 2, 25 - 3 * (t - 20)))
    vx = np.where(t <= 10, 4 - 0.4 * t, np.where(t <= 20, -0.3 * (t - 10), -3.0))
    pos = tr.position_m[:, 0]
    np.testing.assert_allclose(pos[:, 0], x, atol=1e-9)
    np.testing.assert_allclose(pos[:, 1:], np.broadcast_to([0.0, 0.5], (t.size, 2)), atol=1e-9)
    assert pos[:, 0].max() <= 40.0 + 1e-9  # never past the waypoint where it reverses
    rng = np.hypot(x, 0.5)
    np.testing.assert_allclose(tr.radial_velocity_mps[:, 0], x * vx / rng, atol=1e-9)
    np.testing.assert_allclose(tr.rcs_dbsm[:, 0], 30.0, atol=1e-9)


def test_spline_reversal_stops_at_the_waypoint_with_a_cusp(tmp_path):
    # Parking: forward along +x into the space, stop at B, back out to the rear left. The
    # turn at B is 161.6 deg (> 90 deg): B is a cusp. The path must reach B exactly, never run
    # past it, and the body keeps facing the way it drove in while it backs out (its yaw, and
    # with it the RCS aspect, continuous through B).
    a, b, c = np.array([20.0, 0, 0.5]), np.array([30.0, 0, 0.5]), np.array([24.0, 2, 0.5])
    scene = load_scenario(write_scene(tmp_path, [{
        "name": "parker", "rcs": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 20, 30, 20]},
        "motion": {"type": "waypoints", "path": "spline", "points": [
            {"position_m": a.tolist(), "speed_mps": 3},
            {"position_m": b.tolist(), "speed_mps": 0},
            {"position_m": c.tolist(), "speed_mps": 2}]},
    }], duration_s=12.0, frame_rate_hz=20.0))
    t_b = float(scene.targets[0].trajectory.law.knots_s[1])  # arrival at the second waypoint
    at_b = compute_tracks(scene, np.array([t_b]))
    np.testing.assert_allclose(at_b.position_m[0, 0], b, atol=1e-9)
    np.testing.assert_allclose(at_b.radial_velocity_mps[0, 0], 0.0, atol=1e-9)
    # No point of the path beyond B along the incoming chord, nor along the cusp's line.
    u_in, u_out = (b - a) / np.linalg.norm(b - a), (c - b) / np.linalg.norm(c - b)
    line = (u_in - u_out) / np.linalg.norm(u_in - u_out)
    t = np.linspace(0.0, 12.0, 24001)
    pos = compute_tracks(scene, t).position_m[:, 0]
    assert ((pos - b) @ u_in).max() <= 1e-9
    assert ((pos - b) @ line).max() <= 1e-9
    # Either side of B the body lies along the cusp's line, facing in (aspect: the radar at
    # the origin seen from the body; B is 30 m ahead on the boresight).
    eps = np.array([t_b - 1e-4, t_b, t_b + 1e-4])
    near = compute_tracks(scene, eps)
    facing = np.arctan2(line[1], line[0])
    expect = np.degrees(np.pi - facing)  # direction to the radar (180 deg) minus the yaw
    table = np.interp(np.mod(expect, 360.0), [0, 90, 180, 270, 360], [10, 20, 30, 20, 10])
    np.testing.assert_allclose(near.rcs_dbsm[:, 0], table, atol=1e-3)
    # Backing out, the body keeps facing +x roughly: its aspect stays near 180 deg (the table
    # near 30 dBsm), where a body that turned round would show its front (10 dBsm).
    later = compute_tracks(scene, np.linspace(t_b, 12.0, 50))
    assert later.rcs_dbsm[:, 0].min() > 25.0


def test_spline_without_reversal_is_the_natural_cubic_spline(tmp_path):
    # Turns of 90 deg at most: one natural cubic spline through all points (chord-length
    # parameter), as scipy computes it; its tangents at the waypoints are the path's.
    from scipy.interpolate import CubicSpline

    from rts_scenario.scenario.trajectory import Path

    points = np.array([[30, 2, 0.5], [60, -3, 0.8], [90, 4, 0.5], [90, 30, 0.5], [70, 40, 0]],
                      dtype=float)
    knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    reference = CubicSpline(knots, points, bc_type="natural")
    d1 = reference(knots, 1)
    path, at_points = Path.spline(points)
    idx = np.searchsorted(path.arc_m, at_points)
    np.testing.assert_allclose(path.points[idx], points, atol=1e-12)
    tangents = np.concatenate([path.tangent_start[idx[:-1]], path.tangent_end[-1:]])
    np.testing.assert_allclose(tangents, d1 / np.linalg.norm(d1, axis=1)[:, None], atol=1e-12)
    np.testing.assert_array_equal(path.facing, 1.0)


def test_ego_backing_out_on_a_spline_keeps_its_radar_facing_forward(tmp_path):
    # The ego drives 10 m forward, stops and backs 10 m out on the same line: its radar faces
    # +x throughout, so a post straight ahead stays at azimuth 0 and its range follows the ego.
    tr = tracks_of(tmp_path, [{
        "name": "post", "rcs": {"rcs_dbsm": 0},
        "motion": {"type": "stationary", "position_m": [40.0, 0.0, 0.5]}}],
        ego={"motion": {"type": "waypoints", "path": "spline", "points": [
            {"position_m": [0, 0, 0], "speed_mps": 2}, {"position_m": [10, 0, 0], "speed_mps": 0},
            {"position_m": [0, 0, 0], "speed_mps": 2}]}},
        radar={"profile": "awr1843boost", "mount": {"x_m": 3.7, "z_m": 0.5}},
        duration_s=20.0)
    t = tr.t_s
    # -0.2 m/s^2 for 10 s to 10 m, then backwards at +0.2 m/s^2 for 10 s.
    x = np.where(t <= 10, 2 * t - 0.1 * t * t, 10 - 0.1 * (t - 10) ** 2)
    np.testing.assert_allclose(tr.az_deg[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(tr.range_m[:, 0], 40.0 - 3.7 - x, atol=1e-9)


def test_a_target_at_the_radar_s_reference_point_is_within_its_unambiguous_range(tmp_path):
    # Range 0 (the target on the mount point) and 0.1 um from it: the radar's range FFT shows
    # both in its first cell, well inside [0, max_range_m); only a target at max_range_m or
    # beyond folds.
    tr = tracks_of(tmp_path, [
        {"name": name, "rcs": {"rcs_dbsm": 10},
         "motion": {"type": "stationary", "position_m": [3.7 + dx, 0, 0.5]}}
        for name, dx in (("on", 0.0), ("near", 1e-7))
    ], radar={"profile": "awr1843boost", "mount": {"x_m": 3.7, "z_m": 0.5}}, duration_s=1.0)
    np.testing.assert_allclose(tr.range_m[0], [0.0, 1e-7], atol=1e-12)
    assert tr.in_range.all()
