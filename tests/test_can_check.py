import dataclasses
import json
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rts_scenario import CheckError
from rts_scenario.canbus import DetectionPublisher, DetectionReceiver, open_bus
from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.check import check_cycles as check
from rts_scenario.detections import Detections, sequential_numbers
from rts_scenario.kinematics import compute_tracks
from rts_scenario.radar.simulate import SimulatedRadar
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule

ROOT = Path(__file__).resolve().parents[1]


pytestmark = pytest.mark.usefixtures("no_bus_left_open")


@pytest.fixture(scope="module")
def cut_in():
    scene = load_scenario(ROOT / "scenarios" / "cut_in.scenario.yaml")
    tracks = compute_tracks(scene)
    schedule = build_schedule(tracks, scene.rig, scene.radar)
    frames = SimulatedRadar(scene.radar, scene.rig, rng=np.random.default_rng(0)).process(schedule)
    return scene, tracks, schedule, frames


class FaultyBus:
    """Forward sends to a bus, dropping, duplicating, reordering or corrupting some."""

    def __init__(self, bus, rng, fault=None, p=0.0):
        self.bus, self.rng, self.fault, self.p = bus, rng, fault, p
        self.held = None
        self.count = 0

    def send(self, msg):
        hit = self.fault is not None and self.rng.random() < self.p
        if hit:
            self.count += 1
            if self.fault == "drop":
                return
            if self.fault == "corrupt":
                data = bytearray(msg.data)
                data[int(self.rng.integers(len(data)))] ^= 0x10
                msg = can.Message(arbitration_id=msg.arbitration_id, data=bytes(data),
                                  is_extended_id=False)
            if self.fault == "reorder" and self.held is None:
                self.held = msg
                return
            if self.fault == "wrong_id":
                msg = can.Message(arbitration_id=0x7E0, data=msg.data, is_extended_id=False)
        self.bus.send(msg)
        if hit and self.fault == "duplicate":
            self.bus.send(msg)
        if self.held is not None and not (hit and self.fault == "reorder"):
            self.bus.send(self.held)
            self.held = None


def run_over_bus(frames, fault=None, p=0.0, fd=False, mapping=None, send=None):
    with open_bus(channel="test-check", fd=fd) as listen, open_bus(channel="test-check",
                                                                    fd=fd) as talk:
        receiver = DetectionReceiver(mapping)
        faulty = FaultyBus(talk, np.random.default_rng(7), fault, p)
        if send is None:
            publisher = DetectionPublisher(faulty, fd=fd)
            for frame in frames:
                publisher.publish(frame)
        else:
            send(faulty)
        while (msg := listen.recv(timeout=0.05)) is not None:
            receiver.on_message_received(msg)
    return receiver, faulty


def test_clean_run_passes_with_every_frame_checked(cut_in):
    scene, tracks, schedule, frames = cut_in
    receiver, _ = run_over_bus(frames)
    assert receiver.stats.clean
    report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["total"] == scene.n_frames
    data = json.loads(report.to_json())
    for key in ("passed", "frames", "targets", "errors", "detection_rate", "timing"):
        assert key in data
    assert data["errors"]["range_m"]["rms"] < 0.05
    assert "PASS" in report.table()


