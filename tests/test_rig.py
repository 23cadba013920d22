from pathlib import Path

import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.rig import preset_names

ROOT = Path(__file__).resolve().parents[1]
TABLE_I = ([-5.4, 4.5, -3.4, 3.8], [-8.8, -7.7, 8.4, 9.9])


def test_kit_table1_is_the_papers_table_i():
    rig = rs.Rig.preset("kit-table1")
    np.testing.assert_array_equal(rig.az_deg, TABLE_I[0])
    np.testing.assert_array_equal(rig.el_deg, TABLE_I[1])
    np.testing.assert_array_equal(rig.distance_m, 1.0)
    assert rig.quads.tolist() == [[0, 1, 2, 3]]


def test_from_angles_equals_preset():
    rig = rs.Rig.from_angles(az_deg=TABLE_I[0], el_deg=TABLE_I[1], distance_m=1.0)
    preset = rs.Rig.preset("kit-table1")
    np.testing.assert_array_equal(rig.az_deg, preset.az_deg)
    np.testing.assert_array_equal(rig.el_deg, preset.el_deg)


def test_grid_quads_follow_paper_order():
    rig = rs.Rig.grid([-20, -10, 0, 10], [-5, 5, 15])
    assert rig.rows == 3 and rig.columns == 4
    assert len(rig.quads) == 6
    for fes in rig.quads:
        az, el = rig.az_deg[fes], rig.el_deg[fes]
        assert az[0] < az[1] and az[2] < az[3]
        assert el[0] < el[2] and el[1] < el[3]
    # Neighbouring quads share their border FEs.
    assert set(rig.quads[0]) & set(rig.quads[1]) == {1, 5}


def test_wide_preset_covers_required_field():
    rig = rs.Rig.preset("wide-3x5")
    assert rig.az_deg.min() <= -20 and rig.az_deg.max() >= 20
    assert rig.el_deg.min() <= -8 and rig.el_deg.max() >= 8
    assert set(preset_names()) >= {"kit-table1", "wide-3x5"}


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios" / "rigs").glob("*.rig.yaml")),
                         ids=lambda p: p.name)
def test_shipped_rig_files_load(path):
    rig = rs.Rig.from_file(path)
    assert rig.n_front_ends == rig.rows * rig.columns


