"""What a recorded run keeps of what it played: ground-truth checksums and statuses."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rts_scenario.kinematics import compute_tracks
from rts_scenario.recording import TRUTH_STEP_EDGE, StatusRecord, StatusRecorder, TruthChecksums
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule.model import Status

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenarios" / "highway_following.scenario.yaml"


@pytest.fixture(scope="module")
def tracks():
    scene = load_scenario(SCENE)
    return compute_tracks(scene, scene.t_s, np.arange(scene.n_frames))


def checksums(tracks, splits):
    sums = TruthChecksums(tracks.names)
    for rows in np.array_split(np.arange(tracks.t_s.size), splits):
        sums.add(tracks.take(rows), rows)
    return sums.to_dict()["targets"]


def test_the_truth_checksums_do_not_depend_on_the_batches(tracks):
    assert checksums(tracks, 1) == checksums(tracks, 7) == checksums(tracks, 400)
    assert set(checksums(tracks, 1)) == {"lead-car", "truck-left"}


@pytest.mark.parametrize("field, k, step", [
    ("range_m", 0, 1e-3), ("rcs_dbsm", 1, 0.01), ("az_deg", 1, 1e-3), ("el_deg", 0, 1e-3),
    ("radial_velocity_mps", 0, 1e-3)])
def test_one_value_a_quantum_off_changes_that_target_s_checksum_only(tracks, field, k, step):
    base = checksums(tracks, 3)
    values = getattr(tracks, field).copy()
    values[123, k] += step
    changed = checksums(replace(tracks, **{field: values}), 3)
    assert changed[tracks.names[k]] != base[tracks.names[k]]
    assert changed[tracks.names[1 - k]] == base[tracks.names[1 - k]]
    # A hundredth of a quantum towards the middle of the value's step is rounding, not an
    # edit (the steps' edges lie TRUTH_STEP_EDGE quanta past the quantum's multiples).
    values = getattr(tracks, field).copy()
    middle = values[123, k] / step - TRUTH_STEP_EDGE - 0.5
    off = middle - np.rint(middle)
    values[123, k] -= np.copysign(step / 100, off)
    assert checksums(replace(tracks, **{field: values}), 3) == base


def test_the_values_of_an_absent_target_do_not_count_its_presence_does(tracks):
    base = checksums(tracks, 2)
    present = tracks.present.copy()
    present[:50, 0] = False
    gone = replace(tracks, present=present)
    ranges = tracks.range_m.copy()
    ranges[:50, 0] = np.nan  # what an absent target-frame holds does not matter
    assert checksums(gone, 2) == checksums(replace(gone, range_m=ranges), 2)
    assert checksums(gone, 2)["lead-car"] != base["lead-car"]
    # A target-frame swapped with another frame's is another truth.
    swapped = tracks.range_m.copy()
    swapped[[10, 11], 0] = swapped[[11, 10], 0]
    assert checksums(replace(tracks, range_m=swapped), 2)["lead-car"] != base["lead-car"]


def test_a_record_names_the_targets_that_differ(tracks):
    sums = TruthChecksums(tracks.names)
    sums.add(tracks, np.arange(tracks.t_s.size))
    record = sums.to_dict()
    assert sums.differing(record) == []
    other = {**record, "targets": {**record["targets"], "truck-left": "0" * 16, "bus": "1" * 16}}
    assert sums.differing(other) == ["truck-left", "bus"]
    assert sums.differing({**record, "quanta": {"range_m": 0.01}}) is None


def statuses(n_frames=250, n_targets=3, seed=0):
    rng = np.random.default_rng(seed)
    out = np.zeros((n_frames, n_targets), dtype=np.uint16)
    out[rng.random(out.shape) < 0.1] = Status.OUT_OF_COVERAGE
    out[40:60, 1] = Status.NOT_PRESENT | Status.SPLIT
    return out


@pytest.mark.parametrize("write, read", [(1, 1), (7, 3), (250, 11)])
def test_the_statuses_read_back_as_played_in_any_batches(write, read):
    played = statuses()
    recorder = StatusRecorder(3)
    for part in np.array_split(played, write):
        recorder.add(part)
    record = StatusRecord(recorder.to_dict(), 250, 3)
    back = [record.take(part.shape[0]) for part in np.array_split(played, read)]
    record.finish()
    np.testing.assert_array_equal(np.concatenate(back), played)


def test_statuses_of_another_scene_or_damaged_are_refused():
    recorder = StatusRecorder(3)
    recorder.add(statuses())
    data = recorder.to_dict()
    with pytest.raises(ValueError, match="holds 250 frames of 3 targets, the scene has 251 of 3"):
        StatusRecord(data, 251, 3)
    with pytest.raises(ValueError, match="encoding: must be"):
        StatusRecord({**data, "encoding": "raw"}, 250, 3)
    short = StatusRecorder(3)
    short.add(statuses()[:200])
    record = StatusRecord({**short.to_dict(), "frames": 250}, 250, 3)
    record.take(150)
    with pytest.raises(ValueError, match="data: ends 300 bytes early"):
        record.take(100)
    record = StatusRecord(data, 250, 3)
    record.take(249)
    with pytest.raises(ValueError, match="holds more frames than it says"):
        record.finish()
    bad = StatusRecorder(3)
    bad.add(np.full((250, 3), 0x400, dtype=np.uint16))
    with pytest.raises(ValueError, match="values that are no status"):
        StatusRecord(bad.to_dict(), 250, 3).take(10)


@pytest.mark.parametrize("scene", ["euro-ncap/ccrs", "euro-ncap/ccrm", "hard_too_close"])
def test_a_truth_one_rounding_off_has_the_same_checksum(scene):
    # Scenes of round numbers put values exactly on the middle of a millimetre: CCRs's GVT is
    # 10.4175 m away in frame 5, 9.0285 m in frame 15, 7.6395 m in frame 25. One ulp of another
    # machine's or version's arithmetic must not tell another scene.
    loaded = load_scenario(ROOT / "scenarios" / f"{scene}.scenario.yaml")
    truth = compute_tracks(loaded, loaded.t_s, np.arange(loaded.n_frames))
    base = checksums(truth, 1)
    for direction in (np.inf, -np.inf):
        moved = {name: np.nextafter(getattr(truth, name), direction)
                 for name in ("range_m", "radial_velocity_mps", "rcs_dbsm", "az_deg", "el_deg")}
        assert checksums(replace(truth, **moved), 1) == base, direction


def test_a_status_record_cut_short_or_with_bytes_after_it_is_told_so():
    import base64

    recorder = StatusRecorder(3)
    recorder.add(statuses())
    data = recorder.to_dict()
    packed = base64.b64decode(data["data"])
    for cut in (1, 4):
        record = StatusRecord({**data, "data": base64.b64encode(packed[:-cut]).decode()}, 250, 3)
        record.take(250)
        with pytest.raises(ValueError, match="data: ends early: the compressed record is cut"):
            record.finish()
    record = StatusRecord({**data, "data": base64.b64encode(packed + b"xyz").decode()}, 250, 3)
    record.take(250)
    with pytest.raises(ValueError, match="data: holds 3 bytes after the record's end"):
        record.finish()


def test_statuses_are_read_back_by_target_name_in_the_scene_s_order():
    played = statuses()
    recorder = StatusRecorder(3, ["car", "truck", "bike"])
    recorder.add(played)
    data = recorder.to_dict()
    assert data["names"] == ["car", "truck", "bike"]
    back = StatusRecord(data, 250, 3, ["bike", "car", "truck"]).take(250)
    np.testing.assert_array_equal(back, played[:, [2, 0, 1]])
    # Another set of names (a renamed target, which the truth's checksums fail): in order.
    np.testing.assert_array_equal(StatusRecord(data, 250, 3, ["van", "car", "truck"]).take(250),
                                  played)
    with pytest.raises(ValueError, match=r"names: must list the 3 targets' distinct names, got "
                                         r"\['car', 'car', 'bike'\]"):
        StatusRecord({**data, "names": ["car", "car", "bike"]}, 250, 3)