@pytest.mark.parametrize("fd", [False, True])
def test_round_trip_of_every_signal_at_its_limits(fd):
    limits = [
        dict(range_m=0.0, v=-163.84, az=-163.84, el=-163.84, rcs=-64.0, snr=0.0),
        dict(range_m=327.675, v=163.835, az=163.835, el=163.835, rcs=63.5, snr=127.5),
        dict(range_m=12.345, v=-2.005, az=-0.005, el=0.005, rcs=7.5, snr=33.5),
    ]
    frames = [Detections(cycle=i, t_s=0.05 * i,
                         range_m=np.array([x["range_m"]]),
                         radial_velocity_mps=np.array([x["v"]]), az_deg=np.array([x["az"]]),
                         el_deg=np.array([x["el"]]), snr_db=np.array([x["snr"]]),
                         rcs_dbsm=np.array([x["rcs"]])) for i, x in enumerate(limits)]
    receiver, _ = run_over_bus(frames, fd=fd)
    assert receiver.stats.clean
    cycles = receiver.flush()
    assert [c.cycle for c in cycles] == list(range(len(limits)))
    for i, x in enumerate(limits):
        got = vars(cycles[i])
        assert cycles[i].complete and cycles[i].t_s == pytest.approx(0.05 * i, abs=1e-4)
        # Exact at the 0.005 m / 0.005 deg resolution: the 0.01 checks are not blurred.
        assert got["range_m"][0] == pytest.approx(x["range_m"], abs=1e-9)
        assert got["radial_velocity_mps"][0] == pytest.approx(x["v"], abs=1e-9)
        assert got["az_deg"][0] == pytest.approx(x["az"], abs=1e-9)
        assert got["el_deg"][0] == pytest.approx(x["el"], abs=1e-9)
        assert got["rcs_dbsm"][0] == pytest.approx(x["rcs"], abs=1e-9)
        assert got["snr_db"][0] == pytest.approx(x["snr"], abs=1e-9)


def one_cycle(cycle, range_m, **values):
    """A cycle whose detections are at ``range_m``, every other quantity 0 unless given."""
    range_m = np.asarray(range_m, dtype=float)
    columns = {q: np.asarray(values.get(q, np.zeros(range_m.size)), dtype=float)
               for q in ("radial_velocity_mps", "az_deg", "el_deg", "snr_db", "rcs_dbsm")}
    return Detections(cycle=cycle, t_s=0.05 * cycle, range_m=range_m, **columns)


@pytest.mark.parametrize("fd", [False, True])
def test_out_of_range_values_are_counted_and_not_sent(fd):
    # A negative range (sub-bin interpolation next to 0), one beyond the DBC's 327.675 m, an
    # unknown velocity: no signal carries them. The others of the cycle and the next cycle
    # arrive, complete; the publisher counts what it left out and says why.
    frames = [one_cycle(0, [12.0, -0.146, 400.0, 20.0, 30.0],
                        radial_velocity_mps=[1.0, 0.0, 0.0, np.nan, -2.0]),
              one_cycle(1, [40.0])]
    publishers = []

    def send(bus):
        publishers.append(DetectionPublisher(bus, fd=fd))
        for frame in frames:
            publishers[0].publish(frame)

    receiver, _ = run_over_bus(None, fd=fd, send=send)
    publisher = publishers[0]
    assert publisher.unsendable == {"Range": 2, "RadialVelocity": 1}
    assert publisher.unsendable_detections == 3
    assert publisher.unsendable_reason == (
        "2 with Range outside [0, 327.675] m (the first: -0.146, cycle 0 detection 1); "
        "1 with RadialVelocity outside [-163.84, 163.835] m/s (the first: nan, cycle 0 "
        "detection 3)")
    assert receiver.stats.clean
    cycles = receiver.flush()
    assert [c.cycle for c in cycles] == [0, 1] and all(c.complete for c in cycles)
    np.testing.assert_allclose(cycles[0].range_m, [12.0, 30.0])
    np.testing.assert_allclose(cycles[0].radial_velocity_mps, [1.0, -2.0])
    np.testing.assert_allclose(cycles[1].range_m, [40.0])


