"""Third-party radar protocols: Motorola signals, negative scales, multiplexed pages, object
lists, other ECUs on the bus, CAN FD - decoded by the checker and spoken by the simulated radar."""

from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from rts_scenario.canbus import DetectionPublisher, DetectionReceiver, open_bus
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
 SG_ Elev : 63|8@0- (0.5,0) [-64|63.5] "deg" CHECKER
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


# The cluster list is cartesian without z_m: no elevation, which cut_in's tolerances name
# (el_deg: 1.0), so the scene declares quantity_unchecked to run on it.
@pytest.mark.parametrize("mapping, expected, unchecked", [
    (OBJECT_LIST, [], {}),
    (CLUSTER_LIST, ["quantity_unchecked"],
     {"el_deg": {"why": "mapping 'cluster-list' carries no elevation, a cartesian one without "
                        "z_m", "tolerance": 1.0, "written": True,
                        "target_cycles": None}})])
def test_a_scene_passes_with_the_simulated_radar_speaking_a_third_party_protocol(
        mapping, expected, unchecked):
    scene = load_scenario(ROOT / "scenarios" / "cut_in.scenario.yaml",
                          {"radar.noise": False, "radar.fidelity": "analytic",
                           "expectations.expected_limits": expected})
    report = run_scene(scene, RunOptions(mapping=str(mapping))).report
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["total"]
    assert report.bus["unsendable_detections"] == 0
    assert report.unchecked_quantities == unchecked


# A radar protocol written for these tests: every signal Motorola, most of them across byte
# borders; a negative factor (azimuth counted to the right); objects in a multiplexed message
# with a page the mapping does not read (extended information); an 8-bit cycle counter; a
# checksum byte in each message; a CAN FD message with everything; another ECU's message.
TEST_MUX_DBC = '''VERSION ""
BU_: RADAR CHECKER BRAKES
BO_ 768 Head: 8 RADAR
 SG_ Count : 7|6@0+ (1,0) [0|63] "" CHECKER
 SG_ Counter : 1|8@0+ (1,0) [0|255] "" CHECKER
 SG_ MeasTime : 23|16@0+ (0.001,0) [0|65.535] "s" CHECKER
 SG_ Checksum : 63|8@0+ (1,0) [0|255] "" CHECKER
BO_ 769 Obj: 8 RADAR
 SG_ Page M : 7|2@0+ (1,0) [0|3] "" CHECKER
 SG_ Id : 5|6@0+ (1,0) [0|63] "" CHECKER
 SG_ Range m0 : 15|13@0+ (0.05,0) [0|409.55] "m" CHECKER
 SG_ Azimuth m0 : 18|11@0- (-0.1,0) [-102.3|102.4] "deg" CHECKER
 SG_ VrelRad m1 : 15|12@0- (0.05,0) [-102.4|102.35] "m/s" CHECKER
 SG_ Elevation m1 : 19|10@0- (0.1,0) [-51.2|51.1] "deg" CHECKER
 SG_ RCS m1 : 25|8@0+ (0.5,-50) [-50|77.5] "dBsm" CHECKER
 SG_ Class m2 : 15|4@0+ (1,0) [0|15] "" CHECKER
 SG_ ProbOfExist m2 : 11|3@0+ (1,0) [0|7] "" CHECKER
 SG_ Checksum : 63|8@0+ (1,0) [0|255] "" CHECKER
BO_ 770 ObjFD: 12 RADAR
 SG_ Id : 7|8@0+ (1,0) [0|255] "" CHECKER
 SG_ Range : 15|13@0+ (0.05,0) [0|409.55] "m" CHECKER
 SG_ Azimuth : 18|11@0- (-0.1,0) [-102.3|102.4] "deg" CHECKER
 SG_ VrelRad : 39|12@0- (0.05,0) [-102.4|102.35] "m/s" CHECKER
 SG_ Elevation : 43|10@0- (0.1,0) [-51.2|51.1] "deg" CHECKER
 SG_ RCS : 57|8@0+ (0.5,-50) [-50|77.5] "dBsm" CHECKER
 SG_ Checksum : 95|8@0+ (1,0) [0|255] "" CHECKER
BO_ 1280 Brake_Status: 8 BRAKES
 SG_ BrakePressure : 7|12@0+ (0.1,0) [0|409.5] "bar" RADAR
'''

TEST_MUX_MAPPING = """rts_can_mapping: 1
name: mux-test
dbc: mux.dbc
header: {message: Head, counter: Counter, count: [Count], timestamp: MeasTime,
         checksum: Checksum}
detection:
  messages: [Obj]
  fd_message: ObjFD
  index: Id
  checksum: Checksum
  form: polar
  range_m: Range
  azimuth_deg: Azimuth
  elevation_deg: Elevation
  radial_velocity_mps: VrelRad
  rcs_dbsm: RCS
"""

