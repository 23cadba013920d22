"""OpenSCENARIO import: imported tracks against closed-form kinematics, parameters, errors.

The truth is written here from first principles: positions and velocities of the radar (the
ego's reference point plus the mount) and of each target as closed-form functions of time, then
range, radial velocity, azimuth and elevation from their difference. The imported scene is
evaluated by the package's kinematics, so the test covers the import and the scene's meaning.
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from rts_scenario.cli import main
from rts_scenario.errors import RtsError, ScenarioError
from rts_scenario.kinematics import compute_tracks
from rts_scenario.scenario import load_scenario
from rts_scenario.xosc import import_xosc

DATA = Path(__file__).parent / "data" / "xosc"
# Front of the ego's bounding box (centre x 1.4 m + length 4.5 m / 2) at 0.5 m: the mount.
RADAR_X_M, RADAR_Z_M = 3.65, 0.5
# Closed-form positions need no tolerance beyond float rounding and the file's 1e-9 rounding.
ATOL = 1e-6


def imported(tmp_path, source, **options):
    """Import a file (a name in tests/data/xosc or a path) and load the scene it writes."""
    path = source if isinstance(source, Path) else DATA / f"{source}.xosc"
    result = import_xosc(path, radar="awr1843boost", rig="wide-3x5", **options)
    out = tmp_path / f"{path.stem}.scenario.yaml"
    out.write_text(result.text)
    return result, load_scenario(out)


def variant(tmp_path, name, old, new, filename=None):
    """A copy of a test file with one piece of text replaced; returns the path."""
    text = (DATA / f"{name}.xosc").read_text()
    assert old in text
    path = tmp_path / (filename or f"{name}.xosc")
    path.write_text(text.replace(old, new, 1))
    return path


def replace_lane_change(tmp_path, new):
    """A copy of the cut-in with its LaneChangeAction replaced by ``new``."""
    text = (DATA / "cut_in.xosc").read_text()
    path = tmp_path / "cut_in.xosc"
    path.write_text(re.sub(r"<LaneChangeAction>.*?</LaneChangeAction>", new, text,
                           flags=re.DOTALL))
    return path


def line_of(path, needle):
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def assert_tracks(scene, t, radar_p, radar_v, target_p, target_v, k=0, atol=ATOL):
    """Compare the scene's track of target k at times t with the closed-form truth."""
    line = target_p - radar_p
    range_m = np.linalg.norm(line, axis=1)
    radial = np.einsum("ti,ti->t", line, target_v - radar_v) / range_m
    az = np.degrees(np.arctan2(line[:, 1], line[:, 0]))
    el = np.degrees(np.arctan2(line[:, 2], np.hypot(line[:, 0], line[:, 1])))
    tracks = compute_tracks(scene, t)
    np.testing.assert_allclose(tracks.range_m[:, k], range_m, rtol=0, atol=atol)
    np.testing.assert_allclose(tracks.radial_velocity_mps[:, k], radial, rtol=0, atol=atol)
    np.testing.assert_allclose(tracks.az_deg[:, k], az, rtol=0, atol=atol)
    np.testing.assert_allclose(tracks.el_deg[:, k], el, rtol=0, atol=atol)


def straight(x_m, vx_mps, y_m=0.0, vy_mps=0.0, z_m=0.0):
    """Stack per-time x (and optional y) into (T, 3) positions and velocities."""
    x, vx = np.asarray(x_m, float), np.asarray(vx_mps, float)
    p = np.stack([x, np.broadcast_to(y_m, x.shape), np.full_like(x, z_m)], axis=1)
    v = np.stack([vx, np.broadcast_to(vy_mps, x.shape), np.zeros_like(x)], axis=1)
    return p, v


def ego_radar(t, speed_mps):
    """The radar on an ego driving straight along x from the origin at constant speed."""
    return straight(RADAR_X_M + speed_mps * t, np.full_like(t, speed_mps), z_m=RADAR_Z_M)