@pytest.mark.parametrize("fd", [False, True])
def test_more_than_255_detections_in_a_cycle(fd):
    # 300 detections: CAN FD numbers them all; classic CAN's 8-bit index the first 256 (its
    # two messages per detection would not fit 300 per radar cycle on the bus anyway).
    n = 300
    frame = one_cycle(7, 1.0 + 0.25 * np.arange(n), az_deg=np.linspace(-60, 60, n))
    publishers = []

    def send(bus):
        publishers.append(DetectionPublisher(bus, fd=fd))
        publishers[0].publish(frame)
        publishers[0].publish(one_cycle(8, [5.0]))

    receiver, _ = run_over_bus(None, fd=fd, send=send)
    assert receiver.stats.clean
    cycles = receiver.flush()
    assert [c.cycle for c in cycles] == [7, 8] and all(c.complete for c in cycles)
    kept = n if fd else 256
    assert cycles[0].count == kept
    np.testing.assert_allclose(cycles[0].range_m, frame.range_m[:kept], atol=0.0025)
    np.testing.assert_allclose(cycles[0].az_deg, frame.az_deg[:kept], atol=0.0025)
    assert publishers[0].unsendable == ({} if fd else {"Index": n - 256})
    # The header counts up to 1023 detections: more are counted, not sent, in CAN FD too.
    with open_bus(channel="test-many") as bus:
        publisher = DetectionPublisher(bus, fd=True)
        publisher.publish(one_cycle(0, np.full(1100, 10.0)))
        assert publisher.unsendable == {"DetectionCount": 1100 - 1023}
        assert publisher.sent == 1 + 1023


@pytest.mark.parametrize("fault, counter, fails", [
    ("drop", None, True),
    ("corrupt", "checksum_errors", True),
    ("duplicate", "duplicates", False),
    ("reorder", "reordered", False),
    ("wrong_id", "unknown_ids", True),
])
def test_faults_are_detected_and_missing_data_never_passes(cut_in, fault, counter, fails):
    scene, tracks, schedule, frames = cut_in
    receiver, faulty = run_over_bus(frames, fault, p=0.01)
    assert faulty.count > 0
    report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
    if counter is not None:
        assert getattr(receiver.stats, counter) > 0
        assert report.bus[counter] > 0
    if fails:
        assert not report.passed
        assert report.frames["incomplete"] + report.frames["missing"] > 0
        assert any("could not be checked" in r for r in report.reasons)
    else:
        # Nothing was lost: every frame is still complete and checked.
        assert report.frames["checked"] == scene.n_frames
    assert report.table()  # the report renders whatever happened


def test_silent_bus_fails(cut_in):
    scene, tracks, schedule, _ = cut_in
    receiver, _ = run_over_bus([])
    report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
    assert not report.passed
    assert any("silent" in r for r in report.reasons)
    assert report.frames["missing"] == scene.n_frames


def test_bus_error_frames_are_reported(cut_in):
    scene, tracks, schedule, frames = cut_in
    receiver = DetectionReceiver()
    receiver.on_message_received(can.Message(is_error_frame=True))
    assert receiver.stats.error_frames == 1 and not receiver.stats.clean


def test_bad_interface_names_the_valid_ones():
    with pytest.raises(CheckError, match="valid interfaces: .*virtual"):
        open_bus("carrier-pigeon", "0")


