"""Third-party radar protocols: Motorola signals, negative scales, multiplexed pages, object
lists, other ECUs on the bus, CAN FD - decoded by the checker and spoken by the simulated radar."""

from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from rts_scenario.canbus import DetectionPublisher, DetectionReceiver
from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.detections import Detections
from rts_scenario.pipeline import RunOptions, run_scene
from rts_scenario.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
OBJECT_LIST = ROOT / "scenarios" / "can" / "object_list.mapping.yaml"
CLUSTER_LIST = ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml"


class Capture:
    """A bus that keeps what is sent."""

    def __init__(self):
        self.messages: list[can.Message] = []

    def send(self, msg):
        self.messages.append(msg)


def cycle(n=3, counter=4660):
    rng = np.random.default_rng(1)
    return Detections(cycle=counter, t_s=12.345, range_m=rng.uniform(5, 80, n),
                      radial_velocity_mps=rng.uniform(-20, 20, n),
                      az_deg=rng.uniform(-40, 40, n), el_deg=rng.uniform(-10, 10, n),
                      snr_db=rng.uniform(10, 40, n), rcs_dbsm=rng.uniform(-5, 20, n))


def test_object_list_bytes_are_motorola_as_the_dbc_says():
    bus = Capture()
    DetectionPublisher(bus, mapping=CanMapping.from_file(OBJECT_LIST)).publish(cycle())
    status = bus.messages[0]
    assert status.arbitration_id == 1536
    # Big-endian: the object count in byte 0, the 16-bit counter 0x1234 in bytes 1 (high) and
    # 2 (low), the measurement time in ms in bytes 3..5.
    assert status.data[0] == 3
    assert (status.data[1], status.data[2]) == (0x12, 0x34)
    assert int.from_bytes(status.data[3:6], "big") == 12345
    pages = bus.messages[1:]
    assert len(pages) == 6  # two multiplexed pages per object
    for i, msg in enumerate(pages):
        assert msg.arbitration_id == 1537
        assert msg.data[0] >> 7 == i % 2  # the page bit
        assert msg.data[0] & 0x7F == i // 2  # the object id
        assert msg.data[1] == 0x34  # the counter's low byte


def decode_round_trip(mapping, detections, extra=()):
    bus = Capture()
    publisher = DetectionPublisher(bus, mapping=mapping)
    publisher.publish(detections)
    receiver = DetectionReceiver(mapping)
    messages = list(bus.messages)
    for i, msg in enumerate(extra):  # other ECUs in between
        messages.insert(1 + 2 * i, msg)
    for msg in messages:
        receiver.on_message_received(msg)
    got = receiver.flush()
    return publisher, receiver, got


def test_object_list_values_come_back_at_the_signals_resolution():
    mapping = CanMapping.from_file(OBJECT_LIST)
    sent = cycle(5)
    speed = can.Message(arbitration_id=1792, data=bytes(8), is_extended_id=False)
    publisher, receiver, got = decode_round_trip(mapping, sent, [speed] * 3)
    assert publisher.unsendable_detections == 0
    assert len(got) == 1 and got[0].complete and got[0].cycle == 4660
    d = got[0]
    assert receiver.stats.unknown_ids == 3  # counted, not an error
    # What each signal can carry, from the DBC's factor alone (independent of the codec):
    # raw = round(value / factor); a negative factor flips the raw value's sign.
    for name, factor, offset in (("range_m", 0.02, 0), ("radial_velocity_mps", 0.02, 0),
                                 ("az_deg", -0.05, 0), ("el_deg", 0.05, 0),
                                 ("rcs_dbsm", 0.5, -64), ("snr_db", 0.5, 0)):
        want = np.round((getattr(sent, name) - offset) / factor) * factor + offset
        np.testing.assert_allclose(getattr(d, name), want, atol=1e-9, err_msg=name)
    assert d.t_s == pytest.approx(12.345)


def test_a_value_the_dbc_cannot_carry_is_left_out_and_counted():
    mapping = CanMapping.from_file(OBJECT_LIST)
    sent = cycle(3)
    sent.az_deg[1] = 120.0  # beyond Obj_Azimuth's +-102 deg
    publisher, _, got = decode_round_trip(mapping, sent)
    assert publisher.unsendable == {"Obj_Azimuth": 1}
    assert got[0].count == 2 and got[0].complete


