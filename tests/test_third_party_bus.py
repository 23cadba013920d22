"""A third-party radar on the bench: an object-list protocol in the style of a long-range radar
(a status message with the object count and a 16-bit cycle counter, then per object a general
message with scaled, offset distances and velocities, and a quality message), and a cluster
protocol on extended identifiers (an 8-bit counter, Motorola signed signals in multiplexed
pages, a checksum byte). Every expected value here is computed by hand from the DBC's bit
layout, factor and offset, not by the product's codec."""

import math
import zlib
from pathlib import Path

import can
import numpy as np
import pytest
import yaml

import rts_scenario.cli as cli
from rts_scenario.canbus import DetectionReceiver
from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.detections import sequential_numbers
from rts_scenario.recheck import read_cycles

ROOT = Path(__file__).resolve().parents[1]

OBJECTS_DBC = '''VERSION ""
BU_: RADAR GW
BO_ 1546 Obj_0_Status: 8 RADAR
 SG_ Obj_NofObjects : 7|8@0+ (1,0) [0|255] "" GW
 SG_ Obj_MeasCounter : 15|16@0+ (1,0) [0|65535] "" GW
 SG_ Obj_InterfaceVersion : 39|4@0+ (1,0) [0|15] "" GW
BO_ 1547 Obj_1_General: 8 RADAR
 SG_ Obj_ID : 7|8@0+ (1,0) [0|255] "" GW
 SG_ Obj_DistLong : 15|13@0+ (0.2,-500) [-500|1138.2] "m" GW
 SG_ Obj_DistLat : 18|11@0+ (0.2,-204.6) [-204.6|204.8] "m" GW
 SG_ Obj_VrelLong : 39|10@0+ (0.25,-128) [-128|127.75] "m/s" GW
 SG_ Obj_VrelLat : 45|9@0+ (0.25,-64) [-64|63.75] "m/s" GW
 SG_ Obj_DynProp : 50|3@0+ (1,0) [0|7] "" GW
 SG_ Obj_RCS : 63|8@0+ (0.5,-64) [-64|63.5] "dBm2" GW
BO_ 1548 Obj_2_Quality: 8 RADAR
 SG_ Obj_ID : 7|8@0+ (1,0) [0|255] "" GW
 SG_ Obj_DistLong_rms : 15|5@0+ (1,0) [0|31] "" GW
 SG_ Obj_ProbOfExist : 55|3@0+ (1,0) [0|7] "" GW
BO_ 513 RadarState: 8 RADAR
 SG_ RadarState_NVMReadStatus : 6|1@0+ (1,0) [0|1] "" GW
'''

OBJECTS_MAPPING = '''rts_can_mapping: 1
name: object-list-16
dbc: objects.dbc
header:
  message: Obj_0_Status
  counter: Obj_MeasCounter
  count: [Obj_NofObjects]
detection:
  messages: [Obj_1_General, Obj_2_Quality]
  index: Obj_ID
  form: cartesian
  x_m: Obj_DistLong
  y_m: Obj_DistLat
  vx_mps: Obj_VrelLong
  vy_mps: Obj_VrelLat
  rcs_dbsm: Obj_RCS
'''