def quintic(u):
    """The scene format's lane change ramp and its derivative over u in [0, 1]."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2), 30 * u**2 * (1 - u) ** 2


# ----------------------------------------------------------------------------- the three scenes

def test_braking_lead_tracks_match_closed_form(tmp_path):
    result, scene = imported(tmp_path, "braking_lead")
    assert result.ego == "Ego" and scene.duration_s == 6.0
    assert [tg.name for tg in scene.targets] == ["Lead"] and scene.targets[0].kind == "car"
    t = np.array([0.0, 0.7, 1.95, 2.0, 2.3, 3.1, 4.4, 4.5, 5.2, 5.95])
    # Lead: 40 m ahead at 20 m/s; from 2 s it brakes at 4 m/s^2 to 10 m/s (reached at 4.5 s).
    dt = np.clip(t - 2.0, 0.0, 2.5)
    x = 40.0 + 20.0 * t - 2.0 * dt**2 - 10.0 * np.clip(t - 4.5, 0.0, None)
    v = 20.0 - 4.0 * dt
    lead_p, lead_v = straight(x, v, z_m=0.75)  # lifted to its bounding box's centre
    assert_tracks(scene, t, *ego_radar(t, 20.0), lead_p, lead_v)


@pytest.mark.parametrize("rule", ['value="0" rule="greaterThan"', 'value="0" rule="notEqualTo"'])
def test_a_strict_time_rule_false_only_at_the_act_s_start_fires_right_after_it(tmp_path, rule):
    # notEqualTo the time its evaluation starts is false only at that instant: the act (and its
    # braking) was left out as one that "never starts", with exit 0.
    path = variant(tmp_path, "braking_lead",
                   '<SimulationTimeCondition value="0" rule="greaterThan"/>',
                   f'<SimulationTimeCondition {rule}/>')
    result, scene = imported(tmp_path, path)
    assert not any("never starts" in note for note in result.notes), result.notes
    t = np.array([0.0, 1.95, 2.3, 4.4, 5.2])
    dt = np.clip(t - 2.0, 0.0, 2.5)
    x = 40.0 + 20.0 * t - 2.0 * dt**2 - 10.0 * np.clip(t - 4.5, 0.0, None)
    lead_p, lead_v = straight(x, 20.0 - 4.0 * dt, z_m=0.75)
    assert_tracks(scene, t, *ego_radar(t, 20.0), lead_p, lead_v)


def test_cut_in_tracks_match_closed_form(tmp_path):
    result, scene = imported(tmp_path, "cut_in")
    assert scene.duration_s == 10.0 and scene.targets[0].kind == "car"  # a van
    assert any("quintic" in note for note in result.notes)
    t = np.array([0.0, 1.0, 1.99, 2.0, 2.6, 3.5, 4.2, 5.0, 5.7, 6.9, 7.0, 9.5])
    # The gap (longitudinal, reference points) is 30 - 5 t: below 20 m from 2 s on. The lane
    # change into the ego's lane takes 3 s; when it ends (5 s) the cutter speeds up linearly
    # to the ego's 25 m/s in 2 s (2.5 m/s^2).
    acc = np.clip(t - 5.0, 0.0, 2.0)
    x = 30.0 + 20.0 * t + 1.25 * acc**2 + 5.0 * np.clip(t - 7.0, 0.0, None)
    vx = 20.0 + 2.5 * acc
    ramp, slope = quintic((t - 2.0) / 3.0)
    cut_p, cut_v = straight(x, vx, y_m=3.5 - 3.5 * ramp, vy_mps=-3.5 * slope / 3.0, z_m=1.0)
    assert_tracks(scene, t, *ego_radar(t, 25.0), cut_p, cut_v)


def test_pedestrian_crossing_tracks_match_closed_form(tmp_path):
    result, scene = imported(tmp_path, "pedestrian_crossing", ego="Hero")
    assert result.ego == "Hero"
    assert [(tg.name, tg.kind) for tg in scene.targets] == [("Pedestrian", "pedestrian")]
    # The pedestrian stands at (60, -4) facing +y and walks at 1.4 m/s from 1.5 s on. (A step
    # is played as a ramp at 15 m/s2 centred on its time, 1.4 / 15 s: positions after it are
    # exact.)
    t = np.array([0.0, 0.5, 1.45, 1.55, 2.0, 3.3, 4.75, 5.95])
    walked = np.clip(t - 1.5, 0.0, None)
    ped_p = np.stack([np.full_like(t, 60.0), -4.0 + 1.4 * walked, np.full_like(t, 0.9)], 1)
    ped_v = np.stack([np.zeros_like(t), np.where(t > 1.5, 1.4, 0.0), np.zeros_like(t)], 1)
    assert_tracks(scene, t, *ego_radar(t, 6.0), ped_p, ped_v)


def test_ego_defaults_to_entity_named_ego_or_hero_else_the_first_vehicle(tmp_path):
    result, _ = imported(tmp_path, "pedestrian_crossing")
    assert result.ego == "Hero"  # CARLA's name for the ego, after the pedestrian
    assert not any("radar carrier" in note for note in result.notes)
    # Named neither: the first vehicle (a radar rides a vehicle), not the first entity.
    car = variant(tmp_path, "pedestrian_crossing", 'name="Hero"', 'name="Car"', "car.xosc")
    car.write_text(car.read_text().replace('"Hero"', '"Car"'))
    result, _ = imported(tmp_path, car)
    assert result.ego == "Car"
    assert (f"{car}: the ego (radar carrier) is 'Car', the first vehicle; --ego NAME names "
            f"another") in result.notes
    renamed = variant(tmp_path, "braking_lead", 'name="Ego"', 'name="EGO"')
    text = renamed.read_text().replace('"Ego"', '"EGO"')
    renamed.write_text(text)
    result, _ = imported(tmp_path, renamed)
    assert result.ego == "EGO"


# ------------------------------------------------------------------------- other dynamics

def test_cubic_speed_transition_within_stated_tolerance(tmp_path):
    path = variant(tmp_path, "braking_lead",
                   'dynamicsShape="linear" value="$Deceleration" dynamicsDimension="rate"',
                   'dynamicsShape="cubic" value="2.5" dynamicsDimension="time"')
    result, scene = imported(tmp_path, path)
    assert any("linear pieces" in note for note in result.notes)
    t = np.linspace(0.0, 5.9, 60)
    u = np.clip((t - 2.0) / 2.5, 0.0, 1.0)
    v_true = 20.0 - 10.0 * u * u * (3 - 2 * u)
    # Integral of the cubic ramp: u^3 - u^4 / 2, times the duration. The import plays it as
    # linear pieces within 2 mm/s (its stated tolerance) and so within a millimetre.
    x_true = 40.0 + 20.0 * t - 10.0 * 2.5 * (u**3 - u**4 / 2) - 10.0 * np.clip(t - 4.5, 0, None)
    lead_p, lead_v = straight(x_true, v_true, z_m=0.75)
    assert_tracks(scene, t, *ego_radar(t, 20.0), lead_p, lead_v, atol=2.5e-3)


def test_lane_offset_uses_max_lateral_acceleration(tmp_path):
    path = replace_lane_change(
        tmp_path,
        """<LaneOffsetAction continuous="false">
                      <LaneOffsetActionDynamics maxLateralAcc="0.5" dynamicsShape="cubic"/>
                      <LaneOffsetTarget><AbsoluteTargetLaneOffset value="-1.2"/></LaneOffsetTarget>
                    </LaneOffsetAction>""")
    _, scene = imported(tmp_path, path)
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.start_s == pytest.approx(2.0, abs=1e-9)
    assert change.offset_m == pytest.approx(-1.2)
    # Quintic peak lateral acceleration 10 / sqrt(3) * offset / duration^2 = maxLateralAcc.
    assert change.duration_s == pytest.approx(math.sqrt(10 / math.sqrt(3) * 1.2 / 0.5),
                                              abs=1e-9)


def test_lateral_distance_to_the_ego(tmp_path):
    path = replace_lane_change(
        tmp_path,
        """<LateralDistanceAction entityRef="Ego" distance="0.5" freespace="false"
                        continuous="false" displacement="leftToReferencedEntity">
                      <DynamicConstraints maxAcceleration="1.0" maxSpeed="30"/>
                    </LateralDistanceAction>""")
    _, scene = imported(tmp_path, path)
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.offset_m == pytest.approx(-3.0)  # from 3.5 m left of the ego to 0.5 m
    assert change.duration_s == pytest.approx(math.sqrt(10 / math.sqrt(3) * 3.0 / 1.0))


def test_expressions(tmp_path):
    path = variant(tmp_path, "braking_lead", '<AbsoluteTargetSpeed value="$TargetSpeed"/>',
                   '<AbsoluteTargetSpeed value="${$EgoSpeed / 2 - 1}"/>')
    _, scene = imported(tmp_path, path, parameters={"EgoSpeed": "24"})
    speeds = scene.targets[0].trajectory.law.v0_mps
    assert speeds[-1] == pytest.approx(11.0)  # 24 / 2 - 1, after the braking
    bad = variant(tmp_path, "braking_lead", '<AbsoluteTargetSpeed value="$TargetSpeed"/>',
                  '<AbsoluteTargetSpeed value="${$EgoSpeed ** 2}"/>', "bad_expr.xosc")
    with pytest.raises(ScenarioError, match=r"bad_expr\.xosc:\d+: .*only numbers"):
        imported(tmp_path, bad)


def test_storyboard_features(tmp_path):
    result, scene = imported(tmp_path, "storyboard")
    assert result.ego == "ego" and scene.mount.x_m == pytest.approx(4.0)
    truck, cone = scene.targets
    assert (truck.name, truck.kind, cone.name, cone.kind) == ("truck_1", "truck", "cone", "other")
    # The ego accelerates at 2 m/s^2 to 20 m/s (10 s); the truck starts 50 m ahead along the
    # common heading and 3.5 m to its right at 10 m/s. Their 3-D distance falls below 30 m when
    # the gap along the heading is sqrt(30^2 - 3.5^2): after 10 s the gap is 150 - 10 t.
    t_close = (150.0 - math.sqrt(30.0**2 - 3.5**2)) / 10.0
    t_slow = t_close + 0.5  # the condition's delay
    # Slowing to 5 m/s over 30 m takes 2 * 30 / (10 + 5) = 4 s; then the lane change (one lane
    # left of itself plus 0.2 m, over 40 m at 5 m/s = 8 s); the scene stops when it ends.
    law = truck.trajectory.law
    assert law.knots_s[1] == pytest.approx(t_slow, abs=1e-8)
    assert law.v0_mps[-1] == pytest.approx(5.0)
    (change,) = truck.trajectory.lane_changes
    assert (change.start_s, change.duration_s, change.offset_m) == pytest.approx(
        (t_slow + 4.0, 8.0, 3.7), abs=1e-8)
    # The scene plays whole frames: the stop time rounded up to the next 20 Hz frame period,
    # the last frame held past it, and a note says so.
    stop_s = t_slow + 12.0
    assert scene.duration_s == pytest.approx(math.ceil(stop_s * 20.0) / 20.0, abs=1e-9)
    assert scene.n_frames == math.ceil(stop_s * 20.0)
    assert any(f"stops at {stop_s:.6g} s" in note and "rounded up to 491 frames" in note
               for note in result.notes), result.notes
    assert any("'never' never starts" in note for note in result.notes)
    assert any("is target 'truck_1'" in note for note in result.notes)
    assert any("<RoadNetwork> not used" in note for note in result.notes)


@pytest.mark.parametrize("condition, start_s", [
    ('storyboardElementType="action" storyboardElementRef="CutIn" state="completeState"', 5.0),
    ('storyboardElementType="act" storyboardElementRef="CutInAct" state="runningState"', 0.0),
    ('storyboardElementType="story" storyboardElementRef="CutInStory" state="startTransition"',
     0.0),
])
def test_state_conditions(tmp_path, condition, start_s):
    path = variant(tmp_path, "cut_in", 'storyboardElementType="event" '
                   'storyboardElementRef="CutInEvent" state="endTransition"', condition)
    _, scene = imported(tmp_path, path)
    law = scene.targets[0].trajectory.law

    def speed(t):
        k = np.searchsorted(law.knots_s, t, side="right") - 1
        return law.v0_mps[k] + law.a_mps2[k] * (t - law.knots_s[k])

    # The speed-up (20 to 25 m/s in 2 s, linear) starts at start_s.
    assert [speed(start_s + dt) for dt in (0.0, 1.0, 2.5)] == pytest.approx([20.0, 22.5, 25.0])
    bad = variant(tmp_path, "cut_in", 'storyboardElementRef="CutInEvent"',
                  'storyboardElementRef="CutOutEvent"', "bad_ref.xosc")
    with pytest.raises(ScenarioError, match=r"no event named 'CutOutEvent'; events: CutInEvent, "
                                            r"SpeedUpEvent"):
        imported(tmp_path, bad)


# ------------------------------------------------------------------------------- parameters

def test_parameter_override_changes_the_trigger_and_the_header(tmp_path):
    result, scene = imported(tmp_path, "cut_in", parameters={"TriggerDistance": "17.5",
                                                             "$LaneChangeTime": "4"})
    (change,) = scene.targets[0].trajectory.lane_changes
    assert (change.start_s, change.duration_s) == pytest.approx((2.5, 4.0), abs=1e-9)
    assert "# Parameters: EgoSpeed=25, CutterSpeed=20, TriggerDistance=17.5 (--param), " \
           "LaneChangeTime=4 (--param)." in result.text
    assert result.text.startswith("# Imported by rts-scenario import from cut_in.xosc")


def chained(tmp_path, declared_value):
    """The cut-in with its trigger distance taken from a parameter declared after it."""
    path = variant(tmp_path, "cut_in",
                   '<ParameterDeclaration name="LaneChangeTime" parameterType="double" '
                   'value="3"/>',
                   '<ParameterDeclaration name="LaneChangeTime" parameterType="double" '
                   'value="3"/>\n    <ParameterDeclaration name="Gap" parameterType="double" '
                   f'value="{declared_value}"/>')
    path.write_text(path.read_text().replace('value="$TriggerDistance" freespace',
                                             'value="$Gap" freespace'))
    return path


def test_a_parameter_declared_from_an_overridden_one_takes_the_override(tmp_path):
    # A value naming an earlier parameter takes the value used for it: the --param one.
    path = chained(tmp_path, "$TriggerDistance")
    result, scene = imported(tmp_path, path, parameters={"TriggerDistance": "17.5"})
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.start_s == pytest.approx((30 - 17.5) / (25 - 20), abs=1e-9)
    assert "TriggerDistance=17.5 (--param), LaneChangeTime=3, Gap=17.5." in result.text
    # An expression over earlier parameters, too.
    path = chained(tmp_path, "${$TriggerDistance - 2.5}")
    result, scene = imported(tmp_path, path, parameters={"TriggerDistance": "17.5"})
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.start_s == pytest.approx((30 - 15) / (25 - 20), abs=1e-9)


def test_a_declaration_naming_an_undeclared_parameter_is_located(tmp_path):
    path = chained(tmp_path, "$TriggerDistanse")
    line = line_of(path, "$TriggerDistanse")
    with pytest.raises(ScenarioError, match=rf"cut_in\.xosc:{line}: <ParameterDeclaration "
                                            r"name=\"Gap\">: unknown parameter "
                                            r"\$TriggerDistanse; declared before it: EgoSpeed, "
                                            r"CutterSpeed, TriggerDistance, LaneChangeTime$"):
        imported(tmp_path, path)


def test_a_declaration_naming_a_later_one_says_so(tmp_path):
    # It said "declared: none" of a parameter declared on the next line.
    path = variant(tmp_path, "cut_in", 'name="EgoSpeed" parameterType="double" value="25"',
                   'name="EgoSpeed" parameterType="double" value="$CutterSpeed"')
    line, later = line_of(path, "$CutterSpeed"), line_of(path, 'name="CutterSpeed"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (
        f"{path}:{line}: <ParameterDeclaration name=\"EgoSpeed\">: $CutterSpeed is declared "
        f"after it (line {later}); a declaration can use only the parameters declared before "
        f"it; declared before it: none")


def test_one_root_parameter_block_and_none_elsewhere(tmp_path):
    # A second root block was merged; one inside a vehicle was refused without saying where
    # parameters go.
    text = (DATA / "cut_in.xosc").read_text()
    block = re.search(r"<ParameterDeclarations>.*?</ParameterDeclarations>", text,
                      flags=re.DOTALL).group(0)
    path = tmp_path / "twice.xosc"
    path.write_text(text.replace(block, block + "\n  <ParameterDeclarations/>", 1))
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (f"{path}:{line_of(path, '<ParameterDeclarations/>')}: "
                               f"<OpenSCENARIO> has more than one <ParameterDeclarations>")
    path = tmp_path / "vehicle.xosc"
    path.write_text(re.sub(r"(<Vehicle [^>]*>)", r'\1<ParameterDeclarations><ParameterDeclaration '
                           r'name="X" parameterType="double" value="1"/></ParameterDeclarations>',
                           text, count=1))
    with pytest.raises(ScenarioError, match=r"<ParameterDeclaration> in <ParameterDeclarations> "
                                            r"is not supported by import; parameters are "
                                            r"declared in the <ParameterDeclarations> at the "
                                            r"root of the file \(<OpenSCENARIO>\), which import "
                                            r"supports \(at Entities/ScenarioObject/Vehicle/"
                                            r"ParameterDeclarations/ParameterDeclaration\)$"):
        imported(tmp_path, path)


def test_unknown_parameter_lists_the_declared_ones(tmp_path):
    with pytest.raises(RtsError, match=r"--param Speed=3: no such parameter in .*cut_in\.xosc; "
                                       r"declared: EgoSpeed, CutterSpeed, TriggerDistance, "
                                       r"LaneChangeTime"):
        imported(tmp_path, "cut_in", parameters={"Speed": "3"})
    with pytest.raises(RtsError, match="EgoSpeed is a double, got 'fast'"):
        imported(tmp_path, "cut_in", parameters={"EgoSpeed": "fast"})


def test_undeclared_reference_is_located(tmp_path):
    path = variant(tmp_path, "cut_in", 'value="$CutterSpeed"', 'value="$CutterSped"')
    line = line_of(path, "$CutterSped")
    with pytest.raises(ScenarioError, match=rf"cut_in\.xosc:{line}: .*unknown parameter "
                                            r"\$CutterSped; declared: EgoSpeed"):
        imported(tmp_path, path)


# ------------------------------------------------------------------------------- bad input

def test_unsupported_action_names_element_and_line(tmp_path):
    text = (DATA / "braking_lead.xosc").read_text()
    brake = re.search(r'<Action name="Brake">.*?</Action>', text, flags=re.DOTALL).group(0)
    path = tmp_path / "braking_lead.xosc"
    path.write_text(text.replace(brake, brake.replace("LongitudinalAction", "RoutingAction")))
    line = line_of(path, "<RoutingAction>")
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(
        f"{path}:{line}: <RoutingAction> is not supported by import; supported actions: "
        "TeleportAction (Init only), SpeedAction, LaneChangeAction, LaneOffsetAction")


@pytest.mark.parametrize("old, new, needle, message", [
    ('<Properties/>\n      </Vehicle>\n    </ScenarioObject>\n    <ScenarioObject name="Lead">',
     '<Properties/>\n      </Vehicle>\n      <ObjectController/>\n    </ScenarioObject>\n'
     '    <ScenarioObject name="Lead">', "<ObjectController/>",
     "<ObjectController> in <ScenarioObject> is not supported by import"),
    ('<SimulationTimeCondition value="2" rule="greaterThan"/>',
     '<SpeedCondition value="2" rule="greaterThan"/>', "<SpeedCondition",
     "<SpeedCondition> is not supported by import; supported conditions: "
     "SimulationTimeCondition, RelativeDistanceCondition"),
    ('<RelativeObjectPosition entityRef="Ego" dx="$LeadGap" dy="0"/>',
     '<LanePosition roadId="1" laneId="-1" s="40"/>', "<LanePosition",
     "<LanePosition> is not supported by import; supported positions: WorldPosition"),
    ('dynamicsShape="linear" value="$Deceleration"',
     'dynamicsShape="linear" value="$Deceleration" extra="1"', 'extra="1"',
     'attribute extra is not supported by import'),
    ('<Properties/>\n      </Vehicle>\n    </ScenarioObject>\n    <ScenarioObject name="Lead">',
     '<Properties/>\n        <Trailer/>\n      </Vehicle>\n    </ScenarioObject>\n'
     '    <ScenarioObject name="Lead">', "<Trailer/>",
     "<Trailer> in <Vehicle> is not supported by import"),
    ('dynamicsShape="linear" value="$Deceleration"',
     'dynamicsShape="exponential" value="$Deceleration"', 'dynamicsShape="exponential"',
     'dynamicsShape="exponential"> is not supported by import; supported: step, linear'),
])
def test_unsupported_input_is_one_located_error(tmp_path, old, new, needle, message):
    path = variant(tmp_path, "braking_lead", old, new)
    line = line_of(path, needle)
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(f"{path}:{line}: ")
    assert message in str(info.value)


def test_malformed_xml_is_located(tmp_path):
    text = (DATA / "cut_in.xosc").read_text()
    path = tmp_path / "broken.xosc"
    path.write_text(text.replace("</Actors>", "</Actor>", 1))
    line = line_of(path, "</Actor>")
    with pytest.raises(ScenarioError, match=rf"broken\.xosc:{line}: malformed XML: "):
        imported(tmp_path, path)
    path.write_text(text[: len(text) // 2])
    with pytest.raises(ScenarioError, match=r"broken\.xosc:\d+: malformed XML"):
        imported(tmp_path, path)


def test_entities_are_not_expanded(tmp_path):
    path = tmp_path / "entities.xosc"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE OpenSCENARIO [<!ENTITY x SYSTEM '
                    '"file:///etc/passwd">]>\n<OpenSCENARIO><FileHeader description="&x;"/>'
                    '</OpenSCENARIO>')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert "root:" not in str(info.value)
    # An internal entity would be expanded in an attribute value: refused, not expanded.
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE OpenSCENARIO [<!ENTITY a "25">]>\n'
                    + (DATA / "braking_lead.xosc").read_text().split("?>", 1)[1])
    with pytest.raises(ScenarioError, match=r"entities.xosc:1: the DOCTYPE declares entities "
                                            r"\(a\), which are not supported"):
        imported(tmp_path, path)


def test_missing_ego_lists_the_entities(tmp_path):
    with pytest.raises(RtsError, match=r"--ego Nobody: no such entity in .*braking_lead\.xosc; "
                                       r"entities: Ego, Lead"):
        imported(tmp_path, "braking_lead", ego="Nobody")


def test_unplaced_entity_and_missing_stop_trigger(tmp_path):
    path = variant(tmp_path, "pedestrian_crossing", '<Private entityRef="Pedestrian">',
                   '<Private entityRef="Nobody">')
    path.write_text(re.sub(r'<Private entityRef="Nobody">.*?</Private>', "",
                           path.read_text(), flags=re.DOTALL))
    with pytest.raises(ScenarioError, match=r"entity 'Pedestrian' is never placed"):
        imported(tmp_path, path)
    path = variant(tmp_path, "pedestrian_crossing", '<StopTrigger>', '<StopTriggerX>')
    path.write_text(re.sub(r"<StopTriggerX>.*</StopTrigger>", "", path.read_text(),
                           flags=re.DOTALL))
    with pytest.raises(ScenarioError, match="needs a <StopTrigger>"):
        imported(tmp_path, path)


@pytest.mark.parametrize("rule", ['value="0" rule="greaterThan"', 'value="10" rule="lessThan"'])
def test_a_stop_trigger_at_zero_is_located_at_the_stop_trigger(tmp_path, rule):
    path = variant(tmp_path, "cut_in", '<SimulationTimeCondition value="10" rule="greaterThan"/>',
                   f'<SimulationTimeCondition {rule}/>')
    line = line_of(path, "<StopTrigger>")
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (f"{path}:{line}: the <StopTrigger> fires at t = 0 s: the scene "
                               f"needs a duration > 0")


# ----------------------------------------------------------------------------- command line

def test_cli_import_then_validate_and_run(tmp_path, capsys):
    out = tmp_path / "lead.scenario.yaml"
    code = main(["import", str(DATA / "braking_lead.xosc"), "--radar", "awr1843boost",
                 "--rig", "wide-3x5", "--param", "TargetSpeed=12", "--output", str(out)])
    assert code == 0
    assert "-> " in capsys.readouterr().out
    assert "TargetSpeed=12 (--param)" in out.read_text()
    assert main(["validate", str(out)]) == 0
    assert main(["run", str(out)]) == 0
    assert "PASS: lead" in capsys.readouterr().out


def test_cli_import_warns_of_the_limits_a_run_would_fail_on(tmp_path, capsys):
    # The cutter starts beside the ego, outside the rig's field: the scene is written, and the
    # import says, as validate does, what a run of it will fail on unless it is declared.
    out = tmp_path / "cut.scenario.yaml"
    assert main(["import", str(DATA / "cut_in.xosc"), "--radar", "awr1843boost", "--rig",
                 "wide-3x5", "--output", str(out)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"warning: {out}: Cutter: out_of_coverage in "), err
    assert main(["validate", str(out)]) == 0
    assert capsys.readouterr().err.splitlines() == err


def test_cli_errors_are_one_line_exit_2(tmp_path, capsys):
    out = tmp_path / "x.scenario.yaml"
    base = [str(DATA / "cut_in.xosc"), "--radar", "awr1843boost", "--rig", "wide-3x5",
            "--output", str(out)]
    for extra in (["--param", "Nope=1"], ["--ego", "Nobody"], ["--param", "EgoSpeed"]):
        assert main(["import", *base, *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1, err
    assert main(["import", *base[:-1], str(tmp_path / "x.yaml")]) == 2
    assert "ends in .scenario.yaml" in capsys.readouterr().err
    assert main(["import", *base[:2], "nowhere", *base[3:]]) == 2
    assert "--radar 'nowhere'" in capsys.readouterr().err
    assert not out.exists()


def test_cli_import_of_a_scene_validate_refuses_is_refused(tmp_path, capsys):
    # 500 Hz frames on a 100 Hz rig: the scene does not load.
    out = tmp_path / "fast.scenario.yaml"
    argv = ["import", str(DATA / "cut_in.xosc"), "--radar", "awr1843boost", "--rig",
            "wide-3x5", "--output", str(out), "--frame-rate-hz", "500"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {DATA / 'cut_in.xosc'}: the scene it converts to does not "
                          f"load (a value beyond the scene format's or the bench's limits); "
                          f"{out} not written: {out}:")
    assert "frame_rate_hz: the scene runs at 500 Hz but rig 'wide-3x5' updates at most " \
           "100 Hz" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
    argv[-1] = "50"
    assert main(argv) == 0 and main(["validate", str(out)]) == 0


def test_cli_profile_files_are_written_relative_to_the_scene(tmp_path, capsys):
    profiles = Path(__file__).parents[1] / "scenarios" / "radars"
    (tmp_path / "radars").mkdir()
    profile = tmp_path / "radars" / "long.radar.yaml"
    profile.write_text((profiles / "awr1843boost-long.radar.yaml").read_text())
    out = tmp_path / "lead.scenario.yaml"
    assert main(["import", str(DATA / "braking_lead.xosc"), "--radar", str(profile),
                 "--rig", "wide-3x5", "--output", str(out)]) == 0
    assert "profile: radars/long.radar.yaml" in out.read_text()
    elsewhere = tmp_path / "sub" / "lead.scenario.yaml"
    elsewhere.parent.mkdir()
    assert main(["import", str(DATA / "braking_lead.xosc"), "--radar", str(profile),
                 "--rig", "wide-3x5", "--output", str(elsewhere)]) == 2
    assert "inside its own folder tree" in capsys.readouterr().err


@pytest.mark.parametrize("seed", range(4))
def test_corrupted_files_give_one_error_never_a_traceback(tmp_path, seed):
    """Files of the test set with elements dropped, attributes garbled or the text cut short:
    each imports or fails with the package's one-line error, nothing else."""
    from lxml import etree

    rng = np.random.default_rng(seed)
    sources = sorted((Path(__file__).parent / "data" / "xosc").glob("*.xosc"))
    for case in range(60):
        source = sources[case % len(sources)]
        text = source.read_bytes()
        kind = rng.integers(3)
        if kind == 2:  # cut short
            text = text[: int(rng.integers(1, len(text)))]
        else:
            tree = etree.fromstring(text)
            nodes = [n for n in tree.iter() if isinstance(n.tag, str)][1:]
            node = nodes[int(rng.integers(len(nodes)))]
            if kind == 0 or not node.attrib:
                node.getparent().remove(node)
            else:
                key = list(node.attrib)[int(rng.integers(len(node.attrib)))]
                node.set(key, str(rng.choice(["", "-1e400", "nan", "$missing", "x", "1e9"])))
            text = etree.tostring(tree)
        path = tmp_path / f"case{case}.xosc"
        path.write_bytes(text)
        try:
            import_xosc(path, radar="awr1843boost", rig="wide-3x5")
        except RtsError as exc:  # anything else fails the test with its traceback
            assert str(exc).strip()