def test_rig_file_keeps_calibration_and_limits():
    rig = rs.Rig.from_file(ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml")
    assert rig.cal_phase_deg[1] == 12.5
    assert rig.distance_m[2] == 1.01
    assert rig.limits.attenuation_step_db == 0.5
    assert rig.limits.echoes_per_channel == 4
    assert rig.reference.attenuation_db == 42.0


def test_a_phase_shifter_sets_the_nearest_of_its_steps():
    limits = rs.HardwareLimits(phase_step_deg=5.625)  # 6 bits
    deg = np.array([0.0, 2.8, 2.9, -2.9, 8.4, 179.0, -180.0, 370.0, -725.0, np.nan])
    # By hand: 2.8 < 5.625 / 2 < 2.9; 8.4 is just below 8.4375 = 1.5 steps; 179 rounds to 180,
    # which is -180 wrapped; 370 is 10 deg a turn on; -725 is -5 deg two turns back.
    expected = np.array([0.0, 0.0, 5.625, -5.625, 5.625, -180.0, -180.0, 11.25, -5.625, np.nan])
    np.testing.assert_allclose(np.degrees(limits.phase_setting(np.radians(deg))), expected,
                               atol=1e-12)
    rng = np.random.default_rng(0)
    phase = rng.uniform(-4.0 * np.pi, 4.0 * np.pi, 10_000)
    for step in (5.625, 22.5, 120.0, 180.0):
        limits = rs.HardwareLimits(phase_step_deg=step)
        out = limits.phase_setting(phase)
        # On the steps, within [-pi, pi), at most half a step from the phase asked (on the
        # circle), and the same for a phase a turn away.
        k = np.degrees(out) / step
        np.testing.assert_allclose(k, np.round(k), atol=1e-9)
        assert np.all((out >= -np.pi) & (out < np.pi))
        miss = np.degrees(np.angle(np.exp(1j * (out - phase))))
        assert np.abs(miss).max() <= step / 2 + 1e-9
        np.testing.assert_array_equal(limits.phase_setting(phase + 2.0 * np.pi), out)
    # Continuous: wrapped only.
    np.testing.assert_allclose(rs.HardwareLimits().phase_setting(np.radians([190.0, -10.0])),
                               np.radians([-170.0, -10.0]), atol=1e-12)


def test_rig_file_reads_the_phase_step(tmp_path):
    path = tmp_path / "p.rig.yaml"
    path.write_text("rts_rig: 1\nname: p\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\n"
                    "limits: {phase_step_deg: 5.625}\n")
    rig = rs.Rig.from_file(path)
    assert rig.limits.phase_step_deg == 5.625
    assert rs.Rig.preset("kit-table1").limits.phase_step_deg == 0.0
    # Written back and read again.
    rig.write(tmp_path / "q.rig.yaml")
    assert rs.Rig.from_file(tmp_path / "q.rig.yaml").limits.phase_step_deg == 5.625


def test_fe_antenna_offsets_and_delay_model_from_a_file(tmp_path):
    path = tmp_path / "fe.rig.yaml"
    path.write_text(
        "rts_rig: 1\nname: fe\nrts: {delay_model: rf}\nfront_ends:\n"
        "  - {az_deg: -5, el_deg: -5, rx_offset_m: [0.03, -0.01], tx_offset_m: [-0.03, 0.0]}\n"
        "  - {az_deg: 5, el_deg: -5}\n  - {az_deg: -5, el_deg: 5}\n  - {az_deg: 5, el_deg: 5}\n")
    rig = rs.Rig.from_file(path)
    np.testing.assert_array_equal(rig.rx_offset_m, [[0.03, -0.01], [0, 0], [0, 0], [0, 0]])
    np.testing.assert_array_equal(rig.tx_offset_m, [[-0.03, 0.0], [0, 0], [0, 0], [0, 0]])
    assert rig.rts.delay_model == "rf" and rig.rts.delayed_frequency_hz(77e9) == 77e9
    with pytest.raises(ValueError, match="read-only"):
        rig.rx_offset_m[0, 0] = 1.0
    # Defaults: antennas at the nominal point, the paper's digital RTS at a 500 MHz IF.
    kit = rs.Rig.preset("kit-table1")
    np.testing.assert_array_equal(kit.rx_offset_m, np.zeros((4, 2)))
    np.testing.assert_array_equal(kit.tx_offset_m, np.zeros((4, 2)))
    assert kit.rts.delay_model == "if" and kit.rts.delayed_frequency_hz(77e9) == 500e6
    with pytest.raises(rs.RigError, match="one per FE"):
        rs.Rig.from_angles(*TABLE_I, rx_offset_m=np.zeros((3, 2)))


def test_from_angles_rejects_wrong_order():
    with pytest.raises(rs.RigError, match="increasing azimuth"):
        rs.Rig.from_angles([4.5, -5.4, -3.4, 3.8], TABLE_I[1])
    with pytest.raises(rs.RigError, match="increasing elevation"):
        rs.Rig.from_angles(TABLE_I[0], [8.4, 9.9, -8.8, -7.7])


def test_from_angles_needs_four():
    with pytest.raises(rs.RigError, match="exactly 4"):
        rs.Rig.from_angles([1, 2, 3], [1, 2, 3])


def test_unknown_preset_lists_names():
    with pytest.raises(rs.RigError, match="kit-table1"):
        rs.Rig.preset("nope")


BAD_RIGS = [
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\ncolour: red\n",
     4, "colour", "unknown key 'colour'"),
    ("rts_rig: 2\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\n",
     1, "rts_rig", "allowed values: 1"),
    ("rts_rig: 1\nname: x\nlayout:\n  az_deg: [-5, 95]\n  el_deg: [-5, 5]\n",
     4, "layout.az_deg[1]", "must be <= 90"),
    ("rts_rig: 1\nname: x\nlayout:\n  az_deg: [-5, 5]\n  el_deg: [-5, five]\n",
     5, "layout.el_deg[1]", "must be of type number"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1}\n  - {az_deg: 2, el_deg: 1}\n"
     "  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n  - {az_deg: 3, el_deg: 2}\n",
     3, "front_ends", "rows x columns"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 5, el_deg: 1}\n  - {az_deg: 2, el_deg: 1}\n"
     "  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     5, "front_ends[1].az_deg", "increasing azimuth"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  echoes_per_channel: 0\n", 5, "limits.echoes_per_channel", "must be >= 1"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\ndistance_m: 0\n",
     4, "distance_m", "must be > 0"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1}\n  - {az_deg: 1, el_deg: 1}\n"
     "  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     5, "front_ends[1]", "FE 1 is in the same direction as FE 0 (az_deg 1, el_deg 1; every FE "
     "needs its own direction)"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1}\n  - {az_deg: 2, el_deg: 1}\n"
     "  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 0.5}\n",
     7, "front_ends[3].el_deg", "increasing elevation between rows (paper order: FE 0 and 1 "
     "lower than 2 and 3); column 1: row 0 at 1 deg, row 1 at 0.5 deg"),
    ("rts_rig: 1\nname: x\nrows: 2\ncolumns: 3\nfront_ends:\n  - {az_deg: -10, el_deg: -8}\n"
     "  - {az_deg: 0, el_deg: -8}\n  - {az_deg: 10, el_deg: 8}\n  - {az_deg: -9, el_deg: 0}\n"
     "  - {az_deg: 10, el_deg: 8}\n  - {az_deg: 11, el_deg: 9}\n",
     10, "front_ends[4]", "FE 4 is in the same direction as FE 2 (az_deg 10, el_deg 8"),
    ("rts_rig: 1\nname: x\nlayout:\n  az_deg: [-21, -21, 0, 10.5, 21]\n  el_deg: [-9, 0, 9]\n",
     4, "layout.az_deg[1]", "column 1 repeats the azimuth of column 0 (az_deg -21, el_deg -9;"),
    ("rts_rig: 1\nname: x\nlayout:\n  az_deg: [-5, 5]\n  el_deg: [-9, 0, 0]\n",
     5, "layout.el_deg[2]", "row 2 repeats the elevation of row 1 (az_deg -5, el_deg 0;"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  attenuation_min_db: 90\n  attenuation_max_db: 80\n", 5, "limits.attenuation_min_db",
     "must be below attenuation_max_db = 80, got 90"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  doppler_max_hz: 1000\n  doppler_min_hz: 2000\n", 6, "limits.doppler_min_hz",
     "must be below doppler_max_hz = 1000, got 2000"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  attenuation_max_db: 80\n  attenuation_step_db: 200\n", 6, "limits.attenuation_step_db",
     "must be within 0 (continuous) .. 80 (attenuation_max_db - attenuation_min_db), got 200"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  update_rate_hz: 0\n", 5, "limits.update_rate_hz", "must be > 0, got 0"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  phase_step_deg: 200\n", 5, "limits.phase_step_deg", "must be <= 180"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  phase_step_deg: -5.625\n", 5, "limits.phase_step_deg", "must be >= 0"),
    # A datasheet's rounded LSB: a 6-bit shifter's 5.625 deg typed as 5.6.
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  phase_step_deg: 5.6\n", 5, "limits.phase_step_deg",
     "must divide 360 deg into whole steps (360 / 2**n for an n-bit shifter), got 5.6 "
     "(64.29 steps per turn; the nearest that divides it: 5.625)"),
    # Survey and calibrate play each FE at the reference level: it must be one the RTS sets.
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  attenuation_max_db: 80\nreference:\n  attenuation_db: 1.0e+6\n", 7,
     "reference.attenuation_db", "must be within the RTS's attenuation limits 0..80 dB, got 1e+06"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  attenuation_min_db: 10\nreference: {range_m: 5, attenuation_db: -3}\n", 6,
     "reference.attenuation_db", "must be within the RTS's attenuation limits 10..120 dB, got -3"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  attenuation_max_db: 30\n", 5, "limits.attenuation_max_db",
     "the default reference.attenuation_db = 40 dB is outside the RTS's attenuation limits "
     "0..30 dB; give reference.attenuation_db"),
    ("rts_rig: 1\nname: x\n", None, "", "exactly one of 'front_ends'"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nrts:\n"
     "  delay_model: fibre\n", 5, "rts.delay_model", "allowed values: 'if', 'rf'"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1, rx_offset_m: [0.1]}\n"
     "  - {az_deg: 2, el_deg: 1}\n  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     4, "front_ends[0].rx_offset_m", "must have at least 2 items"),
    # Beyond any bench: typing mistakes that would survey or play nonsense without a word.
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\ndistance_m: 1.0e+9\n",
     4, "distance_m", "must be <= 100"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1}\n"
     "  - {az_deg: 2, el_deg: 1, calibration: {delay_s: -1}}\n  - {az_deg: 1, el_deg: 2}\n"
     "  - {az_deg: 2, el_deg: 2}\n", 5, "front_ends[1].calibration.delay_s", "must be >= -1e-06"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1, calibration: {gain_db: 500}}"
     "\n  - {az_deg: 2, el_deg: 1}\n  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     4, "front_ends[0].calibration.gain_db", "must be <= 60"),
    # A phase of 1e30 deg was taken and played as whatever cos(1e30) rounds to.
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1}\n  - {az_deg: 2, el_deg: 1}\n"
     "  - {az_deg: 1, el_deg: 2, calibration: {phase_deg: 1.0e+30}}\n  - {az_deg: 2, el_deg: 2}\n",
     6, "front_ends[2].calibration.phase_deg", "must be <= 360, got 1e+30"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1, calibration: {phase_deg: -400}}"
     "\n  - {az_deg: 2, el_deg: 1}\n  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     4, "front_ends[0].calibration.phase_deg", "must be >= -360, got -400"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1, seen: {level_db: 1.0e+300}}"
     "\n  - {az_deg: 2, el_deg: 1}\n  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     4, "front_ends[0].seen.level_db", "must be <= 200, got 1e+300"),
    ("rts_rig: 1\nname: x\nfront_ends:\n  - {az_deg: 1, el_deg: 1, rx_offset_m: [5, 0]}\n"
     "  - {az_deg: 2, el_deg: 1}\n  - {az_deg: 1, el_deg: 2}\n  - {az_deg: 2, el_deg: 2}\n",
     4, "front_ends[0].rx_offset_m[0]", "must be <= 1"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  latency_s: 1.0e+300\n", 5, "limits.latency_s", "must be <= 1.0, got 1e+300"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  echoes_per_channel: 100000\n", 5, "limits.echoes_per_channel", "must be <= 1024"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nlimits:\n"
     "  delay_min_s: 4.0e-9\n  delay_max_s: 3.0e-9\n", 6, "limits.delay_max_s",
     "must be above delay_min_s = 4e-09, got 3e-09"),
    # A reference RCS of 1e30 dBsm overflowed the schedule's level (numpy's "overflow
    # encountered in power" printed by validate and run).
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nreference:\n"
     "  rcs_dbsm: 1.0e+30\n", 5, "reference.rcs_dbsm", "must be <= 60, got 1e+30"),
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nreference:\n"
     "  range_m: 1.0e+30\n", 5, "reference.range_m", "must be <= 100000, got 1e+30"),
    # An integer beyond 64 bits reached numpy as a Python object: TypeError ("no callable
    # log10 method"), exit 3.
    ("rts_rig: 1\nname: x\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\nreference:\n"
     "  range_m: 1000000000000000000000000000000\n", 5, "reference.range_m",
     "an integer beyond 64 bits"),
    ("rts_rig: 1\nname: x\nname: y\n", 3, "name", "duplicate key"),
    # An unclosed bracket found at the end of the file is placed where it opens.
    ("rts_rig: 1\nname: [x\n", 2, "", "invalid YAML"),
    ("rts_rig: 1\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\n", 1, "", "'name' is required"),
    ("# nothing but a comment\n", None, "", "the file is empty: expected a mapping of keys"),
]