# Extended identifiers 0x19000100 and 0x19000101 (the DBC sets bit 31 for an extended one).
CLUSTERS_DBC = '''VERSION ""
BU_: RADAR GW
BO_ 2566914304 Clu_Status: 8 RADAR
 SG_ Clu_Count : 7|8@0+ (1,0) [0|255] "" GW
 SG_ Clu_Cycle : 15|8@0+ (1,0) [0|255] "" GW
 SG_ Clu_Time : 23|16@0+ (0.01,0) [0|655.35] "s" GW
 SG_ Clu_CRC : 63|8@0+ (1,0) [0|255] "" GW
BO_ 2566914305 Clu_Data: 8 RADAR
 SG_ Clu_Page M : 7|2@0+ (1,0) [0|3] "" GW
 SG_ Clu_Seq : 5|4@0+ (1,0) [0|15] "" GW
 SG_ Clu_Idx : 1|6@0+ (1,0) [0|63] "" GW
 SG_ Clu_Range m0 : 11|14@0+ (0.05,0) [0|819.15] "m" GW
 SG_ Clu_Azi m0 : 29|12@0- (0.1,0) [-204.8|204.7] "deg" GW
 SG_ Clu_Vr m0 : 33|10@0- (0.2,0) [-102.4|102.2] "km/h" GW
 SG_ Clu_Ele m1 : 11|10@0- (0.1,0) [-51.2|51.1] "deg" GW
 SG_ Clu_RCS m1 : 17|8@0+ (0.5,-50) [-50|77.5] "dBsm" GW
 SG_ Clu_CRC : 63|8@0+ (1,0) [0|255] "" GW
'''

CLUSTERS_MAPPING = '''rts_can_mapping: 1
name: clusters-8
dbc: clusters.dbc
header:
  message: Clu_Status
  counter: Clu_Cycle
  count: [Clu_Count]
  timestamp: Clu_Time
  checksum: Clu_CRC
detection:
  messages: [Clu_Data]
  frame_counter: Clu_Seq
  index: Clu_Idx
  checksum: Clu_CRC
  form: polar
  range_m: Clu_Range
  azimuth_deg: Clu_Azi
  elevation_deg: Clu_Ele
  radial_velocity_mps: {signal: Clu_Vr, scale: 0.2777777777777778}
  rcs_dbsm: Clu_RCS
'''

STATUS_ID, GENERAL_ID, QUALITY_ID = 1546, 1547, 1548
CLU_STATUS_ID, CLU_DATA_ID = 0x19000100, 0x19000101


@pytest.fixture
def objects(tmp_path):
    (tmp_path / "objects.dbc").write_text(OBJECTS_DBC)
    (tmp_path / "objects.mapping.yaml").write_text(OBJECTS_MAPPING)
    return tmp_path / "objects.mapping.yaml"


@pytest.fixture
def clusters(tmp_path):
    (tmp_path / "clusters.dbc").write_text(CLUSTERS_DBC)
    (tmp_path / "clusters.mapping.yaml").write_text(CLUSTERS_MAPPING)
    return tmp_path / "clusters.mapping.yaml"