def test_third_party_cluster_list_with_mapping(cut_in):
    scene, tracks, schedule, frames = cut_in
    mapping = CanMapping.from_file(ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml")
    assert mapping.quantities == {"range_m", "azimuth_deg", "radial_velocity_mps", "rcs_dbsm"}
    db = cantools.database.load_file(ROOT / "scenarios" / "can" / "cluster_list.dbc")
    status, general = db.get_message_by_name("Cluster_Status"), db.get_message_by_name(
        "Cluster_General")

    def send(bus):
        # The third-party radar reports each detection as distance and relative velocity.
        for frame in frames:
            bus.send(can.Message(arbitration_id=status.frame_id, is_extended_id=False,
                                 data=status.encode({"NofClustersNear": frame.count,
                                                     "NofClustersFar": 0,
                                                     "MeasCounter": frame.cycle,
                                                     "InterfaceVersion": 1})))
            az, rng = np.radians(frame.az_deg), frame.range_m
            x, y = rng * np.cos(az), rng * np.sin(az)
            vx, vy = frame.radial_velocity_mps * np.cos(az), frame.radial_velocity_mps * np.sin(az)
            for i in range(frame.count):
                values = {"ClusterId": i, "DistLong": x[i], "DistLat": y[i], "VrelLong": vx[i],
                          "VrelLat": vy[i], "DynProp": 0, "RCS": frame.rcs_dbsm[i]}
                bus.send(can.Message(arbitration_id=general.frame_id, is_extended_id=False,
                                     data=general.encode(values, strict=False)))

    receiver, _ = run_over_bus(None, mapping=mapping, send=send)
    assert receiver.stats.clean
    report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
    # Elevation is not in the cluster list: it is not checked. 0.2 m steps keep the rest.
    assert report.targets[0].errors["el_deg"].count == 0
    assert report.errors["range_m"].max < 0.2
    assert report.passed, report.reasons


def test_mapping_errors_are_located(tmp_path):
    from rts_scenario import ScenarioError
    (tmp_path / "x.dbc").write_text((ROOT / "scenarios" / "can" / "cluster_list.dbc").read_text())
    text = (ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml").read_text()
    bad = tmp_path / "bad.mapping.yaml"
    bad.write_text(text.replace("cluster_list.dbc", "x.dbc").replace("DistLat", "DistSide"))
    with pytest.raises(ScenarioError, match="signal 'DistSide' is not in the detection"):
        CanMapping.from_file(bad)


def test_cycles_beyond_the_counters_wrap_keep_their_own_values():
    # A radar counting from 65,000 on: its 16-bit header counter wraps after 536 cycles, the
    # detections' 8-bit one every 256. The receiver remembers at most RECENT_CYCLES counters,
    # so 536 cycles before the wrap and 864 after cover all it can confuse (publishing all
    # 70,000 cycles from 0 passes the same way but takes ~30 s). Each cycle comes back once,
    # whole, with its own values and counter.
    cycles = np.arange(65_000, 66_400)
    got = []
    with open_bus(channel="test-wrap") as listen, open_bus(channel="test-wrap") as talk:
        receiver = DetectionReceiver()
        publisher = DetectionPublisher(talk)
        for start in range(0, cycles.size, 100):
            for i in cycles[start : start + 100]:
                publisher.publish(one_cycle(int(i), [0.005 * (i % 60_000)],
                                            az_deg=[0.005 * (i % 30_000) - 75.0]))
            while (msg := listen.recv(timeout=0)) is not None:
                receiver.on_message_received(msg)
            got.extend(receiver.pop())
        got.extend(receiver.flush())
    assert receiver.stats.clean and publisher.sent == 3 * cycles.size
    assert [c.cycle for c in got] == list(cycles % 65536)
    assert all(c.complete and c.count == 1 for c in got)
    np.testing.assert_allclose([c.range_m[0] for c in got], 0.005 * (cycles % 60_000),
                               atol=1e-9)
    np.testing.assert_allclose([c.az_deg[0] for c in got], 0.005 * (cycles % 30_000) - 75.0,
                               atol=1e-9)


class Recorder(list):
    """A ``send`` target that keeps the messages."""

    send = list.append


def _messages(frame):
    recorder = Recorder()
    DetectionPublisher(recorder).publish(frame)
    return list(recorder)


def _receive(messages):
    receiver = DetectionReceiver()
    for msg in messages:
        receiver.on_message_received(msg)
    return receiver


BUILTIN = CanMapping.builtin()


@settings(max_examples=60, deadline=None)
@given(modulus=st.integers(2, 300), latest=st.integers(0, 299))
def test_the_receiver_and_the_cycle_numbering_agree_on_behind_for_every_step(modulus, latest):
    # A counter of `modulus` values: the step from the latest counter to another is the one
    # of the counter's differences with -modulus < 2 * step <= modulus (for 15 values -7..7,
    # for 16 -7..8). The cycle numbering takes that step, and the receiver takes a header
    # with a negative one for a reordered cycle, a positive one for a new cycle.
    latest %= modulus
    mapping = dataclasses.replace(BUILTIN, counter_max=modulus - 1)
    receiver = DetectionReceiver(mapping)
    publisher = DetectionPublisher(recorder := Recorder(), mapping=mapping)
    for other in range(modulus):
        if other == latest:
            continue
        (step,) = [s for s in range(-modulus + 1, modulus)
                   if (s - (other - latest)) % modulus == 0 and -modulus < 2 * s <= modulus]
        assert sequential_numbers(np.array([latest, other]), modulus)[1] == step
        receiver.reset()
        before = receiver.stats.reordered
        recorder.clear()
        publisher.publish_many([Detections.empty(latest, None), Detections.empty(other, None)])
        for msg in recorder:
            receiver.on_message_received(msg)
        assert [c.cycle for c in receiver.flush()] == [latest, other]
        assert receiver.stats.reordered - before == (step < 0), (modulus, latest, other)


@pytest.mark.parametrize("modulus", [2, 3])
def test_an_incomplete_cycle_of_a_counter_of_two_or_three_values_goes_on_at_the_next_header(
        modulus):
    # Cycle 0's detection is lost; then the counter runs on three laps, every cycle whole. A
    # counter of two values steps back by none, one of three by one: once the next header
    # came, 0 is no longer behind the latest (or as far back as the receiver waits) and goes on
    # incomplete, and each later header is a new cycle, never a copy of it or a conflict.
    # (A mapping file with such a counter is refused; a mapping built in code is not.)
    mapping = dataclasses.replace(BUILTIN, counter_max=modulus - 1)
    recorder = Recorder()
    publisher = DetectionPublisher(recorder, mapping=mapping)
    publisher.publish(one_cycle(0, [10.0]))
    del recorder[1:]  # its detection is lost
    publisher.publish_many([Detections.empty(a % modulus, None)
                            for a in range(1, 3 * modulus + 1)])
    receiver = DetectionReceiver(mapping)
    for msg in recorder:
        receiver.on_message_received(msg)
    assert [(c.cycle, c.complete) for c in receiver.flush()] == [
        (1, True), (0, False), *((a % modulus, True) for a in range(2, 3 * modulus + 1))]
    assert (receiver.stats.duplicates, receiver.stats.conflicts) == (0, 0)


def test_a_copy_of_a_whole_cycle_is_a_duplicate_not_a_conflict():
    frame = one_cycle(3, [10.0, 20.0], az_deg=[1.0, -2.0])
    messages = _messages(frame)
    receiver = _receive(messages + messages[1:] + messages[:1])  # detections again, header again
    assert (receiver.stats.duplicates, receiver.stats.conflicts) == (len(messages), 0)
    (cycle,) = receiver.flush()
    assert cycle.complete and cycle.count == 2


def test_a_detection_beyond_the_announced_count_after_the_cycle_is_a_conflict(cut_in):
    # The radar's cycle holds one more detection than its header announced: the receiver has
    # handed the cycle on once the announced ones came, but the extra one must not vanish as
    # a "duplicate" (the cycle checked would not be the one the radar sent).
    scene, tracks, schedule, frames = cut_in
    header_id = CanMapping.builtin().db.get_message_by_name(CanMapping.builtin().header).frame_id
    messages = []
    for frame in frames:
        ghost = one_cycle(frame.cycle, np.append(frame.range_m, 10.0),
                          az_deg=np.append(frame.az_deg, -20.0))
        messages += _messages(frame)
        messages += [m for m in _messages(ghost) if m.arbitration_id != header_id][-1:]
    receiver = _receive(messages)
    assert receiver.stats.conflicts == len(frames)
    assert receiver.stats.duplicates == 0
    report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
    assert not report.passed
    assert any(f"{len(frames)} conflicting messages" in r for r in report.reasons)
    assert "conflicts" in report.table()


def test_a_second_cycle_with_the_same_counter_is_a_conflict():
    first = one_cycle(5, [10.0, 20.0])
    # Another header (count 1) and another detection 0: its range message differs, its
    # angle message (azimuth, elevation, RCS 0 in both) is a copy.
    second = one_cycle(5, [33.0])
    receiver = _receive(_messages(first) + _messages(second))
    assert (receiver.stats.duplicates, receiver.stats.conflicts) == (1, 2)
    (cycle,) = receiver.flush()
    np.testing.assert_allclose(cycle.range_m, [10.0, 20.0])  # the first stays; the run fails



def test_a_header_after_its_detections_is_its_cycle_after_hundreds_of_cycles():
    # Detections carry 8 bits of the counter: a detection whose header is late must wait for
    # it, not be taken for a copy of the cycle 256 before (which had the same low bits).
    header_id = CanMapping.builtin().db.get_message_by_name(CanMapping.builtin().header).frame_id
    messages = []
    for i in range(400):
        cycle = _messages(one_cycle(i, [10.0 + 0.01 * i], az_deg=[1.0]))
        if i == 300:
            cycle = ([m for m in cycle if m.arbitration_id != header_id]
                     + [m for m in cycle if m.arbitration_id == header_id])
        messages += cycle
    receiver = DetectionReceiver()
    got = []
    for msg in messages:
        receiver.on_message_received(msg)
        got += receiver.pop()
    got += receiver.flush()
    late = next(c for c in got if c.cycle == 300)
    assert late.complete and late.range_m[0] == pytest.approx(13.0, abs=0.003)
    assert (receiver.stats.duplicates, receiver.stats.conflicts, receiver.stats.orphans) == \
        (0, 0, 0)


def test_a_lost_header_without_a_frame_counter_is_reported_as_such_not_as_a_conflict(cut_in):
    # The cluster list's detections carry no frame counter: with a cycle's header lost, its
    # detections follow the cycle before, already whole. They are detections without their
    # header (the cycle is missing), not messages of that cycle come again with other values.
    scene, tracks, schedule, _ = cut_in
    mapping = CanMapping.from_file(ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml")
    header_id = mapping.db.get_message_by_name(mapping.header).frame_id
    frames = [one_cycle(k, [20.0 + k, 40.0 - k], az_deg=[1.0, -3.0]) for k in range(6)]
    recorder = Recorder()
    publisher = DetectionPublisher(recorder, mapping=mapping)
    lost = 3
    for frame in frames:
        before = len(recorder)
        publisher.publish(frame)
        if frame.cycle == lost:
            assert recorder[before].arbitration_id == header_id
            del recorder[before]
    receiver = DetectionReceiver(mapping)
    for msg in recorder:
        receiver.on_message_received(msg)
    got = receiver.flush()
    assert [c.cycle for c in got] == [0, 1, 2, 4, 5] and all(c.complete for c in got)
    assert (receiver.stats.conflicts, receiver.stats.duplicates, receiver.stats.orphans) == \
        (0, 0, 2)
    report = check(scene.name, tracks, schedule.status, got, scene.expectations,
                   bus=vars(receiver.stats))
    assert "2 detections without a frame header" in report.reasons
    assert not any("conflicting" in r for r in report.reasons), report.reasons


def test_without_a_frame_counter_a_detection_beyond_the_count_is_still_a_conflict():
    # The same detections after a whole cycle, and the next header the very next counter:
    # no header was lost, the cycle held more than announced.
    mapping = CanMapping.from_file(ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml")
    recorder = Recorder()
    publisher = DetectionPublisher(recorder, mapping=mapping)
    publisher.publish(one_cycle(0, [20.0]))
    extra = Recorder()
    DetectionPublisher(extra, mapping=mapping).publish(one_cycle(0, [20.0, 33.0]))
    recorder.append(extra[-1])  # detection 1, beyond the count of 1
    publisher.publish(one_cycle(1, [21.0]))
    receiver = DetectionReceiver(mapping)
    for msg in recorder:
        receiver.on_message_received(msg)
    assert [c.cycle for c in receiver.flush()] == [0, 1]
    assert (receiver.stats.conflicts, receiver.stats.orphans) == (1, 0)


def test_the_stream_s_second_cycle_is_kept_where_the_stream_before_s_tail_comes_with_its_first():
    # The stream before's last cycles (238, 239, or 7) reach the bus after the reset, and this
    # stream's first cycle (counter 0) is held up behind its second (1, or 1 and 2), or comes
    # among the stale ones. The cycles counting on from the restart without a gap are the
    # stream's own; only the stream before's are dropped, and only the held-up header of
    # cycle 0 counts as reordered.
    receiver = DetectionReceiver()
    cycles = {k: one_cycle(k, [10.0 + k]) for k in range(6)}
    stale = {k: one_cycle(k, [3.0]) for k in (7, 238, 239)}
    for order, dropped in (([238, 239, 1, 0, 2, 3, 4, 5], 2),
                           ([238, 1, 239, 0, 2, 3, 4, 5], 2),
                           ([7, 1, 0, 2, 3, 4, 5], 1),
                           ([239, 1, 2, 0, 3, 4, 5], 1)):
        receiver.reset(restart=0)
        reordered = receiver.stats.reordered
        for k in order:
            for msg in _messages({**cycles, **stale}[k]):
                receiver.on_message_received(msg)
        got = receiver.flush()
        assert sorted(c.cycle for c in got) == list(range(6)), order
        assert all(c.complete for c in got)
        np.testing.assert_allclose([c.range_m[0] for c in sorted(got, key=lambda c: c.cycle)],
                                   10.0 + np.arange(6))
        assert receiver.stale_cycles == dropped, order
        assert receiver.stats.reordered - reordered == 1, order
        assert (receiver.stats.duplicates, receiver.stats.conflicts,
                receiver.stats.orphans) == (0, 0, 0)


def test_a_stream_s_first_cycle_held_up_behind_its_second_is_not_dropped_at_the_restart():
    # A radar counting afresh from 0 with each stream: its first cycle's header reaches the bus
    # after its second cycle. Both are the stream's own: the count restarting at 0 follows
    # the cycle after it by one, no stream before's. The stream before's last cycle (7 ahead
    # of the restart, not counting on from it) is still dropped.
    receiver = DetectionReceiver()
    cycles = [one_cycle(k, [10.0 + k]) for k in range(6)]
    for before, order, dropped in (([], [1, 0, 2, 3, 4, 5], 0),
                                   ([one_cycle(7, [3.0])], [0, 1, 2, 3, 4, 5], 1)):
        receiver.reset(restart=0)
        for cycle in [*before, *(cycles[k] for k in order)]:
            for msg in _messages(cycle):
                receiver.on_message_received(msg)
        got = receiver.flush()
        assert sorted(c.cycle for c in got) == list(range(6))
        assert all(c.complete for c in got)
        assert receiver.stale_cycles == dropped


@settings(max_examples=80, deadline=None)
@given(modulus=st.sampled_from([4, 5, 15, 16, 256]),
       cycles=st.lists(st.tuples(st.integers(-3, 12), st.booleans()), min_size=1,
                       max_size=60))
def test_the_receiver_remembers_no_counter_out_of_reach_of_the_latest(modulus, cycles):
    # Any course of counters (steps back, lost headers, jumps) and cycles that lose their
    # detection: after every message, each counter the receiver remembers as handed on lies
    # at or behind the latest by at most the counter's largest step back. A counter out of
    # that reach read as remembered would make the next lap's cycle a copy or a conflict.
    from rts_scenario.detections import largest_step_back, signed_step

    mapping = dataclasses.replace(BUILTIN, counter_max=modulus - 1)
    recorder = Recorder()
    publisher = DetectionPublisher(recorder, mapping=mapping)
    counter = 0
    for step, whole in cycles:
        counter = (counter + step) % modulus
        first = len(recorder)
        publisher.publish(one_cycle(counter, [10.0]))
        if not whole:
            del recorder[first + 1:]  # its detection is lost
    receiver = DetectionReceiver(mapping)
    back = largest_step_back(modulus)
    for msg in recorder:
        receiver.on_message_received(msg)
        latest = receiver._latest
        for known in (receiver._recent, receiver._content):
            assert all(-back <= signed_step(c, latest, modulus) <= 0 for c in known), (
                latest, list(known))