def test_cli_import_rejects_a_parameter_given_twice(tmp_path, capsys):
    out = tmp_path / "lead.scenario.yaml"
    code = main(["import", str(DATA / "braking_lead.xosc"), "--radar", "awr1843boost", "--rig",
                 "wide-3x5", "--param", "TargetSpeed=12", "--param", "TargetSpeed=14",
                 "--output", str(out)])
    assert code == 2
    assert capsys.readouterr().err == ("error: --param TargetSpeed: given twice (TargetSpeed=12 "
                                       "and TargetSpeed=14); give each parameter once\n")
    assert not out.exists()


def test_cli_import_rejects_a_parameter_given_twice_with_and_without_its_dollar(tmp_path,
                                                                                capsys):
    # --param takes the name with or without $: EgoSpeed=2 and $EgoSpeed=30 were both taken,
    # the last played.
    out = tmp_path / "cut.scenario.yaml"
    code = main(["import", str(DATA / "cut_in.xosc"), "--radar", "awr1843boost", "--rig",
                 "wide-3x5", "--param", "EgoSpeed=2", "--param", "$EgoSpeed=30",
                 "--output", str(out)])
    assert code == 2
    assert capsys.readouterr().err == ("error: --param $EgoSpeed: given twice (EgoSpeed=2 and "
                                       "$EgoSpeed=30); give each parameter once\n")
    assert not out.exists()