@pytest.mark.parametrize("text, line, key, message", BAD_RIGS)
def test_bad_rig_files_name_file_line_and_key(tmp_path, text, line, key, message):
    path = tmp_path / "bad.rig.yaml"
    path.write_text(text)
    with pytest.raises(rs.ScenarioError) as info:
        rs.Rig.from_file(path)
    err = info.value
    assert err.file == str(path)
    assert message in str(err)
    if line is not None:
        assert err.line == line, str(err)
        assert f"{path}:{line}:" in str(err)
    if key:
        assert err.key_path == key
        assert f": {key}: " in str(err)


def test_missing_rig_file(tmp_path):
    with pytest.raises(rs.ScenarioError, match="cannot read file"):
        rs.Rig.from_file(tmp_path / "missing.rig.yaml")


def test_yaml_tags_are_not_executed(tmp_path):
    path = tmp_path / "evil.rig.yaml"
    path.write_text("rts_rig: 1\nname: !!python/object/apply:os.system ['true']\n")
    with pytest.raises(rs.ScenarioError, match="invalid YAML"):
        rs.Rig.from_file(path)


def test_write_keeps_offsets_delay_model_calibration_and_survey(tmp_path):
    import dataclasses

    from rts_scenario.rig import RtsDelayModel

    rig = rs.Rig.preset("kit-table1")
    rig = dataclasses.replace(
        rig, rx_offset_m=np.array([[0.01, 0.0], [0.0, 0.0], [0.0, -0.02], [0.0, 0.0]]),
        tx_offset_m=np.array([0.0, 0.015]), rts=RtsDelayModel("rf"),
        cal_phase_deg=np.array([0.0, 12.5, -40.0, 3.0]),
        seen=np.array([[1.0, 2.0, 0.5], [np.nan] * 3, [3.0, 4.0, -0.5], [5.0, 6.0, 0.0]]))
    rig.write(tmp_path / "r.rig.yaml")
    back = rs.Rig.from_file(tmp_path / "r.rig.yaml")
    for name in ("az_deg", "el_deg", "distance_m", "cal_phase_deg", "rx_offset_m", "tx_offset_m",
                 "seen"):
        np.testing.assert_allclose(getattr(back, name), getattr(rig, name), err_msg=name)
    assert back.rts == rig.rts and back.limits == rig.limits