def motorola(fields) -> bytearray:
    """Pack ``(start bit, length, raw)`` Motorola signals into 8 bytes, by hand.

    The DBC numbers a big-endian signal from its most significant bit, bit 7 of a byte being
    that byte's first bit on the wire; a negative raw value goes in as two's complement.
    """
    word = 0
    for start, length, raw in fields:
        first = (start // 8) * 8 + (7 - start % 8)  # position from the message's first bit
        assert -(1 << length) < raw < (1 << length)
        word |= (raw & ((1 << length) - 1)) << (64 - first - length)
    return bytearray(word.to_bytes(8, "big"))


def status(count, counter, t=0.0):
    return can.Message(arbitration_id=STATUS_ID, is_extended_id=False, timestamp=t,
                       data=motorola([(7, 8, count), (15, 16, counter), (39, 4, 1)]))


def general(obj_id, dist_long, dist_lat, vrel_long, vrel_lat, rcs, t=0.0):
    raw = [round((dist_long + 500) / 0.2), round((dist_lat + 204.6) / 0.2),
           round((vrel_long + 128) / 0.25), round((vrel_lat + 64) / 0.25),
           round((rcs + 64) / 0.5)]
    return can.Message(arbitration_id=GENERAL_ID, is_extended_id=False, timestamp=t,
                       data=motorola([(7, 8, obj_id), (15, 13, raw[0]), (18, 11, raw[1]),
                                      (39, 10, raw[2]), (45, 9, raw[3]), (50, 3, 1),
                                      (63, 8, raw[4])]))


def quality(obj_id, t=0.0):
    return can.Message(arbitration_id=QUALITY_ID, is_extended_id=False, timestamp=t,
                       data=motorola([(7, 8, obj_id), (15, 5, 3), (55, 3, 7)]))


def crc(data: bytearray) -> bytearray:
    """The checksum byte (byte 7) as docs/can-mapping.md defines it: CRC-32 of the others."""
    data[7] = zlib.crc32(bytes(data[:7])) & 0xFF
    return data


def clu_status(count, counter, t_s):
    return can.Message(arbitration_id=CLU_STATUS_ID, is_extended_id=True, timestamp=t_s,
                       data=crc(motorola([(7, 8, count), (15, 8, counter),
                                          (23, 16, round(t_s / 0.01))])))


def clu_pages(counter, idx, range_m, az_deg, vr_kmh, el_deg, rcs, t_s=0.0):
    seq = counter & 0xF
    return [can.Message(arbitration_id=CLU_DATA_ID, is_extended_id=True, timestamp=t_s,
                        data=crc(motorola([(7, 2, 0), (5, 4, seq), (1, 6, idx),
                                           (11, 14, round(range_m / 0.05)),
                                           (29, 12, round(az_deg / 0.1)),
                                           (33, 10, round(vr_kmh / 0.2))]))),
            can.Message(arbitration_id=CLU_DATA_ID, is_extended_id=True, timestamp=t_s,
                        data=crc(motorola([(7, 2, 1), (5, 4, seq), (1, 6, idx),
                                           (11, 10, round(el_deg / 0.1)),
                                           (17, 8, round((rcs + 50) / 0.5))])))]


def receive(mapping, messages):
    receiver = DetectionReceiver(CanMapping.from_file(mapping))
    got = []
    for msg in messages:
        receiver.on_message_received(msg)
        got += receiver.pop()
    return receiver, got + receiver.flush()


OBJECTS = [  # id, distance long, lat (m), velocity long, lat (m/s), RCS (dBm2)
    (17, 40.2, -3.4, -5.25, 0.5, 7.5),
    (3, 120.0, 10.2, 2.0, -1.25, -10.0),
    (200, 0.4, 0.0, -128.0, -64.0, -64.0),  # the signals' lower ends
]


def test_an_object_list_decodes_to_the_values_computed_by_hand(objects):
    messages = [status(len(OBJECTS), 65535)]
    for obj in OBJECTS:
        messages += [general(*obj), quality(obj[0])]
    receiver, got = receive(objects, messages)
    assert receiver.stats.clean
    (d,) = got
    assert d.cycle == 65535 and d.complete and d.count == 3
    for i, (_, x, y, vx, vy, rcs) in enumerate(sorted(OBJECTS)):  # in index order
        r = math.hypot(x, y)
        assert d.range_m[i] == pytest.approx(r, abs=1e-9)
        assert d.az_deg[i] == pytest.approx(math.degrees(math.atan2(y, x)), abs=1e-9)
        assert d.radial_velocity_mps[i] == pytest.approx((x * vx + y * vy) / r, abs=1e-9)
        assert d.rcs_dbsm[i] == pytest.approx(rcs, abs=1e-12)
    assert d.el_deg is None  # not mapped: not reported


def test_multiplexed_motorola_clusters_on_extended_ids_decode_to_hand_computed_values(clusters):
    rows = [(0, 35.25, -12.3, -36.0, 1.5, 10.0), (1, 801.0, 100.0, 50.4, -3.2, -20.5)]
    messages = [clu_status(2, 0x2A, 3.21)]
    for row in rows:
        messages += clu_pages(0x2A, *row)
    receiver, (d,) = receive(clusters, messages)
    assert receiver.stats.clean and d.complete and d.cycle == 42 and d.t_s == pytest.approx(3.21)
    np.testing.assert_allclose(d.range_m, [35.25, 801.0], atol=1e-9)
    np.testing.assert_allclose(d.az_deg, [-12.3, 100.0], atol=1e-9)
    np.testing.assert_allclose(d.radial_velocity_mps, [-36.0 / 3.6, 50.4 / 3.6], atol=1e-9)
    np.testing.assert_allclose(d.el_deg, [1.5, -3.2], atol=1e-9)
    np.testing.assert_allclose(d.rcs_dbsm, [10.0, -20.5], atol=1e-12)
    # One bit off in a page: its checksum fails, and the cycle is not whole.
    messages[1].data[3] ^= 0x04
    receiver, (d,) = receive(clusters, messages)
    assert receiver.stats.checksum_errors == 1 and not d.complete


def test_a_frame_of_the_other_id_format_with_a_mapped_number_is_another_ecu_s(objects):
    # Another ECU sends 29-bit identifiers 0x60A and 0x60B: the radar's messages are 11-bit
    # ones of those numbers, and the others are not its header or objects.
    cycle = [status(1, 7), general(*OBJECTS[0]), quality(OBJECTS[0][0])]
    stranger = [can.Message(arbitration_id=i, is_extended_id=True, data=bytes(range(8)))
                for i in (STATUS_ID, GENERAL_ID)]
    receiver, got = receive(objects, [cycle[0], stranger[0], cycle[1], stranger[1], cycle[2]])
    assert [(d.cycle, d.complete, d.count) for d in got] == [(7, True, 1)]
    assert receiver.stats.unknown_ids == 2
    assert (receiver.stats.conflicts, receiver.stats.duplicates, receiver.stats.orphans,
            receiver.stats.decode_errors) == (0, 0, 0, 0)


def test_a_cut_off_cycle_is_handed_on_while_its_8_bit_counter_still_names_it(clusters):
    # 300 cycles of an 8-bit counter; cycle 5 loses its last page. The receiver must hand it
    # on (incomplete) while the cycles after it can still tell where it belongs: held to the
    # end of the run, its counter came 295 cycles late and named cycle 261.
    messages = []
    for n in range(300):
        cycle = [clu_status(1, n % 256, 0.05 * n), *clu_pages(n % 256, 0, 10.0 + 0.05 * n,
                                                               1.0, 0.0, 0.0, 0.0)]
        messages += cycle[:-1] if n == 5 else cycle
    receiver, got = receive(clusters, messages)
    assert len(got) == 300
    numbers = sequential_numbers(np.array([d.cycle for d in got]), 256)
    assert sorted(numbers.tolist()) == list(range(300))
    (cut,) = [d for d, n in zip(got, numbers, strict=True) if n == 5]
    assert not cut.complete
    assert all(d.complete for d, n in zip(got, numbers, strict=True) if n != 5)
    first_ranges = {int(n): d.range_m[0] for d, n in zip(got, numbers, strict=True) if n != 5}
    assert all(r == pytest.approx(10.0 + 0.05 * n, abs=0.03) for n, r in first_ranges.items())


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_a_repeated_header_leaves_each_later_cycle_its_own_bus_time(clusters, tmp_path,
                                                                    suffix):
    # Cycle 10's header comes twice: a copy. Cycles 266 and 522 have its counter again, and
    # must each keep the time of their own header, not the copy's from 12.8 s before.
    log = tmp_path / f"drive{suffix}"
    with can.Logger(str(log)) as logger:
        for n in range(600):
            t = 100.0 + 0.05 * n
            cycle = [clu_status(1, n % 256, 0.05 * n), *clu_pages(n % 256, 0, 10.0, 1.0,
                                                                   0.0, 0.0, 0.0)]
            for msg in (cycle[:1] + cycle if n == 10 else cycle):
                msg.timestamp = t
                logger.on_message_received(msg)
    cycles, stats = read_cycles(log, CanMapping.from_file(clusters), 0.05)
    assert stats["duplicates"] == 1 and len(cycles) == 600
    # The log's own time base (ASC keeps times from its start): the headers' times as read.
    with can.LogReader(str(log)) as reader:
        stamps = [m.timestamp for m in reader if m.arbitration_id == CLU_STATUS_ID]
    del stamps[11]  # the copy
    assert np.ptp(np.diff(stamps)) < 1e-5
    np.testing.assert_allclose([c.bus_t_s for c in cycles], stamps, atol=1e-6)


def test_check_of_a_log_with_a_cut_off_cycle_fails_and_counts_it(objects, tmp_path, capsys):
    # A radar of 72 ms cycles whose cycle 20 lost an object message: the check of its log
    # (no sidecar: aligned by time) fails on the incomplete cycle; it does not refuse the log
    # as one whose timestamps go back.
    radar = yaml.safe_load((ROOT / "rts_scenario/data/radars/awr1843boost.radar.yaml")
                           .read_text())
    radar.update(name="slow-cycle", clock={"cycle_s": 0.072, "latency_s": 0.01})
    (tmp_path / "slow.radar.yaml").write_text(yaml.safe_dump(radar))
    text = (ROOT / "scenarios" / "approaching_target.scenario.yaml").read_text()
    assert "profile: awr1843boost" in text and "detection_rate: 0.95" in text
    scene = tmp_path / "approach.scenario.yaml"
    scene.write_text(text.replace("profile: awr1843boost", "profile: slow.radar.yaml").replace(
        "detection_rate: 0.95",
        "detection_rate: 0.95\n  expected_limits: [frame_rate_above_radar, quantity_unchecked]"))
    recorded = tmp_path / "drive.blf"
    assert cli.main(["run", str(scene), "--mapping", str(objects), "--record",
                     str(recorded)]) == 0
    capsys.readouterr()
    cycles = []
    for msg in can.LogReader(str(recorded)):
        if msg.arbitration_id == STATUS_ID:
            cycles.append([])
        if cycles:
            cycles[-1].append(msg)
    assert len(cycles) > 60 and all(len(c) == 3 for c in cycles[18:23])
    cycles[20] = [m for m in cycles[20] if m.arbitration_id != GENERAL_ID]
    log = tmp_path / "cut.blf"  # another tool's log: no sidecar
    with can.Logger(str(log)) as logger:
        for msg in (m for cycle in cycles for m in cycle):
            logger.on_message_received(msg)
    code = cli.main(["check", str(scene), "--log", str(log), "--mapping", str(objects)])
    out, err = capsys.readouterr()
    assert "error" not in err, err
    assert code == 1
    (fail,) = [line for line in out.splitlines() if line.startswith("FAIL")]
    assert fail.endswith("0 radar cycles missing and 1 incomplete: 1 target-cycles and the "
                         "cycles' false detections could not be checked"), fail


def test_a_remote_frame_asking_for_the_radar_s_message_is_counted_not_undecodable(objects):
    # A gateway asks for the status with a remote frame (no data, DLC 8): no data was lost,
    # so it is counted on its own and does not fail the verdict as an undecodable message.
    request = can.Message(arbitration_id=STATUS_ID, is_extended_id=False,
                          is_remote_frame=True, dlc=8)
    cycle = [status(1, 7), general(*OBJECTS[0]), quality(OBJECTS[0][0])]
    receiver, got = receive(objects, [request, *cycle, request])
    assert [(d.cycle, d.complete, d.count) for d in got] == [(7, True, 1)]
    assert receiver.stats.remote_frames == 2 and receiver.stats.decode_errors == 0
    assert not receiver.stats.clean  # visible in the report's bus counters


def test_a_dbc_saved_with_a_utf8_byte_order_mark_loads(tmp_path):
    # Editors on Windows save UTF-8 with a byte order mark; the DBC is the same.
    (tmp_path / "objects.dbc").write_bytes(b"\xef\xbb\xbf" + OBJECTS_DBC.encode()
                                           + 'CM_ BO_ 1546 "Zähler °";\n'.encode())
    (tmp_path / "objects.mapping.yaml").write_text(OBJECTS_MAPPING)
    mapping = CanMapping.from_file(tmp_path / "objects.mapping.yaml")
    assert mapping.db.get_message_by_name("Obj_0_Status").comment == "Zähler °"