@pytest.mark.parametrize("kind, value, allowed", [
    ("unsignedShort", "70000", "0 to 65535"), ("unsignedShort", "-1", "0 to 65535"),
    ("unsignedInt", "4294967296", "0 to 4294967295"),
    ("integer", "2147483648", "-2147483648 to 2147483647")])
def test_an_integer_parameter_beyond_its_type_is_refused(tmp_path, kind, value, allowed):
    path = variant(tmp_path, "cut_in",
                   '<ParameterDeclaration name="TriggerDistance" parameterType="double" '
                   'value="20"/>',
                   f'<ParameterDeclaration name="TriggerDistance" parameterType="double" '
                   f'value="20"/><ParameterDeclaration name="M" parameterType="{kind}" '
                   f'value="{value}"/>')
    with pytest.raises(ScenarioError, match=rf"M is an {kind} \({allowed}\), got '{value}'"):
        import_xosc(path, radar="awr1843boost", rig="wide-3x5")


def test_an_expression_nested_beyond_the_parser_is_located(tmp_path):
    # 10,000 unary minus signs: CPython's parser ran out of memory (MemoryError, exit 3).
    path = variant(tmp_path, "cut_in",
                   '<ParameterDeclaration name="TriggerDistance" parameterType="double" '
                   'value="20"/>',
                   '<ParameterDeclaration name="TriggerDistance" parameterType="double" '
                   'value="${' + "-" * 10_000 + '20}"/>')
    with pytest.raises(ScenarioError, match=r"cut_in\.xosc:11: <ParameterDeclaration "
                                            r"name=\"TriggerDistance\">: expression nested "
                                            r"too deeply"):
        import_xosc(path, radar="awr1843boost", rig="wide-3x5")


def test_two_speeds_for_one_entity_in_init_are_refused(tmp_path):
    # The first was dropped without a word, the header still naming its parameter.
    speed = ('<PrivateAction>\n            <LongitudinalAction>\n              <SpeedAction>\n'
             '                <SpeedActionDynamics dynamicsShape="step" value="0" '
             'dynamicsDimension="time"/>\n                <SpeedActionTarget>'
             '<AbsoluteTargetSpeed value="$EgoSpeed"/></SpeedActionTarget>\n'
             '              </SpeedAction>\n            </LongitudinalAction>\n'
             '          </PrivateAction>')
    again = speed.replace('value="$EgoSpeed"', 'value="5"')
    path = variant(tmp_path, "cut_in", speed, speed + "\n          " + again)
    with pytest.raises(ScenarioError, match=r"entity 'Ego' is given a speed twice in <Init> "
                                            r"\(first at line 57\)"):
        import_xosc(path, radar="awr1843boost", rig="wide-3x5")