def test_a_rig_file_is_written_as_before(tmp_path):
    import yaml

    rig = rs.Rig.preset("kit-table1")
    path = tmp_path / "r.rig.yaml"
    rig.write(path)
    assert path.read_text() == yaml.safe_dump(rig.to_document(), sort_keys=False, width=100)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rig.yaml"]


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), OSError(28, "No space left on device")],
                         ids=["interrupt", "full-disk"])
def test_a_rig_file_written_part_way_leaves_the_previous_one(tmp_path, cut_short_drafts, exc):
    # `survey --write` and `calibrate --write` over the rig a bench runs on: stopped part way,
    # the bench kept half a rig file, which no command reads.
    path = tmp_path / "r.rig.yaml"
    rs.Rig.preset("wide-3x5").write(path)
    before = path.read_bytes()
    cut_short_drafts(exc)
    with pytest.raises(type(exc)):
        rs.Rig.preset("kit-table1").write(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rig.yaml"]


def test_a_written_rig_keeps_its_description(tmp_path):
    # calibrate --write and survey --write dropped the lab's description of the rig.
    rig = rs.Rig.from_file(Path(__file__).resolve().parents[1] / "scenarios" / "rigs"
                           / "lab-2x3.rig.yaml")
    assert rig.description
    rig.write(tmp_path / "again.rig.yaml")
    assert rs.Rig.from_file(tmp_path / "again.rig.yaml").description == rig.description
    import dataclasses

    assert "description" not in dataclasses.replace(rig, description="").to_document()