def test_cluster_list_cartesian_round_trip():
    mapping = CanMapping.from_file(CLUSTER_LIST)
    sent = cycle(4)
    sent = Detections(cycle=sent.cycle, t_s=None, range_m=sent.range_m,
                      radial_velocity_mps=sent.radial_velocity_mps, az_deg=sent.az_deg,
                      el_deg=np.zeros(4), snr_db=sent.snr_db, rcs_dbsm=sent.rcs_dbsm)
    _, _, got = decode_round_trip(mapping, sent)
    d = got[0]
    # Distances at 0.2 m and velocities at 0.25 m/s steps: range within half a step on each
    # axis, azimuth accordingly.
    np.testing.assert_allclose(d.range_m, sent.range_m, atol=0.15)
    np.testing.assert_allclose(d.az_deg, sent.az_deg, atol=np.degrees(0.15 / 5.0))
    np.testing.assert_allclose(d.radial_velocity_mps, sent.radial_velocity_mps, atol=0.2)


TEST_FD_DBC = '''VERSION ""
BU_: RADAR CHECKER
BO_ 1 Head: 8 RADAR
 SG_ Counter : 7|16@0+ (1,0) [0|65535] "" CHECKER
 SG_ Count : 23|8@0+ (1,0) [0|255] "" CHECKER
BO_ 2 Obj: 8 RADAR
 SG_ Id : 7|8@0+ (1,0) [0|255] "" CHECKER
 SG_ Dist : 15|16@0+ (0.01,0) [0|655.35] "m" CHECKER
 SG_ Angle : 31|16@0- (-0.01,0) [-327.67|327.68] "deg" CHECKER
 SG_ Speed : 47|16@0- (0.01,0) [-327.68|327.67] "m/s" CHECKER
BO_ 3 ObjFD: 16 RADAR
 SG_ Id : 7|8@0+ (1,0) [0|255] "" CHECKER
 SG_ Dist : 15|16@0+ (0.01,0) [0|655.35] "m" CHECKER
 SG_ Angle : 31|16@0- (-0.01,0) [-327.67|327.68] "deg" CHECKER
 SG_ Speed : 47|16@0- (0.01,0) [-327.68|327.67] "m/s" CHECKER
 SG_ Elev : 63|16@0- (0.01,0) [-327.68|327.67] "deg" CHECKER
'''


def test_can_fd_objects_from_a_mapping_written_for_the_test(tmp_path):
    (tmp_path / "fd.dbc").write_text(TEST_FD_DBC)
    (tmp_path / "fd.mapping.yaml").write_text(
        "rts_can_mapping: 1\nname: fd-test\ndbc: fd.dbc\n"
        "header: {message: Head, counter: Counter, count: [Count]}\n"
        "detection: {messages: [Obj], fd_message: ObjFD, index: Id, form: polar,\n"
        "  range_m: Dist, azimuth_deg: Angle, radial_velocity_mps: Speed,\n"
        "  elevation_deg: Elev}\n")
    mapping = CanMapping.from_file(tmp_path / "fd.mapping.yaml")
    assert cantools.database.load_file(tmp_path / "fd.dbc").get_message_by_name("ObjFD").length \
        == 16
    bus = Capture()
    sent = cycle(3)
    DetectionPublisher(bus, mapping=mapping, fd=True).publish(sent)
    assert all(m.is_fd for m in bus.messages)  # an FD bus
    assert [len(m.data) for m in bus.messages] == [8, 16, 16, 16]
    receiver = DetectionReceiver(mapping)
    for msg in bus.messages:
        receiver.on_message_received(msg)
    d = receiver.flush()[0]
    assert d.complete and d.count == 3
    np.testing.assert_allclose(d.el_deg, np.round(sent.el_deg / 0.01) * 0.01, atol=1e-9)
    np.testing.assert_allclose(d.az_deg, np.round(sent.az_deg / -0.01) * -0.01, atol=1e-9)


def test_rts_scenario_s_own_header_is_laid_out_as_its_dbc_says():
    import zlib

    bus = Capture()
    DetectionPublisher(bus).publish(cycle(4, counter=70000))  # wraps at 16 bits
    head = bus.messages[0].data
    assert int.from_bytes(head[0:2], "little") == 70000 % 65536
    assert head[2] | (head[3] & 0x03) << 8 == 4  # 10-bit count from bit 16
    assert head[7] == zlib.crc32(bytes(head[:7])) & 0xFF
    assert len(bus.messages) == 1 + 2 * 4  # two classic halves per detection
    assert all(m.data[0] == 70000 % 256 for m in bus.messages[1:])  # FrameCounter8


@pytest.mark.parametrize("mapping", [OBJECT_LIST, CLUSTER_LIST])
def test_a_scene_passes_with_the_simulated_radar_speaking_a_third_party_protocol(mapping):
    scene = load_scenario(ROOT / "scenarios" / "cut_in.scenario.yaml",
                          {"radar.noise": False, "radar.fidelity": "analytic"})
    report = run_scene(scene, RunOptions(mapping=str(mapping))).report
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["total"]
    assert report.bus["unsendable_detections"] == 0