def test_cli_import_that_does_not_load_leaves_no_file_and_keeps_the_old_one(tmp_path, capsys,
                                                                            monkeypatch):
    import dataclasses

    import rts_scenario.xosc as xosc

    real = xosc.import_xosc

    def beyond_limits(*args, **kwargs):
        result = real(*args, **kwargs)
        return dataclasses.replace(result, text=result.text.replace("duration_s:",
                                                                    "duration_s: -1 #"))

    monkeypatch.setattr(xosc, "import_xosc", beyond_limits)
    out = tmp_path / "lead.scenario.yaml"
    argv = ["import", str(DATA / "braking_lead.xosc"), "--radar", "awr1843boost", "--rig",
            "wide-3x5", "--output", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {DATA / 'braking_lead.xosc'}: the scene it converts to does "
                          f"not load") and err.count("\n") == 1
    assert f"{out} not written: {out}:" in err and "duration_s" in err
    assert list(tmp_path.iterdir()) == []
    out.write_text("earlier: scene\n")
    assert main(argv) == 2
    capsys.readouterr()
    assert out.read_text() == "earlier: scene\n"
    assert list(tmp_path.iterdir()) == [out]


def test_a_reversing_speed_is_refused_naming_the_import_s_range_not_the_scene_s():
    # Scenes drive backwards (a negative speed_mps on constant_velocity and speed_profile);
    # the import does not: its refusal says so, and where a scene takes reversing instead.
    path = DATA / "braking_lead.xosc"
    text = path.read_text().splitlines()
    brake = line_of(path, '<Action name="Brake">')
    line = next(i for i, row in enumerate(text[brake:], brake + 1) if "<SpeedAction>" in row)
    with pytest.raises(ScenarioError) as refused:
        import_xosc(path, radar="awr1843boost", rig="wide-3x5",
                    parameters={"TargetSpeed": "-5"})
    message = str(refused.value)
    assert f"braking_lead.xosc:{line}: target speed -5 m/s of 'Lead'" in message
    assert "scenes allow 0 to 150" not in message
    assert "the import takes 0 to 150 m/s (it does not import reversing" in message
    assert "speed_mps" in message


# ----------------------------------------------------- nothing the file says is dropped

def lateral_distance(tmp_path, constraints):
    """The cut-in with its lane change replaced by a lateral distance of 0.5 m to the ego."""
    return replace_lane_change(
        tmp_path,
        f"""<LateralDistanceAction entityRef="Ego" distance="0.5" freespace="false"
                        continuous="false" displacement="leftToReferencedEntity">
                      <DynamicConstraints {constraints}/>
                    </LateralDistanceAction>""")


@pytest.mark.parametrize("constraints, duration_s", [
    # A lateral action's constraints limit its lateral motion; the quintic's peak lateral
    # acceleration is 10 / sqrt(3) * offset / T^2, its speed 15 / 8 * offset / T, its jerk
    # 60 * offset / T^3 (offset 3 m here).
    ('maxAcceleration="1.0"', math.sqrt(10 / math.sqrt(3) * 3.0 / 1.0)),
    ('maxAcceleration="4" maxDeceleration="1.0"', math.sqrt(10 / math.sqrt(3) * 3.0 / 1.0)),
    ('maxSpeed="0.5"', 15 / 8 * 3.0 / 0.5),
    ('maxAcceleration="1" maxSpeed="0.5"', 15 / 8 * 3.0 / 0.5),
    ('maxAccelerationRate="0.5"', (60 * 3.0 / 0.5) ** (1 / 3)),
    ('maxAcceleration="100" maxDecelerationRate="0.5" maxAccelerationRate="9"',
     (60 * 3.0 / 0.5) ** (1 / 3)),
])
def test_lateral_distance_constraints_limit_the_lateral_motion(tmp_path, constraints,
                                                                duration_s):
    _, scene = imported(tmp_path, lateral_distance(tmp_path, constraints))
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.offset_m == pytest.approx(-3.0)
    assert change.start_s == pytest.approx(2.0, abs=1e-9)
    assert change.duration_s == pytest.approx(duration_s, abs=1e-9)  # the file's rounding


def test_lateral_distance_non_standard_limit_is_located(tmp_path):
    path = lateral_distance(tmp_path, 'maxLateralAcc="1.0"')
    line = line_of(path, "maxLateralAcc")
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(f"{path}:{line}: <DynamicConstraints "
                                      f"maxLateralAcc=\"1.0\">: attribute maxLateralAcc is not "
                                      f"supported by import")


def speed_event(name, priority, speed, shape, dyn_value, condition, delay=0.0):
    """An event of the braking lead's maneuver: a speed action of the lead."""
    return f"""<Event name="{name}" priority="{priority}">
              <Action name="{name}A">
                <PrivateAction><LongitudinalAction><SpeedAction>
                  <SpeedActionDynamics dynamicsShape="{shape}" value="{dyn_value}"
                                       dynamicsDimension="time"/>
                  <SpeedActionTarget><AbsoluteTargetSpeed value="{speed}"/></SpeedActionTarget>
                </SpeedAction></LongitudinalAction></PrivateAction>
              </Action>
              <StartTrigger><ConditionGroup>
                <Condition name="{name}C" delay="{delay}" conditionEdge="none">
                  <ByValueCondition>{condition}</ByValueCondition>
                </Condition>
              </ConditionGroup></StartTrigger>
            </Event>
"""


def at_time(t_s):
    return f'<SimulationTimeCondition value="{t_s}" rule="greaterThan"/>'


def with_events(tmp_path, *events, filename="braking_lead.xosc"):
    """The braking lead with events added to its maneuver (after the brake event)."""
    return variant(tmp_path, "braking_lead", "          </Maneuver>",
                   "".join(events) + "          </Maneuver>", filename)


def speed_at(law, t_s):
    k = np.searchsorted(law.knots_s, t_s, side="right") - 1
    return law.v0_mps[k] + law.a_mps2[k] * (t_s - law.knots_s[k])


def test_an_overriding_event_stops_the_running_events_of_its_maneuver(tmp_path):
    # The brake (20 to 10 m/s at 4 m/s^2 from 2 s) is stopped at 3 s by an event of the same
    # maneuver with priority overwrite: the lead keeps 16 m/s from then on. The stopping
    # event's own action changes nothing (a lane offset of 0).
    hold = f"""<Event name="Hold" priority="overwrite">
              <Action name="HoldA">
                <PrivateAction><LateralAction><LaneOffsetAction continuous="false">
                  <LaneOffsetActionDynamics dynamicsShape="step"/>
                  <LaneOffsetTarget><AbsoluteTargetLaneOffset value="0"/></LaneOffsetTarget>
                </LaneOffsetAction></LateralAction></PrivateAction>
              </Action>
              <StartTrigger><ConditionGroup>
                <Condition name="HoldC" delay="0" conditionEdge="none">
                  <ByValueCondition>{at_time(3)}</ByValueCondition>
                </Condition>
              </ConditionGroup></StartTrigger>
            </Event>
"""
    result, scene = imported(tmp_path, with_events(tmp_path, hold))
    assert any("event 'BrakeEvent' stopped at 3 s by event 'Hold' (priority overwrite)" in note
               for note in result.notes)
    t = np.array([0.0, 1.0, 2.0, 2.5, 2.99, 3.0, 3.5, 4.5, 5.9])
    dt = np.clip(t - 2.0, 0.0, 1.0)
    x = 40.0 + 20.0 * t - 2.0 * dt**2 - 4.0 * np.clip(t - 3.0, 0.0, None)
    lead_p, lead_v = straight(x, 20.0 - 4.0 * dt, z_m=0.75)
    assert_tracks(scene, t, *ego_radar(t, 20.0), lead_p, lead_v)
    # priority override (OpenSCENARIO 1.2's name) is the same.
    path = with_events(tmp_path, hold.replace('"overwrite"', '"override"'), filename="o.xosc")
    _, scene = imported(tmp_path, path)
    assert_tracks(scene, t, *ego_radar(t, 20.0), lead_p, lead_v)


def test_an_overriding_event_that_would_stop_a_lateral_move_midway_is_located(tmp_path):
    # The speed-up starts 1 s into the 3 s cut-in with priority overwrite: the cut-in would
    # stop with the cutter between the lanes, which a scene's lane change cannot play.
    path = variant(tmp_path, "cut_in", '<Event name="SpeedUpEvent" priority="parallel">',
                   '<Event name="SpeedUpEvent" priority="overwrite">')
    path.write_text(path.read_text()
                    .replace('storyboardElementRef="CutInEvent" state="endTransition"',
                             'storyboardElementRef="CutInEvent" state="startTransition"')
                    .replace('<Condition name="CutInDone" delay="0"',
                             '<Condition name="CutInDone" delay="1"'))
    line = line_of(path, '<Event name="SpeedUpEvent"')
    cut_in = line_of(path, '<Event name="CutInEvent"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(
        f"{path}:{line}: event 'SpeedUpEvent' (priority overwrite) starts at 3 s and would stop "
        f"event 'CutInEvent' (line {cut_in}) in the middle of the lateral move of 'Cutter'")


def test_an_overridden_action_ends_when_a_new_one_takes_over(tmp_path):
    # The brake (2 s to 4.5 s) is overridden at 3 s by a step to 18 m/s (another event, in
    # parallel): the brake action ends at 3 s, so the event waiting for its end (plus 1 s)
    # speeds the lead up to 25 m/s from 4 s, not from 5.5 s.
    done = ('<StoryboardElementStateCondition storyboardElementType="action" '
            'storyboardElementRef="Brake" state="{}"/>')
    for state in ("completeState", "endTransition"):
        path = with_events(tmp_path, speed_event("Cruise", "parallel", 18, "step", 0, at_time(3)),
                           speed_event("After", "parallel", 25, "linear", 1,
                                       done.format(state), delay=1.0))
        _, scene = imported(tmp_path, path)
        law = scene.targets[0].trajectory.law
        # The step from 16.0 m/s ramps at 15 m/s2 over 2 / 15 s centred on 3 s: at 2.9 s the
        # brake still holds.
        speeds = [speed_at(law, t) for t in (2.5, 2.9, 3.5, 3.99, 4.5, 5.0, 5.5)]
        assert speeds == pytest.approx([18.0, 16.4, 18.0, 18.0, 21.5, 25.0, 25.0])