# (quantity, factor, offset) of TEST_MUX_DBC, written out here rather than read through cantools.
MUX_RESOLUTION = (("range_m", 0.05, 0.0), ("az_deg", -0.1, 0.0), ("el_deg", 0.1, 0.0),
                  ("radial_velocity_mps", 0.05, 0.0), ("rcs_dbsm", 0.5, -50.0))


def motorola(data: bytes, start: int, length: int, signed: bool = False) -> int:
    """Raw value of a Motorola signal, read by hand: ``start`` is the DBC's bit number of its
    most significant bit (byte start // 8, bit start % 8 with 7 the byte's top bit)."""
    msb = (start // 8) * 8 + (7 - start % 8)  # position in the big-endian bit stream
    raw = int.from_bytes(data, "big") >> (8 * len(data) - msb - length) & ((1 << length) - 1)
    return raw - (1 << length) if signed and raw >> (length - 1) else raw


def quantized(values, factor, offset):
    return np.round((np.asarray(values) - offset) / factor) * factor + offset


@pytest.fixture
def mux_mapping(tmp_path):
    (tmp_path / "mux.dbc").write_text(TEST_MUX_DBC)
    (tmp_path / "mux.mapping.yaml").write_text(TEST_MUX_MAPPING)
    return CanMapping.from_file(tmp_path / "mux.mapping.yaml")


def test_motorola_bytes_are_where_the_dbc_says(mux_mapping):
    import zlib

    bus = Capture()
    sent = cycle(2, counter=300)
    DetectionPublisher(bus, mapping=mux_mapping).publish(sent)
    head = bus.messages[0].data
    assert motorola(head, 7, 6) == 2
    assert motorola(head, 1, 8) == 300 % 256  # wrapped at the counter's 8 bits
    assert motorola(head, 23, 16) == 12345  # ms
    assert head[7] == zlib.crc32(bytes(head[:7])) & 0xFF  # checksum in the last byte
    pages = bus.messages[1:]
    assert [motorola(m.data, 7, 2) for m in pages] == [0, 1, 2, 0, 1, 2]  # every page is sent
    assert [motorola(m.data, 5, 6) for m in pages] == [0, 0, 0, 1, 1, 1]
    for i in range(2):
        page0, page1 = pages[3 * i].data, pages[3 * i + 1].data
        assert motorola(page0, 15, 13) * 0.05 == pytest.approx(sent.range_m[i], abs=0.025)
        # Counted to the right on the bus: the raw value has the opposite sign.
        assert motorola(page0, 18, 11, signed=True) * -0.1 == pytest.approx(sent.az_deg[i],
                                                                             abs=0.05)
        assert np.sign(motorola(page0, 18, 11, signed=True)) == -np.sign(sent.az_deg[i])
        assert motorola(page1, 15, 12, signed=True) * 0.05 == pytest.approx(
            sent.radial_velocity_mps[i], abs=0.025)
        assert motorola(page1, 19, 10, signed=True) * 0.1 == pytest.approx(sent.el_deg[i],
                                                                           abs=0.05)
        assert motorola(page1, 25, 8) * 0.5 - 50 == pytest.approx(sent.rcs_dbsm[i], abs=0.25)
        for page in pages[3 * i : 3 * i + 3]:
            assert page.data[7] == zlib.crc32(bytes(page.data[:7])) & 0xFF


@pytest.mark.parametrize("fd", [False, True])
def test_virtual_bus_round_trip_with_other_ecus_on_the_bus(mux_mapping, fd):
    counters = [254, 255, 256, 257]  # the 8-bit counter wraps
    sent = [cycle(n, counter=c) for n, c in zip((3, 0, 5, 63), counters, strict=True)]
    brakes = can.Message(arbitration_id=1280, data=bytes(8), is_extended_id=False, is_fd=fd)
    unknown = can.Message(arbitration_id=0x18FF0001, data=bytes(8), is_extended_id=True,
                          is_fd=fd)
    with open_bus(channel="test-real-dbc", fd=fd) as listen, \
            open_bus(channel="test-real-dbc", fd=fd) as talk:
        publisher = DetectionPublisher(talk, mapping=mux_mapping, fd=fd)
        receiver = DetectionReceiver(mux_mapping)
        for detections in sent:
            talk.send(brakes)
            publisher.publish(detections)
            talk.send(unknown)
        while (msg := listen.recv(timeout=0.05)) is not None:
            receiver.on_message_received(msg)
        got = receiver.flush()
    assert publisher.unsendable_detections == 0
    parts = 1 if fd else 3  # classic: three pages per object, one the receiver skips
    assert publisher.sent == sum(1 + parts * d.count for d in sent)
    stats = receiver.stats
    assert stats.unknown_ids == 2 * len(sent)  # other ECUs: ignored and counted
    assert (stats.checksum_errors, stats.decode_errors, stats.duplicates, stats.orphans,
            stats.reordered) == (0, 0, 0, 0, 0)
    assert [d.cycle for d in got] == [c % 256 for c in counters]
    assert all(d.complete for d in got)
    assert got[1].count == 0
    for want, have in zip(sent, got, strict=True):
        assert have.snr_db is None  # not mapped: not reported
        assert have.t_s == pytest.approx(want.t_s)
        for name, factor, offset in MUX_RESOLUTION:
            np.testing.assert_allclose(getattr(have, name),
                                       quantized(getattr(want, name), factor, offset),
                                       atol=1e-9, err_msg=name)


def test_pages_the_mapping_does_not_read_may_be_missing_and_faults_are_counted(mux_mapping):
    bus = Capture()
    DetectionPublisher(bus, mapping=mux_mapping).publish(cycle(3))
    receiver = DetectionReceiver(mux_mapping)
    without_extended = [m for m in bus.messages
                        if m.arbitration_id != 769 or motorola(m.data, 7, 2) != 2]
    assert len(without_extended) == 1 + 2 * 3
    for msg in without_extended:
        receiver.on_message_received(msg)
    d, = receiver.flush()
    assert d.complete and d.count == 3 and receiver.stats.clean

    receiver = DetectionReceiver(mux_mapping)
    corrupt = bytearray(bus.messages[2].data)  # object 0, page 1
    corrupt[2] ^= 0x04
    broken = can.Message(arbitration_id=769, data=bytes(corrupt), is_extended_id=False)
    for msg in [*bus.messages[:2], broken, *bus.messages[3:], bus.messages[4]]:
        receiver.on_message_received(msg)
    d, = receiver.flush()
    assert not d.complete  # object 0 lacks its second page
    assert (receiver.stats.checksum_errors, receiver.stats.duplicates) == (1, 1)


TEST_CARTESIAN_DBC = '''VERSION ""
BU_: RADAR CHECKER
BO_ 1024 Status: 8 RADAR
 SG_ NofObj : 7|8@0+ (1,0) [0|255] "" CHECKER
 SG_ Cycle : 15|16@0+ (1,0) [0|65535] "" CHECKER
BO_ 1025 Object: 8 RADAR
 SG_ ObjId : 7|6@0+ (1,0) [0|63] "" CHECKER
 SG_ DistX : 1|13@0+ (0.1,-50) [-50|769.1] "m" CHECKER
 SG_ DistY : 20|11@0- (-0.1,0) [-102.3|102.4] "m" CHECKER
 SG_ DistZ : 25|9@0- (0.05,0) [-12.8|12.75] "m" CHECKER
 SG_ VelX : 32|12@0- (0.1,0) [-204.8|204.7] "m/s" CHECKER
 SG_ VelY : 52|12@0- (-0.1,0) [-204.7|204.8] "m/s" CHECKER
'''


def test_cartesian_motorola_with_height_and_a_lateral_axis_counted_to_the_right(tmp_path):
    (tmp_path / "xyz.dbc").write_text(TEST_CARTESIAN_DBC)
    (tmp_path / "xyz.mapping.yaml").write_text(
        "rts_can_mapping: 1\nname: xyz\ndbc: xyz.dbc\n"
        "header: {message: Status, counter: Cycle, count: [NofObj]}\n"
        "detection: {messages: [Object], index: ObjId, form: cartesian,\n"
        "  x_m: DistX, y_m: DistY, z_m: DistZ, vx_mps: VelX, vy_mps: VelY}\n")
    mapping = CanMapping.from_file(tmp_path / "xyz.mapping.yaml")
    assert mapping.quantities == {"range_m", "azimuth_deg", "elevation_deg",
                                  "radial_velocity_mps"}
    sent = cycle(6)
    _, receiver, got = decode_round_trip(mapping, sent)
    d, = got
    assert d.complete and receiver.stats.clean
    # Reference from the radar frame's definitions: position on the line of sight, velocity
    # horizontal (a road target) with the measured radial velocity; quantized at the DBC's steps.
    az, el, r = np.radians(sent.az_deg), np.radians(sent.el_deg), sent.range_m
    x = quantized(r * np.cos(el) * np.cos(az), 0.1, -50)
    y = quantized(r * np.cos(el) * np.sin(az), -0.1, 0)
    z = quantized(r * np.sin(el), 0.05, 0)
    vx = quantized(sent.radial_velocity_mps * np.cos(az) / np.cos(el), 0.1, 0)
    vy = quantized(sent.radial_velocity_mps * np.sin(az) / np.cos(el), -0.1, 0)
    rq = np.sqrt(x * x + y * y + z * z)
    np.testing.assert_allclose(d.range_m, rq, atol=1e-9)
    np.testing.assert_allclose(d.az_deg, np.degrees(np.arctan2(y, x)), atol=1e-9)
    np.testing.assert_allclose(d.el_deg, np.degrees(np.arctan2(z, np.hypot(x, y))), atol=1e-9)
    np.testing.assert_allclose(d.radial_velocity_mps, (x * vx + y * vy) / rq, atol=1e-9)
    # And close to what was sent (steps of 0.1 m, 0.05 m, 0.1 m/s).
    np.testing.assert_allclose(d.range_m, r, atol=0.1)
    np.testing.assert_allclose(d.radial_velocity_mps, sent.radial_velocity_mps, atol=0.1)


def test_a_radar_without_height_reports_the_range_of_an_elevated_target():
    mapping = CanMapping.from_file(CLUSTER_LIST)
    sent = cycle(4)
    sent.range_m[:] = [40.0, 55.0, 70.0, 85.0]
    sent.el_deg[:] = 8.0  # cos(8 deg) would shorten 85 m by 0.8 m
    _, _, got = decode_round_trip(mapping, sent)
    d, = got
    assert d.el_deg is None
    # x and y at 0.2 m steps: the range within half a step on each axis.
    np.testing.assert_allclose(d.range_m, sent.range_m, atol=0.1 * np.sqrt(2))


# Makes message 769 (Obj) a CAN FD message in the DBC, 8 bytes long as it is.
FD_FRAME_FORMAT_769 = (
    'BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN","reserved","reserved",'
    '"reserved","reserved","reserved","reserved","reserved","reserved","reserved","reserved",'
    '"reserved","reserved","StandardCAN_FD","ExtendedCAN_FD";\n'
    'BA_DEF_DEF_ "VFrameFormat" "StandardCAN";\n'
    'BA_ "VFrameFormat" BO_ 769 14;\n')

BAD_MAPPINGS = [
    ("checksum-not-a-byte", ("checksum: Checksum}", "checksum: Count}"), "header.checksum",
     r"signal 'Count' of message 'Head' must fill one whole byte .* got 6 bits"),
    ("checksum-motorola-off-byte", ("Checksum : 63|8@0+ (1,0) [0|255] \"\" CHECKER\nBO_ 769",
                                    "Checksum : 51|8@0+ (1,0) [0|255] \"\" CHECKER\nBO_ 769"),
     "header.checksum", r"signal 'Checksum' of message 'Head' must fill one whole byte .*bit 7 "
                        r"Motorola.* got 8 bits from bit 51 big-endian"),
    ("index-on-one-page", (" SG_ Id : 5|6@0+", " SG_ Id m0 : 5|6@0+"), "detection.index",
     r"signal 'Id' is not in page 1 of message 'Obj'"),
    ("unknown-message", ("messages: [Obj]", "messages: [Objects]"), "detection.messages",
     r"message 'Objects' is not in the DBC; messages: .*Head, Obj"),
    ("form", ("form: polar", "form: spherical"), "detection.form",
     r"got 'spherical'; allowed values: 'polar', 'cartesian'"),
    ("too-many-messages", ("messages: [Obj]", "messages: [Obj" + ", Obj" * 8 + "]"),
     "detection.messages", r"must have at most 8 items, got 9"),
    ("missing-dbc", ("dbc: mux.dbc", "dbc: none.dbc"), "dbc", r"cannot load DBC .*none.dbc"),
    ("one-signal-two-quantities", ("elevation_deg: Elevation", "elevation_deg: Azimuth"),
     "detection.elevation_deg",
     r"signal 'Azimuth' is already mapped as detection.azimuth_deg; each signal carries one"),
    ("counter-is-the-count", ("counter: Counter", "counter: Count"), "header.count[0]",
     r"signal 'Count' is already mapped as header.counter"),
    ("scale-zero", ("rcs_dbsm: RCS", "rcs_dbsm: {signal: RCS, scale: 0}"),
     "detection.rcs_dbsm.scale", r"must not be 0: rcs_dbsm would read 0 whatever the radar"),
    ("shared-frame-id", ("BO_ 770 ObjFD", "BO_ 769 ObjFD"), "dbc",
     r"DBC mux.dbc: messages 'Obj' and 'ObjFD' have the same frame ID 0x301; a receiver could "
     r"not tell them apart"),
    ("dbc-factor-zero", ("(0.001,0) [0|65.535]", "(0,0) [0|65.535]"), "header.timestamp",
     r"signal 'MeasTime' of message 'Head' in DBC mux.dbc has factor 0: every raw value reads 0"),
    ("header-signal-typo", ("counter: Counter", "counter: Countr"), "header.counter",
     r"signal 'Countr' is not in message 'Head'; signals: Checksum, Count, Counter, MeasTime$"),
    ("quantity-signal-typo", ("range_m: Range", "range_m: Rnage"), "detection.range_m",
     r"signal 'Rnage' is not in the detection message\(s\) Obj, ObjFD; signals: "
     r"Azimuth, Checksum, Class, Elevation, Id, Page, ProbOfExist, RCS, Range, VrelRad$"),
    ("index-typo", ("index: Id", "index: ID"), "detection.index",
     r"signal 'ID' is not in the detection message\(s\) Obj, ObjFD; signals: .*, Id, "),
    # A typo in an optional role must not leave the checksum or the counter unread.
    ("checksum-typo", ("checksum: Checksum\n  form", "checksum: Chksum\n  form"),
     "detection.checksum", r"signal 'Chksum' is not in the detection message\(s\) Obj, ObjFD; "
                           r"signals: Azimuth, Checksum, "),
    ("frame-counter-typo", ("index: Id\n", "index: Id\n  frame_counter: Counter8\n"),
     "detection.frame_counter", r"signal 'Counter8' is not in the detection message\(s\) Obj, "
                                r"ObjFD; signals: Azimuth, Checksum, "),
    # A DBC unit that is not the quantity's: converted by the mapping's scale, or refused.
    ("velocity-in-km/h", ('[-102.4|102.35] "m/s" CHECKER\n SG_ Elevation m1',
                          '[-102.4|102.35] "km/h" CHECKER\n SG_ Elevation m1'),
     "detection.radial_velocity_mps",
     r"signal 'VrelRad' of message 'Obj' is in km/h \(its DBC unit\), radial_velocity_mps in "
     r"m/s: give \{signal: VrelRad, scale: 0.277778\} to convert it$"),
    ("azimuth-in-rad", ('(-0.1,0) [-102.3|102.4] "deg" CHECKER\n SG_ VrelRad m1',
                        '(-0.1,0) [-102.3|102.4] "rad" CHECKER\n SG_ VrelRad m1'),
     "detection.azimuth_deg",
     r"signal 'Azimuth' of message 'Obj' is in rad \(its DBC unit\), azimuth_deg in deg: give "
     r"\{signal: Azimuth, scale: 57.2958\} to convert it$"),
    ("range-in-a-velocity-unit", ('[0|409.55] "m" CHECKER\n SG_ Azimuth m0',
                                  '[0|409.55] "m/s" CHECKER\n SG_ Azimuth m0'),
     "detection.range_m",
     r"signal 'Range' of message 'Obj' is in m/s \(its DBC unit\), not a length: range_m is "
     r"in m; map a signal in m \(or give a scale that converts it\)$"),
    ("rcs-linear", ('(0.5,-50) [-50|77.5] "dBsm" CHECKER\n SG_ Class',
                    '(0.5,-50) [-50|77.5] "m2" CHECKER\n SG_ Class'),
     "detection.rcs_dbsm",
     r"signal 'RCS' of message 'Obj' is in m2 \(its DBC unit\), not a level in dB: rcs_dbsm "
     r"is in dB"),
    ("dbc-factor-zero-unmapped", ("ProbOfExist m2 : 11|3@0+ (1,0)",
                                  "ProbOfExist m2 : 11|3@0+ (0,0)"), "dbc",
     r"signal 'ProbOfExist' of message 'Obj' in DBC mux.dbc has factor 0"),
    # detection.messages are classic CAN: a longer message (or one the DBC makes CAN FD) would
    # go out as CAN FD without --can-fd; so would a header, which every cycle opens.
    ("classic-message-over-8-bytes", ("messages: [Obj]", "messages: [Obj, ObjFD]"),
     "detection.messages[1]",
     r"message 'ObjFD' is 12 bytes long: detection.messages are classic CAN messages, of 8 "
     r"bytes at most; a CAN FD message goes under fd_message \(sent with --can-fd\)$"),
    ("classic-message-fd-in-the-dbc", ("BO_ 1280 Brake_Status", FD_FRAME_FORMAT_769
                                       + "BO_ 1280 Brake_Status"),
     "detection.messages[0]",
     r"message 'Obj' is a CAN FD message in the DBC \(its frame format\), 8 bytes: "
     r"detection.messages are classic CAN messages"),
    ("header-over-8-bytes", ("BO_ 768 Head: 8 RADAR", "BO_ 768 Head: 12 RADAR"),
     "header.message",
     r"message 'Head' is 12 bytes long: the header opens every cycle, on classic CAN too "
     r"\(detection.messages are classic\), so it is a classic message of 8 bytes at most$"),
    ("multiplexed-header", ("BO_ 768 Head: 8 RADAR\n", "BO_ 768 Head: 8 RADAR\n"
                            ' SG_ HPage M : 39|1@0+ (1,0) [0|1] "" CHECKER\n'
                            ' SG_ HExtra m1 : 38|7@0+ (1,0) [0|127] "" CHECKER\n'),
     "header.message",
     r"message 'Head' is multiplexed \(multiplexer 'HPage', pages 1\): a multiplexed header "
     r"is not supported; the header must be one plain message$"),
    # Without --can-fd a detection is its classic messages, with it the CAN FD one alone:
    # each must carry every mapped quantity.
    ("quantity-only-in-fd", (' SG_ Azimuth m0 : 18|11@0- (-0.1,0) [-102.3|102.4] "deg" '
                             'CHECKER\n', ""),
     "detection.azimuth_deg",
     r"signal 'Azimuth' is only in fd_message 'ObjFD', in none of the classic messages Obj: "
     r"without --can-fd a detection goes in those, so each mapped quantity must be in one of "
     r"them$"),
    ("quantity-not-in-fd", (' SG_ Elevation : 43|10@0- (0.1,0) [-51.2|51.1] "deg" CHECKER\n',
                            ""),
     "detection.elevation_deg",
     r"signal 'Elevation' is in Obj but not in fd_message 'ObjFD': with --can-fd a detection "
     r"is that one message, so it must carry every mapped quantity$"),
    ("message-listed-twice", ("messages: [Obj]", "messages: [Obj, Obj]"),
     "detection.messages[1]",
     r"message 'Obj' is listed twice \(entries 0 and 1\); each message carries its part of a "
     r"detection once: list it once$"),
    # Detections and cycles are numbered one by one: an index or counter of factor 2 would
    # give two detections one number.
    ("index-counting-by-2", (' SG_ Id : 5|6@0+ (1,0) [0|63] "" CHECKER',
                             ' SG_ Id : 5|6@0+ (2,0) [0|126] "" CHECKER'), "detection.index",
     r"signal 'Id' of message 'Obj' counts in steps of 2 \(its DBC factor\); it numbers "
     r"detections or cycles one by one, so its factor must be 1$"),
    ("counter-counting-by-half", (' SG_ Counter : 1|8@0+ (1,0) [0|255] "" CHECKER',
                                  ' SG_ Counter : 1|8@0+ (0.5,0) [0|127.5] "" CHECKER'),
     "header.counter", r"signal 'Counter' of message 'Head' counts in steps of 0.5 "),
    # The header's time is in seconds, as the quantities are in their units.
    ("timestamp-in-ms", ('(0.001,0) [0|65.535] "s"', '(1,0) [0|65535] "ms"'),
     "header.timestamp",
     r"signal 'MeasTime' of message 'Head' is in ms \(its DBC unit\), the timestamp in s: "
     r"give \{signal: MeasTime, scale: 0.001\} to convert it$"),
    ("timestamp-in-a-length-unit", ('[0|65.535] "s"', '[0|65.535] "m"'), "header.timestamp",
     r"signal 'MeasTime' of message 'Head' is in m \(its DBC unit\), not a time: the "
     r"timestamp is in s; map a signal in s \(or give a scale that converts it\)$"),
]


@pytest.mark.parametrize(("change", "key", "pattern"), [c[1:] for c in BAD_MAPPINGS],
                         ids=[c[0] for c in BAD_MAPPINGS])
def test_bad_mapping_is_one_located_error_naming_file_and_key(tmp_path, capsys, change, key,
                                                              pattern):
    import re

    import rts_scenario.cli as cli

    old, new = change
    dbc, mapping = TEST_MUX_DBC, TEST_MUX_MAPPING
    assert old in dbc + mapping, old
    (tmp_path / "mux.dbc").write_text(dbc.replace(old, new))
    path = tmp_path / "mux.mapping.yaml"
    path.write_text(mapping.replace(old, new))
    code = cli.main(["run", str(ROOT / "scenarios" / "cut_in.scenario.yaml"),
                     "--mapping", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and "Overwriting" not in err
    lines = [line for line in err.splitlines() if "error: " in line]
    assert len(lines) == 1, err
    message = lines[0].split("error: ", 1)[1]
    assert re.match(rf"--mapping {re.escape(str(path))}:\d+:\d+: {re.escape(key)}: {pattern}",
                    message), message


def test_an_8_bit_counter_that_comes_round_again_is_a_new_cycle(mux_mapping):
    # Cycle 256 has counter 0 again, with the same content here: a new cycle, not a copy of
    # the first (the receiver remembers cycles for half the counter's range at most).
    bus = Capture()
    publisher = DetectionPublisher(bus, mapping=mux_mapping)
    for n in range(300):
        publisher.publish(cycle(1, counter=n))
    receiver = DetectionReceiver(mux_mapping)
    for msg in bus.messages:
        receiver.on_message_received(msg)
    got = receiver.flush()
    assert (receiver.stats.duplicates, receiver.stats.conflicts) == (0, 0)
    assert [d.cycle for d in got] == [n % 256 for n in range(300)]
    assert all(d.complete for d in got)


def test_the_bus_steps_of_a_mapping_are_its_signals_scales(mux_mapping):
    steps = mux_mapping.steps()
    named = {"az_deg": "azimuth_deg", "el_deg": "elevation_deg"}
    assert steps == pytest.approx({named.get(q, q): abs(factor)
                                   for q, factor, _ in MUX_RESOLUTION}, rel=1e-12)
    builtin = CanMapping.builtin()  # rts_detections.dbc: 0.005 steps, RCS and SNR 0.5 classic
    classic = {"range_m": 0.005, "azimuth_deg": 0.005, "elevation_deg": 0.005,
               "radial_velocity_mps": 0.005, "rcs_dbsm": 0.5, "snr_db": 0.5}
    assert builtin.steps() == pytest.approx(classic, rel=1e-12)
    # RTS_DetectionFD carries RCS in 0.01 dB steps, the rest as the classic messages; a bus not
    # known: the finer of the two.
    fd = {**classic, "rcs_dbsm": 0.01}
    assert builtin.steps(fd=True) == pytest.approx(fd, rel=1e-12)
    assert builtin.steps(fd=None) == pytest.approx(fd, rel=1e-12)


@pytest.mark.parametrize("tolerances, said", [
    ({"az_deg": 0.04}, ["az tolerance 0.04 deg", "azimuth_deg", "(0.1 deg)", "0.05 deg off"]),
    ({"az_deg": 0.05, "range_m": 0.025, "rcs_db": 0.25}, []),  # half a step: enough
    ({"range_m": 0.02, "rcs_db": 0.2}, ["range tolerance 0.02 m", "rcs tolerance 0.2 dB"]),
])
def test_a_tolerance_finer_than_half_the_bus_step_is_said(mux_mapping, tolerances, said):
    from rts_scenario.check import tolerances_below_bus_steps
    from rts_scenario.scenario.model import DEFAULT_TOLERANCES, Expectations

    exp = Expectations(tolerances={**DEFAULT_TOLERANCES, **tolerances})
    lines = tolerances_below_bus_steps(exp, mux_mapping.steps(), mux_mapping.name)
    text = "\n".join(lines)
    assert len(lines) == (len(tolerances) if said else 0)
    for part in said:
        assert part in text
    assert all("'mux-test'" in line for line in lines)


def test_run_and_check_warn_of_a_tolerance_the_mapping_cannot_carry(tmp_path, capsys):
    from rts_scenario import cli

    (tmp_path / "mux.dbc").write_text(TEST_MUX_DBC)
    (tmp_path / "mux.mapping.yaml").write_text(TEST_MUX_MAPPING)
    text = (Path(__file__).parents[1] / "scenarios" / "approaching_target.scenario.yaml"
            ).read_text().replace("duration_s: 7.5", "duration_s: 1.0").replace(
        "az_deg: 0.5, el_deg: 1.0}", "az_deg: 0.03, el_deg: 1.0}")
    scene = tmp_path / "tight.scenario.yaml"
    scene.write_text(text)
    log = tmp_path / "run.blf"
    cli.main(["run", str(scene), "--mapping", str(tmp_path / "mux.mapping.yaml"),
              "--record", str(log)])
    err = capsys.readouterr().err
    assert f"warning: {scene}: the az tolerance 0.03 deg is finer than half" in err
    cli.main(["check", str(scene), "--log", str(log)])  # the sidecar names the mapping
    assert "warning: the az tolerance 0.03 deg is finer than half" in capsys.readouterr().err
    cli.main(["run", str(scene)])  # rts-scenario's own messages: 0.005 deg steps
    assert "finer than half" not in capsys.readouterr().err
    # RCS: 0.5 dB steps in the classic messages, 0.01 dB in the FD one.
    scene.write_text(text.replace("az_deg: 0.03, el_deg: 1.0}", "rcs_db: 0.2}"))
    cli.main(["run", str(scene)])
    assert "the rcs tolerance 0.2 dB is finer than half" in capsys.readouterr().err
    cli.main(["run", str(scene), "--can-fd"])
    assert "finer than half" not in capsys.readouterr().err


def test_a_timestamp_in_ms_is_read_and_written_through_the_mapping_s_scale(tmp_path):
    # MeasTime in ms with the DBC's factor 1: the mapping's scale 0.001 makes it seconds.
    (tmp_path / "mux.dbc").write_text(TEST_MUX_DBC.replace('(0.001,0) [0|65.535] "s"',
                                                           '(1,0) [0|65535] "ms"'))
    (tmp_path / "mux.mapping.yaml").write_text(TEST_MUX_MAPPING.replace(
        "timestamp: MeasTime", "timestamp: {signal: MeasTime, scale: 0.001}"))
    mapping = CanMapping.from_file(tmp_path / "mux.mapping.yaml")
    bus = Capture()
    DetectionPublisher(bus, mapping=mapping).publish(cycle(1))  # t_s 12.345
    assert motorola(bus.messages[0].data, 23, 16) == 12345  # ms on the bus
    hand_packed = bytearray(bus.messages[0].data)
    receiver = DetectionReceiver(mapping)
    for msg in bus.messages:
        receiver.on_message_received(msg)
    d, = receiver.flush()
    assert d.t_s == pytest.approx(12.345, abs=1e-9)
    assert bytes(hand_packed[2:4]) == (12345).to_bytes(2, "big")


def _objects(tmp_path, *changes):
    """The object list of test_third_party_bus with its DBC changed (old, new, count)."""
    from test_third_party_bus import OBJECTS_DBC, OBJECTS_MAPPING

    dbc = OBJECTS_DBC
    for old, new, count in changes:
        assert dbc.count(old) == count, old
        dbc = dbc.replace(old, new)
    (tmp_path / "objects.dbc").write_text(dbc)
    (tmp_path / "objects.mapping.yaml").write_text(OBJECTS_MAPPING)
    return CanMapping.from_file(tmp_path / "objects.mapping.yaml")


def _published(mapping, n):
    """Publish one cycle of ``n`` detections; return the publisher, messages, and cycle read."""
    bus = Capture()
    sent = cycle(n, counter=9)
    sent.az_deg[:] = np.linspace(-20, 20, n)  # inside the lateral distance's range
    publisher = DetectionPublisher(bus, mapping=mapping)
    publisher.publish(sent)
    receiver = DetectionReceiver(mapping)
    for msg in bus.messages:
        receiver.on_message_received(msg)
    got, = receiver.flush()
    return publisher, bus.messages, got


def test_an_index_numbered_from_1_starts_at_1_and_detections_past_its_last_are_left_out(
        tmp_path):
    # Obj_ID in 6 bits, raw 0..63 read as 1..64 (offset 1), in both messages.
    mapping = _objects(tmp_path, ("Obj_ID : 7|8@0+ (1,0) [0|255]",
                                  "Obj_ID : 7|6@0+ (1,1) [1|64]", 2))
    publisher, messages, got = _published(mapping, 70)
    assert messages[0].data[0] == 64  # Obj_NofObjects: the ones sent
    general = [m.data for m in messages if m.arbitration_id == 1547]
    quality = [m.data for m in messages if m.arbitration_id == 1548]
    # Raw index (the top 6 bits of byte 0) 0..63: physical 1..64.
    assert [d[0] >> 2 for d in general] == list(range(64))
    assert [d[0] >> 2 for d in quality] == list(range(64))
    assert publisher.unsendable == {"Obj_ID": 6}
    assert publisher.unsendable_reason == (
        "6 past the 64 per cycle that index Obj_ID numbers (1 to 64, in every message) "
        "(the first: cycle 9 detection 64)")
    assert got.complete and got.count == 64


def test_an_index_narrower_in_one_message_numbers_what_every_message_carries(tmp_path):
    # Obj_ID in 3 bits (0..7) in the general message, 8 bits in the quality message.
    mapping = _objects(tmp_path, ("BO_ 1547 Obj_1_General: 8 RADAR\n SG_ Obj_ID : 7|8@0+ (1,0) "
                                  "[0|255]", "BO_ 1547 Obj_1_General: 8 RADAR\n SG_ Obj_ID : "
                                  "7|3@0+ (1,0) [0|7]", 1))
    publisher, messages, got = _published(mapping, 10)
    assert messages[0].data[0] == 8
    assert [m.data[0] >> 5 for m in messages if m.arbitration_id == 1547] == list(range(8))
    assert [m.data[0] for m in messages if m.arbitration_id == 1548] == list(range(8))
    assert publisher.unsendable == {"Obj_ID": 2}
    assert "2 past the 8 per cycle that index Obj_ID numbers (0 to 7, in every message)" \
        in publisher.unsendable_reason
    assert got.complete and got.count == 8


def test_a_run_past_its_index_s_last_value_fails_saying_so(tmp_path):
    # An index of one value (1) numbers 1 detection per cycle: the cut-out's other target is left
    # out where both are seen, and the run fails naming the index's range, not a value its
    # signals cannot carry.
    import re

    _objects(tmp_path, ("Obj_ID : 7|8@0+ (1,0) [0|255]", "Obj_ID : 7|1@0+ (1,0) [1|1]", 2))
    scene = load_scenario(ROOT / "scenarios" / "cut_out.scenario.yaml",
                          {"radar.noise": False, "radar.fidelity": "analytic"})
    report = run_scene(scene, RunOptions(mapping=str(tmp_path / "objects.mapping.yaml"))).report
    n = report.bus["unsendable_detections"]
    assert n > 0 and not report.passed
    said = [r for r in report.reasons if "could not put on the bus" in r]
    assert len(said) == 1, report.reasons
    assert re.fullmatch(rf"{n} detections the radar could not put on the bus: {n} past the 1 "
                        rf"per cycle that index Obj_ID numbers \(1 to 1, in every message\) "
                        rf"\(the first: cycle \d+ detection 1\)", said[0]), said[0]