def test_an_action_of_several_actors_ends_when_the_last_actor_s_part_ends(tmp_path):
    # The ego joins the cut-in: its own lane change is empty (it is in the target lane), the
    # cutter's 3.5 m at a peak lateral speed of 1.75 m/s take 15/8 * 3.5 / 1.75 = 3.75 s. The
    # speed-up waits for the action's end: 2 + 3.75 s.
    path = variant(tmp_path, "cut_in", '<EntityRef entityRef="Cutter"/></Actors>',
                   '<EntityRef entityRef="Cutter"/><EntityRef entityRef="Ego"/></Actors>')
    path.write_text(path.read_text()
                    .replace('value="$LaneChangeTime" dynamicsDimension="time"',
                             'value="1.75" dynamicsDimension="rate"')
                    .replace('storyboardElementType="event" storyboardElementRef="CutInEvent"',
                             'storyboardElementType="action" storyboardElementRef="CutIn"'))
    _, scene = imported(tmp_path, path)
    law = scene.targets[0].trajectory.law
    assert [speed_at(law, t) for t in (5.74, 5.75, 6.75, 7.75, 9.0)] == pytest.approx(
        [20.0, 20.0, 22.5, 25.0, 25.0])


def test_a_lateral_move_started_during_another_gets_a_note(tmp_path):
    text = (DATA / "cut_in.xosc").read_text()
    speed_up = re.search(r"<LongitudinalAction>\s*<SpeedAction>\s*<SpeedActionDynamics "
                         r"dynamicsShape=\"linear\".*?</LongitudinalAction>", text,
                         flags=re.DOTALL).group(0)
    path = tmp_path / "cut_in.xosc"
    path.write_text(text.replace(speed_up, """<LateralAction><LaneOffsetAction continuous="false">
                      <LaneOffsetActionDynamics maxLateralAcc="0.5" dynamicsShape="cubic"/>
                      <LaneOffsetTarget><AbsoluteTargetLaneOffset value="0.5"/></LaneOffsetTarget>
                    </LaneOffsetAction></LateralAction>""")
                    .replace('storyboardElementRef="CutInEvent" state="endTransition"',
                             'storyboardElementRef="CutInEvent" state="startTransition"')
                    .replace('<Condition name="CutInDone" delay="0"',
                             '<Condition name="CutInDone" delay="1"'))
    result, scene = imported(tmp_path, path)
    first, second = scene.targets[0].trajectory.lane_changes
    assert (first.start_s, first.offset_m, second.start_s, second.offset_m) == pytest.approx(
        (2.0, -3.5, 3.0, 0.5))
    assert (f"{path}:{line_of(path, '<LaneOffsetAction')}: lateral move of 'Cutter' starts at "
            f"3 s while the one of line {line_of(path, '<LaneChangeAction>')} is under way "
            f"(until 5 s)") in "\n".join(result.notes)


def constrained(tmp_path, groups):
    """The cut-in with constraint groups on its parameter EgoSpeed (declared 25)."""
    return variant(tmp_path, "cut_in",
                   '<ParameterDeclaration name="EgoSpeed" parameterType="double" value="25"/>',
                   '<ParameterDeclaration name="EgoSpeed" parameterType="double" value="25">'
                   f'{groups}</ParameterDeclaration>')


def test_parameter_value_constraints_are_checked(tmp_path):
    # Groups are OR-ed, the constraints of a group AND-ed (OpenSCENARIO 1.1).
    groups = ('<ConstraintGroup><ValueConstraint rule="greaterOrEqual" value="20"/>'
              '<ValueConstraint rule="lessOrEqual" value="30"/></ConstraintGroup>'
              '<ConstraintGroup><ValueConstraint rule="equalTo" value="40"/></ConstraintGroup>')
    path = constrained(tmp_path, groups)
    for speed in ("20", "30", "40"):
        _, scene = imported(tmp_path, path, parameters={"EgoSpeed": speed})
        assert scene.ego.law.v0_mps[0] == pytest.approx(float(speed))
    with pytest.raises(RtsError) as info:
        imported(tmp_path, path, parameters={"EgoSpeed": "35"})
    line = line_of(path, '<ParameterDeclaration name="EgoSpeed"')
    assert str(info.value) == (
        f"--param EgoSpeed=35: outside the values {path}:{line} allows for EgoSpeed: "
        f"(greaterOrEqual 20 and lessOrEqual 30) or (equalTo 40)")
    # A declared value outside its own constraints is located.
    path = constrained(tmp_path, '<ConstraintGroup><ValueConstraint rule="lessThan" '
                                 'value="20"/></ConstraintGroup>')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (f"{path}:{line}: <ParameterDeclaration name=\"EgoSpeed\">: value "
                               f"25 is outside the values allowed: (lessThan 20)")


@pytest.mark.parametrize("groups, needle, message", [
    ('<ConstraintGroup><ValueConstraint rule="lessThan" value="30" unit="m"/></ConstraintGroup>',
     'unit="m"', '<ValueConstraint unit="m">: attribute unit is not supported by import'),
    ('<ConstraintGroup><ValueConstraint rule="below" value="30"/></ConstraintGroup>',
     'rule="below"', '<ValueConstraint rule="below"> is not supported by import; supported: '
                     'greaterThan, greaterOrEqual, lessThan, lessOrEqual, equalTo, notEqualTo'),
    ('<Range lower="1"/>', '<Range', '<Range> in <ParameterDeclaration> is not supported'),
    ('<ConstraintGroup/>', '<ConstraintGroup/>', '<ConstraintGroup> needs at least one '
                                                 '<ValueConstraint>'),
])
def test_bad_parameter_constraints_are_located(tmp_path, groups, needle, message):
    path = constrained(tmp_path, groups)
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(f"{path}:{line_of(path, needle)}: ")
    assert message in str(info.value)


def test_parameter_declaration_attributes_are_checked(tmp_path):
    path = variant(tmp_path, "cut_in", 'name="EgoSpeed" parameterType="double" value="25"',
                   'name="EgoSpeed" parameterType="double" value="25" unit="km/h"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(
        f"{path}:{line_of(path, 'unit=')}: <ParameterDeclaration unit=\"km/h\">: attribute unit "
        f"is not supported by import")


@pytest.mark.parametrize("old, new, needle, message", [
    # An empty trigger means nothing in OpenSCENARIO (1.0 allows it, 1.1 calls it not
    # meaningful): the event would start at once.
    (r"<StartTrigger>\s*<ConditionGroup>\s*<Condition name=\"EgoClose\".*?</StartTrigger>",
     "<StartTrigger/>", "<StartTrigger/>",
     "an empty <StartTrigger> is not supported by import"),
    (r"<StartTrigger>\s*<ConditionGroup>\s*<Condition name=\"ActStart\".*?</StartTrigger>",
     "<StartTrigger></StartTrigger>", "<StartTrigger></StartTrigger>",
     "an empty <StartTrigger> is not supported by import"),
    # Lanes are whole: half a lane is no OpenSCENARIO value.
    (r'<RelativeTargetLane entityRef="Ego" value="0"/>',
     '<RelativeTargetLane entityRef="Ego" value="0.5"/>', 'value="0.5"',
     '<RelativeTargetLane value="0.5">: must be a whole number of lanes'),
    # An attribute in another namespace is no OpenSCENARIO attribute.
    (r'<WorldPosition x="0" y="0" h="0"/>',
     '<WorldPosition xmlns:f="urn:x" x="0" y="0" h="0" f:z="5"/>', 'f:z="5"',
     '<WorldPosition f:z="5">: attribute f:z is not supported by import'),
    # Text inside an element is no OpenSCENARIO data.
    (r'<AbsoluteTargetSpeed value="\$EgoSpeed"/>',
     '<AbsoluteTargetSpeed value="$EgoSpeed">30</AbsoluteTargetSpeed>', ">30<",
     "<AbsoluteTargetSpeed> contains text ('30'): OpenSCENARIO gives values as attributes"),
])
def test_constructs_the_import_cannot_honour_are_located(tmp_path, old, new, needle, message):
    text = (DATA / "cut_in.xosc").read_text()
    path = tmp_path / "cut_in.xosc"
    path.write_text(re.sub(old, lambda _: new, text, count=1, flags=re.DOTALL))
    assert path.read_text() != text
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(f"{path}:{line_of(path, needle)}: ")
    assert message in str(info.value)


def test_unsupported_attribute_names_the_element_path_and_the_supported_ones(tmp_path):
    path = variant(tmp_path, "braking_lead", 'dynamicsShape="linear" value="$Deceleration"',
                   'dynamicsShape="linear" value="$Deceleration" extra="1"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (
        f"{path}:{line_of(path, 'extra=')}: <SpeedActionDynamics extra=\"1\">: attribute extra "
        f"is not supported by import; supported: dynamicsDimension, dynamicsShape, "
        f"followingMode, value (at Storyboard/Story/Act/ManeuverGroup/Maneuver/Event/Action/"
        f"PrivateAction/LongitudinalAction/SpeedAction/SpeedActionDynamics)")
    path = variant(tmp_path, "braking_lead", "<Properties/>\n      </Vehicle>",
                   "<Properties/>\n        <Trailer/>\n      </Vehicle>")
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (
        f"{path}:{line_of(path, '<Trailer/>')}: <Trailer> in <Vehicle> is not supported by "
        f"import; supported in <Vehicle>: Axles, BoundingBox, ParameterDeclarations, "
        f"Performance, Properties (at Entities/ScenarioObject/Vehicle/Trailer)")


def test_a_continuous_relative_lane_offset_is_set_once_with_a_note(tmp_path):
    path = replace_lane_change(
        tmp_path,
        """<LaneOffsetAction continuous="true">
                      <LaneOffsetActionDynamics maxLateralAcc="0.5" dynamicsShape="linear"/>
                      <LaneOffsetTarget>
                        <RelativeTargetLaneOffset entityRef="Ego" value="0.4"/>
                      </LaneOffsetTarget>
                    </LaneOffsetAction>""")
    result, scene = imported(tmp_path, path)
    (change,) = scene.targets[0].trajectory.lane_changes
    assert (change.start_s, change.offset_m) == pytest.approx((2.0, 0.4))
    assert (f"{path}:{line_of(path, '<LaneOffsetAction')}: continuous lane offset of 'Cutter' "
            f"relative to 'Ego' set once at 2 s; later lateral moves of 'Ego' are not "
            f"followed") in result.notes


# ------------------------------------------------------------- the test files' scenes

SHIPPED = {"braking_lead": None, "cut_in": None, "pedestrian_crossing": "Hero",
           "storyboard": None}


@pytest.mark.parametrize("name", SHIPPED)
def test_each_test_file_imports_to_its_recorded_scene(name):
    """The scenes recorded in tests/data/xosc/expected: what each file meant before the
    import learnt to refuse more; a change there must be a deliberate one."""
    import json

    result = import_xosc(DATA / f"{name}.xosc", radar="awr1843boost", rig="wide-3x5",
                         ego=SHIPPED[name])
    # JSON, not YAML: a YAML file holding a scene outside *.scenario.yaml is taken for a
    # misnamed scene by the pytest plugin.
    expected = json.loads((DATA / "expected" / f"{name}.json").read_text())
    assert result.scene == expected


def literal_twin(source: Path, target: Path, overrides=None):
    """Write ``source`` with every $parameter replaced by its value, no declarations."""
    from lxml import etree

    tree = etree.parse(str(source))
    root = tree.getroot()
    values = {}
    for block in root.findall("ParameterDeclarations"):
        for decl in block.findall("ParameterDeclaration"):
            values[decl.get("name")] = decl.get("value")
        root.remove(block)
    values.update(overrides or {})
    for el in root.iter():
        for key, value in el.attrib.items():
            if value.startswith("$"):
                el.set(key, values[value[1:]])
    tree.write(str(target))
    assert "$" not in target.read_text()
    return target


@pytest.mark.parametrize("name, overrides", [
    ("braking_lead", {}), ("braking_lead", {"TargetSpeed": "12", "Deceleration": "2.5"}),
    ("cut_in", {}), ("cut_in", {"TriggerDistance": "17.5", "LaneChangeTime": "4"}),
])
def test_a_parameterized_file_imports_equal_to_its_literal_twin(tmp_path, name, overrides):
    twin = literal_twin(DATA / f"{name}.xosc", tmp_path / f"{name}.xosc", overrides)
    original = import_xosc(DATA / f"{name}.xosc", radar="awr1843boost", rig="wide-3x5",
                           parameters=overrides)
    literal = import_xosc(twin, radar="awr1843boost", rig="wide-3x5")
    assert original.scene == literal.scene
    assert original.parameters and not literal.parameters
    # And the parameters matter: the twin of other values is another scene.
    if overrides:
        plain = import_xosc(DATA / f"{name}.xosc", radar="awr1843boost", rig="wide-3x5")
        assert plain.scene != literal.scene


def init_relative_speed(tmp_path, cutter_first, ego_target=None):
    """The cut-in with the cutter's initial speed 0.8 times the ego's (its Private listed
    first or second in Init); ``ego_target`` replaces the ego's own initial target speed."""
    text = (DATA / "cut_in.xosc").read_text()
    ego = re.search(r'        <Private entityRef="Ego">.*?</Private>\n', text,
                    flags=re.DOTALL).group(0)
    cut = re.search(r'        <Private entityRef="Cutter">.*?</Private>\n', text,
                    flags=re.DOTALL).group(0)
    if cutter_first:
        text = text.replace(ego + cut, cut + ego)
    text = text.replace('<AbsoluteTargetSpeed value="$CutterSpeed"/>',
                        '<RelativeTargetSpeed entityRef="Ego" value="0.8" '
                        'speedTargetValueType="factor" continuous="false"/>')
    if ego_target:
        text = text.replace('<AbsoluteTargetSpeed value="$EgoSpeed"/>', ego_target)
    path = tmp_path / ("cutter_first.xosc" if cutter_first else "ego_first.xosc")
    path.write_text(text)
    return path


def test_init_actions_relative_to_another_entity_do_not_depend_on_the_file_order(tmp_path):
    # Init happens at t = 0: the cutter starts at 0.8 * 25 = 20 m/s whichever Private comes
    # first (listed first, it took the ego's speed before the ego had one: 0 m/s).
    for cutter_first in (False, True):
        _, scene = imported(tmp_path, init_relative_speed(tmp_path, cutter_first))
        law = scene.targets[0].trajectory.law
        assert speed_at(law, 0.0) == pytest.approx(20.0)
        assert speed_at(law, 1.0) == pytest.approx(20.0)


def test_init_actions_relative_to_each_other_are_located(tmp_path):
    path = init_relative_speed(tmp_path, True, '<RelativeTargetSpeed entityRef="Cutter" '
                               'value="1" speedTargetValueType="delta" continuous="false"/>')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    rows = path.read_text().splitlines()
    target = line_of(path, 'value="0.8" speedTargetValueType="factor"')
    line = max(i for i, row in enumerate(rows[:target], 1) if "<SpeedAction>" in row)
    assert str(info.value).startswith(
        f"{path}:{line}: the initial speed action of 'Cutter' refers to 'Ego', whose "
        f"initial speed action refers back to it")


def test_a_rising_edge_already_true_when_evaluated_gets_a_note(tmp_path):
    # The gap is 30 m at the act's start: below 40 m already. Read as firing then (what a
    # simulator that starts with "false" does); a note says a rising edge may wait instead.
    result, scene = imported(tmp_path, "cut_in", parameters={"TriggerDistance": "40"})
    (change,) = scene.targets[0].trajectory.lane_changes
    assert change.start_s == pytest.approx(0.0)
    line = line_of(DATA / "cut_in.xosc", '<Condition name="EgoClose"')
    assert (f"{DATA / 'cut_in.xosc'}:{line}: condition 'EgoClose' (conditionEdge rising) is "
            f"already true when its evaluation starts at 0 s: fired then (a simulator may "
            f"instead wait for it to turn false and true again)") in result.notes
    # Edge none: no note; a rising edge that turns true later: none either.
    path = variant(tmp_path, "cut_in", '<Condition name="EgoClose" delay="0" '
                   'conditionEdge="rising">', '<Condition name="EgoClose" delay="0" '
                   'conditionEdge="none">')
    result, _ = imported(tmp_path, path, parameters={"TriggerDistance": "40"})
    assert not any("conditionEdge" in note for note in result.notes)
    result, _ = imported(tmp_path, "cut_in")
    assert not any("conditionEdge" in note for note in result.notes)


def test_a_parameter_declared_twice_is_located(tmp_path):
    path = variant(tmp_path, "cut_in",
                   '<ParameterDeclaration name="LaneChangeTime" parameterType="double" '
                   'value="3"/>',
                   '<ParameterDeclaration name="LaneChangeTime" parameterType="double" '
                   'value="3"/>\n    <ParameterDeclaration name="EgoSpeed" '
                   'parameterType="double" value="30"/>')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    second, first = line_of(path, 'value="30"'), line_of(path, 'name="EgoSpeed"')
    assert str(info.value) == (f"{path}:{second}: <ParameterDeclaration name=\"EgoSpeed\">: "
                               f"declared twice (first at line {first})")


def test_a_state_condition_on_a_name_two_elements_share_is_located(tmp_path):
    # Two events named CutInEvent: which one's end starts the speed-up is not said.
    path = variant(tmp_path, "cut_in", '<Event name="SpeedUpEvent" priority="parallel">',
                   '<Event name="CutInEvent" priority="parallel">')
    path.write_text(path.read_text().replace(
        'storyboardElementRef="CutInEvent" state="endTransition"',
        'storyboardElementRef="CutInEvent" state="startTransition"'))
    line = line_of(path, "<StoryboardElementStateCondition")
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (
        f"{path}:{line}: <StoryboardElementStateCondition>: 2 events are named 'CutInEvent': "
        f"the reference is ambiguous (give them distinct names)")


@pytest.mark.parametrize("value", ["1_0", "0x10", "٣"])
def test_a_number_outside_xml_schema_s_form_is_located(tmp_path, value):
    # Python's float() reads these (10, -, 3); OpenSCENARIO's doubles are XML Schema doubles.
    path = variant(tmp_path, "cut_in", '<RelativeWorldPosition entityRef="Ego" dx="30"',
                   f'<RelativeWorldPosition entityRef="Ego" dx="{value}"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(
        f"{path}:{line_of(path, '<RelativeWorldPosition')}: <RelativeWorldPosition "
        f"dx=\"{value}\">: must be a number")


def test_a_step_with_a_value_gets_a_note(tmp_path):
    path = variant(tmp_path, "pedestrian_crossing", 'dynamicsShape="step" value="0"',
                   'dynamicsShape="step" value="2"')
    result, _ = imported(tmp_path, path, ego="Hero")
    line = line_of(path, 'dynamicsShape="step" value="2"')
    assert (f"{path}:{line}: <SpeedActionDynamics dynamicsShape=\"step\" value=\"2\">: played "
            f"as an immediate change (a step takes no time; the value is not used)") \
        in result.notes
    result, _ = imported(tmp_path, "pedestrian_crossing", ego="Hero")
    assert not any("immediate change" in note for note in result.notes)


def test_nesting_beyond_the_parser_s_depth_says_the_limit(tmp_path):
    # libxml's message advised its own parser option ("use XML_PARSE_HUGE"), which users
    # cannot set.
    path = tmp_path / "deep.xosc"
    path.write_text("<OpenSCENARIO>" + "<RoadNetwork>" * 300 + "</RoadNetwork>" * 300
                    + "</OpenSCENARIO>")
    with pytest.raises(ScenarioError, match=r"deep\.xosc:1: elements nested deeper than 256 "
                                            r"levels \(import's limit, for any element, skipped "
                                            r"ones included\)$"):
        imported(tmp_path, path)


@pytest.mark.parametrize(("value", "message"), [
    # It said "declared after it" with the declaration's own line.
    ("$EgoSpeed", "$EgoSpeed names the declaration itself"),
    # An expression said only "unknown parameter", with no line.
    ("${$CutterSpeed + 5}", "$CutterSpeed is declared after it (line {later})"),
])
def test_a_declaration_naming_itself_or_a_later_one_in_an_expression(tmp_path, value, message):
    path = variant(tmp_path, "cut_in", 'name="EgoSpeed" parameterType="double" value="25"',
                   f'name="EgoSpeed" parameterType="double" value="{value}"')
    line, later = line_of(path, 'name="EgoSpeed"'), line_of(path, 'name="CutterSpeed"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value) == (
        f"{path}:{line}: <ParameterDeclaration name=\"EgoSpeed\">: "
        f"{message.format(later=later)}; a declaration can use only the parameters declared "
        f"before it; declared before it: none")


def test_a_speed_transition_beyond_the_scene_format_s_acceleration_is_refused(tmp_path):
    # The lead brakes from 20 m/s to 10 m/s at 20 m/s2; scenes take at most 15 m/s2.
    path = variant(tmp_path, "braking_lead",
                   'dynamicsShape="linear" value="$Deceleration" dynamicsDimension="rate"',
                   'dynamicsShape="linear" value="20" dynamicsDimension="rate"')
    with pytest.raises(ScenarioError) as info:
        imported(tmp_path, path)
    assert str(info.value).startswith(f"{path}:")
    assert ("changes from 20 to 10 m/s in 0.5 s (linear): a peak acceleration of 20 m/s2; a "
            "scene's accelerations run from -15 to 15 m/s2") in str(info.value)
    # At the bound it imports, and brakes at 15 m/s2.
    path = variant(tmp_path, "braking_lead",
                   'dynamicsShape="linear" value="$Deceleration" dynamicsDimension="rate"',
                   'dynamicsShape="linear" value="15" dynamicsDimension="rate"')
    _, scene = imported(tmp_path, path)
    assert scene.targets[0].trajectory.law.a_mps2.min() == pytest.approx(-15.0)


def test_a_step_ramps_at_the_scene_format_s_acceleration_keeping_positions_after_it(tmp_path):
    result, scene = imported(tmp_path, "pedestrian_crossing", ego="Hero")
    law = scene.targets[0].trajectory.law
    # 0 to 1.4 m/s at 15 m/s2 (10 ns longer, for the times written to 1 ns).
    assert np.abs(law.a_mps2).max() == pytest.approx(15.0, rel=1e-6)
    assert np.abs(law.a_mps2).max() <= 15.0
    assert law.knots_s[-1] - law.knots_s[-2] == pytest.approx(1.4 / 15.0, abs=1e-7)
    assert not any("played as a ramp" in note for note in result.notes)


@pytest.mark.parametrize("shape, value", [("step", "3"), ("linear", "-2")])
def test_a_lateral_shift_faster_than_the_bound_plays_as_the_shortest_lane_change(
        tmp_path, shape, value):
    # A lane offset of 3 m as a step (or -2 m at 100 m/s2 sideways, over
    # sqrt(10 / sqrt(3) * 2 / 100) s) at 3 s: the scene format allows 15 m/s2 sideways, so it
    # plays as the shortest quintic within it, sqrt(10 / sqrt(3) * |offset| / 15) long,
    # centred on the shift's middle.
    duration = "" if shape == "step" else ' maxLateralAcc="100"'
    event = f"""<Event name="Shift" priority="parallel">
              <Action name="ShiftA">
                <PrivateAction><LateralAction><LaneOffsetAction continuous="false">
                  <LaneOffsetActionDynamics dynamicsShape="{shape}"{duration}/>
                  <LaneOffsetTarget><AbsoluteTargetLaneOffset value="{value}"/></LaneOffsetTarget>
                </LaneOffsetAction></LateralAction></PrivateAction>
              </Action>
              <StartTrigger><ConditionGroup>
                <Condition name="ShiftC" delay="0" conditionEdge="none">
                  <ByValueCondition>{at_time(3)}</ByValueCondition>
                </Condition>
              </ConditionGroup></StartTrigger>
            </Event>
"""
    result, scene = imported(tmp_path, with_events(tmp_path, event))
    offset = abs(float(value))
    shortest = math.sqrt(10 / math.sqrt(3) * offset / 15)
    fast = math.sqrt(10 / math.sqrt(3) * offset / 100)
    middle = 3.0 if shape == "step" else 3.0 + fast / 2
    (change,) = scene.targets[0].trajectory.lane_changes
    assert abs(change.offset_m) == pytest.approx(offset)
    assert change.duration_s == pytest.approx(shortest, abs=1e-6)  # the file's rounding
    assert change.start_s == pytest.approx(middle - shortest / 2, abs=1e-6)
    what = "step" if shape == "step" else f"shift over {fast:.3f} s"
    assert any(f"lateral {what} of " in note and "played as the shortest quintic lane change "
               "within 15 m/s2 sideways" in note for note in result.notes), result.notes


@pytest.mark.parametrize("category, kind, rcs", [
    ("pedestrian", "pedestrian", {"rcs_dbsm": -8.0, "fluctuation": "swerling1"}),
    ("wheelchair", "pedestrian", {"rcs_dbsm": -8.0, "fluctuation": "swerling1"}),
    # docs/import.md: an animal is of kind other with the pedestrian model (not other's 10 dBsm)
    ("animal", "other", {"rcs_dbsm": -8.0, "fluctuation": "swerling1"}),
])
def test_each_pedestrian_category_gets_the_kind_and_rcs_the_docs_give(tmp_path, category, kind,
                                                                      rcs):
    path = variant(tmp_path, "pedestrian_crossing", 'pedestrianCategory="pedestrian"',
                   f'pedestrianCategory="{category}"')
    result, scene = imported(tmp_path, path, ego="Hero")
    target = yaml.safe_load(result.text)["targets"][0]
    assert (target["kind"], target["rcs"]) == (kind, rcs)
    assert scene.targets[0].kind == kind


def test_cli_import_refused_names_the_xosc_element_the_failing_key_came_from(tmp_path, capsys):
    # The ego stands (no SpeedAction) and changes lane from 1 s: the scene refuses the lane
    # change; the error points at the LaneChangeAction in the .xosc, not at the scene it did
    # not write.
    source = DATA / "ego_lane_change_standing.xosc"
    out = tmp_path / "stand.scenario.yaml"
    assert main(["import", str(source), "--radar", "awr1843boost", "--rig", "wide-3x5",
                 "--output", str(out)]) == 2
    err = capsys.readouterr().err
    line = line_of(source, "<LaneChangeAction>")
    assert err.startswith(f"error: {source}:{line}: <LaneChangeAction>: the scene it converts "
                          f"to does not load")
    assert "ego.lane_changes[0]: the ego's speed along its path is 0 at 1 s" in err
    assert list(tmp_path.iterdir()) == []


def test_a_lane_change_over_a_distance_says_it_is_timed_at_its_start(tmp_path):
    # 60 m at the cutter's 20 m/s: 3 s, fixed when it starts (2 s); a note says so.
    path = variant(tmp_path, "cut_in", 'value="$LaneChangeTime" dynamicsDimension="time"',
                   'value="60" dynamicsDimension="distance"')
    result, _ = imported(tmp_path, path)
    change = yaml.safe_load(result.text)["targets"][0]["lane_changes"][0]
    assert (change["start_s"], change["duration_s"]) == pytest.approx((2.0, 3.0))
    assert any(note.endswith("lane change of 'Cutter' over 60 m played over the 3.000 s its "
                             "speeds as known at 2.000 s take to cover it: a speed action that "
                             "starts later does not stretch it") for note in result.notes)


def test_a_lane_change_over_a_short_distance_is_said_once_as_the_shortest_quintic(tmp_path):
    # 5 m at 20 m/s: 0.25 s, faster than a scene's lane change may be; said as the shortest
    # quintic, not as one timed over 0.25 s.
    path = variant(tmp_path, "cut_in", 'value="$LaneChangeTime" dynamicsDimension="time"',
                   'value="5" dynamicsDimension="distance"')
    result, _ = imported(tmp_path, path)
    assert any("played as the shortest quintic lane change" in note for note in result.notes)
    assert not any("its speeds as known at" in note for note in result.notes)
