"""A production radar's protocol on a real bench: AUTOSAR E2E and SAE J1850 checksums, an alive
counter that wraps below its bit width (0..14 in 4 bits), and logs holding several CAN channels.

Every CRC here is computed by a bitwise reference written from the polynomials (and proven on
the standard check values of "123456789"), every message packed by hand from its bit layout.
"""

import re
from pathlib import Path

import can
import numpy as np
import pytest

import rts_scenario.cli as cli
from rts_scenario.canbus import DetectionPublisher, DetectionReceiver
from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.detections import Detections, sequential_numbers

ROOT = Path(__file__).resolve().parents[1]


def crc_bitwise(data, poly, init, xorout, width):
    """A non-reflected CRC, bit by bit, as the polynomial defines it."""
    crc, top, mask = init, 1 << (width - 1), (1 << width) - 1
    for byte in data:
        crc ^= byte << (width - 8)
        for _ in range(8):
            crc = ((crc << 1) ^ poly) & mask if crc & top else (crc << 1) & mask
    return crc ^ xorout


def crc8_j1850(data):
    return crc_bitwise(data, 0x1D, 0xFF, 0xFF, 8)


def crc8_h2f(data):  # AUTOSAR CRC-8 (E2E profile 2)
    return crc_bitwise(data, 0x2F, 0xFF, 0xFF, 8)


def crc16_ccitt(data):  # CRC-16/CCITT-FALSE (E2E profile 5)
    return crc_bitwise(data, 0x1021, 0xFFFF, 0x0000, 16)


def test_the_reference_crcs_give_the_standard_check_values():
    assert crc8_j1850(b"123456789") == 0x4B
    assert crc8_h2f(b"123456789") == 0xDF
    assert crc16_ccitt(b"123456789") == 0x29B1


# A radar in the AUTOSAR style: the header protected by E2E profile 2 (CRC in byte 0, the alive
# counter 0..14 in byte 1's low nibble, a DataIDList of 16), each detection by profile 5 (CRC-16
# in bytes 0-1, data ID 0x1234) with the counter's low part. All Intel.
AUTOSAR_DBC = '''VERSION ""
BU_: RADAR GW
BO_ 768 Rad_Header: 8 RADAR
 SG_ Hdr_CRC : 0|8@1+ (1,0) [0|255] "" GW
 SG_ Hdr_Alive : 8|4@1+ (1,0) [0|14] "" GW
 SG_ Hdr_Count : 16|8@1+ (1,0) [0|255] "" GW
 SG_ Hdr_Time : 24|16@1+ (0.01,0) [0|655.35] "s" GW
 SG_ Hdr_J1850 : 56|8@1+ (1,0) [0|255] "" GW
BO_ 769 Rad_Det: 8 RADAR
 SG_ Det_CRC : 0|16@1+ (1,0) [0|65535] "" GW
 SG_ Det_Alive : 16|4@1+ (1,0) [0|14] "" GW
 SG_ Det_Idx : 20|8@1+ (1,0) [0|255] "" GW
 SG_ Det_Range : 28|12@1+ (0.1,0) [0|409.5] "m" GW
 SG_ Det_Azi : 40|12@1- (0.1,0) [-204.8|204.7] "deg" GW
 SG_ Det_Vr : 52|12@1- (0.1,0) [-204.8|204.7] "m/s" GW
'''

HEADER_IDS = [0x10 + 3 * k for k in range(16)]  # profile 2's DataIDList
DET_ID = 0x1234

AUTOSAR_MAPPING = f'''rts_can_mapping: 1
name: autosar-radar
dbc: autosar.dbc
header:
  message: Rad_Header
  counter: Hdr_Alive
  counter_max: 14
  count: [Hdr_Count]
  timestamp: Hdr_Time
  checksum: {{signal: Hdr_CRC, scheme: autosar-e2e-p2, data_id: {HEADER_IDS}}}
detection:
  messages: [Rad_Det]
  frame_counter: Det_Alive
  index: Det_Idx
  checksum: {{signal: Det_CRC, scheme: autosar-e2e-p5, data_id: {DET_ID}}}
  form: polar
  range_m: Det_Range
  azimuth_deg: Det_Azi
  radial_velocity_mps: Det_Vr
'''

# The same radar with a plain CRC-8 SAE J1850 in the header's last byte instead.
J1850_MAPPING = AUTOSAR_MAPPING.replace(
    f"{{signal: Hdr_CRC, scheme: autosar-e2e-p2, data_id: {HEADER_IDS}}}",
    "{signal: Hdr_J1850, scheme: crc8-sae-j1850}")

HEADER_ID, DETECTION_ID = 768, 769


def _mapping(folder, name, text):
    """The AUTOSAR-style DBC and a mapping of it, written to ``folder``."""
    (folder / "autosar.dbc").write_text(AUTOSAR_DBC)
    path = folder / f"{name}.mapping.yaml"
    path.write_text(text)
    return path


def approach(folder):
    """approaching_target, declaring the elevation it names unchecked: the AUTOSAR-style
    radar's messages carry none (its tolerances write el_deg, so it would fail on it)."""
    path = folder / "approaching_target.scenario.yaml"
    text = (ROOT / "scenarios" / "approaching_target.scenario.yaml").read_text()
    assert "detection_rate: 0.95\n" in text
    path.write_text(text.replace("detection_rate: 0.95\n", "detection_rate: 0.95\n"
                                 "  expected_limits: [quantity_unchecked]\n"))
    return path


@pytest.fixture
def autosar(tmp_path):
    return _mapping(tmp_path, "autosar", AUTOSAR_MAPPING)


@pytest.fixture
def j1850(tmp_path):
    return _mapping(tmp_path, "j1850", J1850_MAPPING)


def header_p2(alive, count, t_s=0.0, *, stamp=0.0):
    """Rad_Header by hand, its profile 2 CRC over bytes 1..7 and the counter's data ID."""
    time_raw = round(t_s / 0.01)
    data = bytearray([0, alive & 0x0F, count, time_raw & 0xFF, time_raw >> 8, 0, 0, 0])
    data[0] = crc8_h2f(bytes(data[1:]) + bytes([HEADER_IDS[alive & 0x0F]]))
    return can.Message(arbitration_id=HEADER_ID, is_extended_id=False, data=data,
                       timestamp=stamp)


def header_j1850(alive, count, *, stamp=0.0):
    """Rad_Header by hand, its CRC-8 SAE J1850 in byte 7 over bytes 0..6."""
    data = bytearray([0, alive & 0x0F, count, 0, 0, 0, 0, 0])
    data[7] = crc8_j1850(bytes(data[:7]))
    return can.Message(arbitration_id=HEADER_ID, is_extended_id=False, data=data,
                       timestamp=stamp)


def detection_p5(alive, idx, range_m, az_deg, vr_mps, *, stamp=0.0):
    """Rad_Det by hand, its profile 5 CRC-16 (low byte first) over bytes 2..7 and the ID."""
    word = ((alive & 0xF) << 16 | idx << 20 | round(range_m / 0.1) << 28
            | (round(az_deg / 0.1) & 0xFFF) << 40 | (round(vr_mps / 0.1) & 0xFFF) << 52)
    data = bytearray(word.to_bytes(8, "little"))
    crc = crc16_ccitt(bytes(data[2:]) + bytes([DET_ID & 0xFF, DET_ID >> 8]))
    data[0], data[1] = crc & 0xFF, crc >> 8
    return can.Message(arbitration_id=DETECTION_ID, is_extended_id=False, data=data,
                       timestamp=stamp)


def receive(mapping, messages):
    receiver = DetectionReceiver(CanMapping.from_file(mapping))
    got = []
    for msg in messages:
        receiver.on_message_received(msg)
        got += receiver.pop()
    return receiver, got + receiver.flush()


def test_hand_packed_e2e_protected_messages_decode_to_their_values(autosar):
    messages = [header_p2(9, 2, 12.34),
                detection_p5(9, 0, 40.2, -12.5, -5.3),
                detection_p5(9, 1, 120.0, 30.1, 2.0)]
    receiver, got = receive(autosar, messages)
    assert receiver.stats.checksum_errors == 0 and receiver.stats.decode_errors == 0
    (cycle,) = got
    assert cycle.complete and cycle.cycle == 9 and cycle.t_s == pytest.approx(12.34)
    np.testing.assert_allclose(cycle.range_m, [40.2, 120.0], atol=1e-9)
    np.testing.assert_allclose(cycle.az_deg, [-12.5, 30.1], atol=1e-9)
    np.testing.assert_allclose(cycle.radial_velocity_mps, [-5.3, 2.0], atol=1e-9)


def test_a_profile_2_header_is_checked_with_the_data_id_of_its_counter(autosar):
    # The CRC of alive 9 computed with the data ID of alive 8: not this message's.
    good = header_p2(9, 0)
    wrong_id = bytearray(good.data)
    wrong_id[0] = crc8_h2f(bytes(wrong_id[1:]) + bytes([HEADER_IDS[8]]))
    assert wrong_id[0] != good.data[0]
    receiver, got = receive(autosar, [
        can.Message(arbitration_id=HEADER_ID, is_extended_id=False, data=wrong_id), good])
    assert receiver.stats.checksum_errors == 1
    assert [c.cycle for c in got] == [9]


def test_a_damaged_byte_fails_each_scheme_s_checksum(autosar, j1850):
    for mapping, header in ((autosar, header_p2(3, 1)), (j1850, header_j1850(3, 1))):
        detection = detection_p5(3, 0, 50.0, 1.0, 0.0)
        damaged = [bytearray(m.data) for m in (header, detection)]
        for data in damaged:
            data[3] ^= 0x04  # one bit of the payload
        receiver, got = receive(mapping, [
            can.Message(arbitration_id=m.arbitration_id, is_extended_id=False, data=d)
            for m, d in zip((header, detection), damaged, strict=True)])
        assert receiver.stats.checksum_errors == 2, mapping
        assert got == []
        receiver, got = receive(mapping, [header, detection])
        assert receiver.stats.checksum_errors == 0 and [c.complete for c in got] == [True]


def test_a_hand_packed_j1850_header_decodes(j1850):
    receiver, got = receive(j1850, [header_j1850(14, 1), detection_p5(14, 0, 7.5, 0.0, 0.0)])
    assert receiver.stats.checksum_errors == 0
    (cycle,) = got
    assert cycle.complete and cycle.cycle == 14
    np.testing.assert_allclose(cycle.range_m, [7.5])


class Capture:
    """A bus that keeps what is sent."""

    def __init__(self):
        self.messages: list[can.Message] = []

    def send(self, msg):
        self.messages.append(msg)


def cycles(n, per_cycle=2):
    rng = np.random.default_rng(3)
    return [Detections(cycle=k, t_s=0.05 * k, range_m=rng.uniform(5, 80, per_cycle),
                       radial_velocity_mps=rng.uniform(-20, 20, per_cycle),
                       az_deg=rng.uniform(-40, 40, per_cycle), el_deg=np.zeros(per_cycle))
            for k in range(n)]


@pytest.mark.parametrize("which", ["autosar", "j1850"])
def test_the_simulated_radar_speaking_the_mapping_computes_the_same_checksums(which, request):
    mapping = request.getfixturevalue(which)
    bus = Capture()
    sent = cycles(40)
    DetectionPublisher(bus, mapping=CanMapping.from_file(mapping)).publish_many(sent)
    headers = [m for m in bus.messages if m.arbitration_id == HEADER_ID]
    detections = [m for m in bus.messages if m.arbitration_id == DETECTION_ID]
    assert len(headers) == 40 and len(detections) == 80
    for k, msg in enumerate(headers):
        data = bytes(msg.data)
        assert data[1] & 0x0F == k % 15  # the alive counter wraps after 14
        if which == "autosar":
            assert data[0] == crc8_h2f(data[1:] + bytes([HEADER_IDS[k % 15]]))
        else:
            assert data[7] == crc8_j1850(data[:7])
    for j, msg in enumerate(detections):
        data = bytes(msg.data)
        assert (data[2] & 0x0F) == (j // 2) % 15
        crc = crc16_ccitt(data[2:] + bytes([DET_ID & 0xFF, DET_ID >> 8]))
        assert (data[0], data[1]) == (crc & 0xFF, crc >> 8)
    receiver, got = receive(mapping, bus.messages)
    stats = receiver.stats
    assert (stats.checksum_errors, stats.decode_errors, stats.reordered, stats.duplicates,
            stats.conflicts, stats.orphans) == (0, 0, 0, 0, 0, 0)
    assert [c.cycle for c in got] == [k % 15 for k in range(40)]
    assert all(c.complete for c in got)
    for c, s in zip(got, sent, strict=True):
        np.testing.assert_allclose(c.range_m, s.range_m, atol=0.05 + 1e-9)


def test_a_counter_wrapping_after_14_steps_from_14_to_0(autosar):
    mapping = CanMapping.from_file(autosar)
    assert mapping.counter_modulus == 15
    alive = [12, 13, 14, 0, 1, 2]
    receiver, got = receive(autosar, [header_p2(a, 0) for a in alive])
    assert (receiver.stats.reordered, receiver.stats.duplicates) == (0, 0)
    assert [c.cycle for c in got] == alive


def test_a_counter_wrapping_after_14_tells_reordered_and_copied_cycles_over_the_wrap(autosar):
    # 0 comes after 1 (one step back over the wrap), then 14 again with the same content.
    receiver, got = receive(autosar, [header_p2(a, 0) for a in (13, 14, 1, 0, 2, 14)])
    assert receiver.stats.reordered == 1  # 0, one step behind 1
    assert receiver.stats.duplicates == 1  # 14 again, within the cycles remembered
    assert [c.cycle for c in got] == [13, 14, 1, 0, 2]


def test_a_header_seven_back_on_a_counter_wrapping_after_14_is_behind_not_a_new_cycle(autosar):
    # Fifteen values: a step is -7..7, so a counter seven before the latest is behind it (and
    # one seven after is ahead). Cycles 0..7, then 0 again: a copy of the cycle seven back.
    # Then 8..11, cycle 9's header held up behind 10's (one back): reordered.
    sent = [*range(8), 0, 8, 10, 9, 11]
    receiver, got = receive(autosar, [header_p2(a, 0) for a in sent])
    assert receiver.stats.duplicates == 1
    assert receiver.stats.reordered == 1  # 9 only
    assert [c.cycle for c in got] == [*range(9), 10, 9, 11]
    # A cycle seen for the first time seven back (0 after 1..7) is late, not the next one:
    # the latest stays 7, and 8 is one step on from it.
    receiver, got = receive(autosar, [header_p2(a, 0) for a in (*range(1, 8), 0, 8)])
    assert receiver.stats.reordered == 1 and receiver.stats.duplicates == 0
    assert [c.cycle for c in got] == [*range(1, 8), 0, 8]


def test_a_counter_of_sixteen_values_keeps_a_step_of_eight_forward(tmp_path):
    # Sixteen values: a step is -7..8; a counter eight before the latest is eight after it, a
    # new cycle, and seven before is behind.
    path = _mapping(tmp_path, "sixteen", AUTOSAR_MAPPING.replace("  counter_max: 14\n", ""))
    assert CanMapping.from_file(path).counter_modulus == 16
    receiver, got = receive(path, [header_p2(a, 0) for a in (*range(9), 0)])
    assert (receiver.stats.duplicates, receiver.stats.reordered) == (0, 0)
    assert [c.cycle for c in got] == [*range(9), 0]
    receiver, got = receive(path, [header_p2(a, 0) for a in (*range(8), 0)])
    assert (receiver.stats.duplicates, receiver.stats.reordered) == (1, 0)


def _counter(tmp_path, counter_max):
    """The J1850 radar's mapping with its counter wrapping after ``counter_max`` (None: the
    4-bit signal's width, 16 values)."""
    line = "" if counter_max is None else f"  counter_max: {counter_max}\n"
    return _mapping(tmp_path, f"max{counter_max}",
                    J1850_MAPPING.replace("  counter_max: 14\n", line))


@pytest.mark.parametrize(("counter_max", "modulus"), [(14, 15), (None, 16)])
def test_an_incomplete_cycle_handed_on_late_is_no_copy_of_a_new_cycle_after_lost_headers(
        tmp_path, counter_max, modulus):
    # Cycle 0 announces a detection that never comes: it waits for it while the next cycles
    # come (3 on 15 values, 4 on 16), then goes on incomplete, after them. Cycles 1..8 are
    # whole; then the headers up to the wrap are lost, and 0 is 7 (15 values) or 8 (16) on
    # from 8: a new cycle, as it would be had the first 0 been whole. So is 1 after it.
    path = _counter(tmp_path, counter_max)
    assert CanMapping.from_file(path).counter_modulus == modulus
    receiver, got = receive(path, [header_j1850(0, 1), *(header_j1850(a, 0) for a in range(1, 9)),
                                   header_j1850(0, 0), header_j1850(1, 0)])
    assert (receiver.stats.duplicates, receiver.stats.reordered,
            receiver.stats.conflicts) == (0, 0, 0)
    assert [c.cycle for c in got if not c.complete] == [0]
    assert [c.cycle for c in got if c.complete] == [*range(1, 9), 0, 1]


def test_an_incomplete_cycle_on_a_counter_of_four_values_is_no_copy_after_a_lost_header(
        tmp_path):
    # Four values: a step is -1..2. Cycle 0 is incomplete and goes on once 1 came; 2 is lost,
    # and 3 is two on from 1. Then 0 is one on from 3: a new cycle, not the old 0 again.
    path = _counter(tmp_path, 3)
    receiver, got = receive(path, [header_j1850(0, 1), *(header_j1850(a, 0) for a in (1, 3, 0, 1))])
    assert (receiver.stats.duplicates, receiver.stats.reordered,
            receiver.stats.conflicts) == (0, 0, 0)
    assert [(c.cycle, c.complete) for c in got] == [(1, True), (0, False), (3, True),
                                                    (0, True), (1, True)]


def test_an_incomplete_cycle_the_counter_left_behind_in_one_jump_goes_on(tmp_path):
    # Sixteen values: cycle 0 is incomplete, still waited for when 3 comes (3 back); 7 headers
    # are lost and 11 comes, 8 on from 3. 0 is no longer behind 11 (5 ahead of it): it goes
    # on incomplete, and the 0 of the next lap is a new cycle, not a conflicting header.
    path = _counter(tmp_path, None)
    receiver, got = receive(path, [header_j1850(0, 1),
                                   *(header_j1850(a, 0) for a in (3, *range(11, 16), 0))])
    assert (receiver.stats.duplicates, receiver.stats.reordered,
            receiver.stats.conflicts) == (0, 0, 0)
    assert [(c.cycle, c.complete) for c in got] == [(3, True), (11, True), (0, False),
                                                    *((a, True) for a in (12, 13, 14, 15, 0))]


def _timed(path, headers):
    """Receive headers ``(counter, bus time)`` of 50 ms cycles; return the receiver and the
    cycles."""
    receiver = DetectionReceiver(CanMapping.from_file(path), cycle_s=0.05)
    got = []
    for alive, t in headers:
        receiver.on_message_received(header_j1850(alive, 0, stamp=t))
        got += receiver.pop()
    return receiver, got + receiver.flush()


@pytest.mark.parametrize("counter_max", [3, 4, None])
def test_a_header_again_a_millisecond_on_is_a_copy_on_a_counter_of_few_values(tmp_path,
                                                                              counter_max):
    # 50 ms cycles: headers 0, 1, 2, then 2 again 1 ms on, then 3. On a counter of 4 or 5
    # values as on one of 16, a gap of 1 ms is no silence after which every counter is new:
    # the second 2 is a copy.
    receiver, got = _timed(_counter(tmp_path, counter_max),
                           [(0, 0.0), (1, 0.05), (2, 0.10), (2, 0.101), (3, 0.15)])
    assert [c.cycle for c in got] == [0, 1, 2, 3]
    assert (receiver.stats.duplicates, receiver.stats.reordered) == (1, 0)


@pytest.mark.parametrize(("counter_max", "modulus"), [(3, 4), (4, 5)])
def test_on_a_counter_of_few_values_a_gap_over_two_cycles_is_told_by_its_time_alike(
        tmp_path, counter_max, modulus):
    # Headers 0 and 1, then cycles 2 and 3 are lost: 4's header, 3 cycles after 1's, carries
    # 0 (4 values, one back from 1 by the counter) or 4 (5 values, two back). Its time tells
    # it: a new cycle three on, live and in the re-check's numbering.
    path = _counter(tmp_path, counter_max)
    headers = [(0, 0.0), (1, 0.05), (4 % modulus, 0.20)]
    receiver, got = _timed(path, headers)
    assert [c.cycle for c in got] == [0, 1, 4 % modulus]
    assert (receiver.stats.duplicates, receiver.stats.reordered) == (0, 0)
    numbers = sequential_numbers(np.array([c for c, _ in headers]), modulus,
                                 np.array([t for _, t in headers]), 0.05)
    assert list(numbers) == [0, 1, 4]


def test_a_header_held_up_a_cycle_on_a_counter_of_four_values_is_reordered_alike(tmp_path):
    # 50 ms cycles: cycle 1's header is held up behind 2's and comes 1.2 cycles after it. A gap
    # of 2 cycles or less is no silence, whatever the counter's range: by the counter, 1 is
    # one back from 2, a reordered cycle, live and in the re-check's numbering (not three
    # cycles on, as the time alone would have it).
    headers = [(0, 0.0), (2, 0.10), (1, 0.16)]
    receiver, got = _timed(_counter(tmp_path, 3), headers)
    assert [c.cycle for c in got] == [0, 2, 1]
    assert (receiver.stats.duplicates, receiver.stats.reordered) == (0, 1)
    numbers = sequential_numbers(np.array([c for c, _ in headers]), 4,
                                 np.array([t for _, t in headers]), 0.05)
    assert list(numbers) == [0, 2, 1]


def test_a_counter_wrapping_after_14_restarts_within_seven_steps_either_way(autosar):
    # The restart's counter 0 on 15 values: up to seven cycles counting on from it (1..7)
    # are the stream's own, its first header held up behind them; a cycle up to seven before
    # it (8, seven before 0) leads up to it (a radar measuring before the stream's start);
    # cycles ahead of it that do not count on from it (5; 3 and 4) are the stream before's,
    # dropped.
    receiver = DetectionReceiver(CanMapping.from_file(autosar))
    for before, order, dropped in (([], [*range(1, 8), 0, *range(8, 12)], 0),
                                   ([8], [0, 1, 2], 0),
                                   ([5], [0, 1, 2], 1),
                                   ([3, 4], [0, 1, 2], 2)):
        receiver.reset(restart=0)
        got = []
        for a in [*before, *order]:
            receiver.on_message_received(header_p2(a, 0))
            got += receiver.pop()
        got += receiver.flush()
        assert sorted(c.cycle for c in got) == sorted([*before, *order][dropped:]), before
        assert receiver.stale_cycles == dropped, before
    assert (receiver.stats.duplicates, receiver.stats.conflicts) == (0, 0)


def test_the_invalid_value_15_of_a_counter_wrapping_after_14_is_refused(autosar):
    receiver, got = receive(autosar, [header_p2(14, 0), header_p2(15, 0), header_p2(0, 0)])
    assert receiver.stats.decode_errors == 1
    assert [c.cycle for c in got] == [14, 0]
    assert receiver.stats.reordered == 0


def test_counter_max_dbc_takes_the_signal_s_maximum(tmp_path):
    (tmp_path / "autosar.dbc").write_text(AUTOSAR_DBC)
    path = tmp_path / "m.mapping.yaml"
    path.write_text(AUTOSAR_MAPPING.replace("counter_max: 14", "counter_max: dbc"))
    assert CanMapping.from_file(path).counter_modulus == 15
    path.write_text(AUTOSAR_MAPPING.replace("  counter_max: 14\n", ""))
    assert CanMapping.from_file(path).counter_modulus == 16  # the width, as before


def test_a_run_and_its_recheck_pass_with_e2e_checksums_and_a_counter_wrapping_after_14(
        autosar, tmp_path, capsys):
    scene = approach(tmp_path)
    log = tmp_path / "drive.blf"
    assert cli.main(["run", str(scene), "--mapping", str(autosar), "--record", str(log)]) == 0
    out = capsys.readouterr().out
    assert "checksum" not in out, out
    headers = [m for m in can.LogReader(str(log)) if m.arbitration_id == HEADER_ID]
    assert len(headers) > 30  # over the counter's wrap, twice at least
    assert cli.main(["check", str(scene), "--log", str(log)]) == 0, capsys.readouterr().out


def test_an_after_scene_cycle_whose_counter_comes_again_counts_alike_live_and_re_checked(
        autosar, tmp_path):
    # After the scene's 150 cycles the radar sends cycles 150..157, then cycle 150's messages
    # again. A counter wrapping after 14 reads 150 (alive 0) after 157 (alive 7) as seven
    # steps back, and the receiver remembers the latest counter and the seven before it: its
    # header and detections are copies (duplicates), the detections also parts of a cycle
    # before the latest (reordered). The first five (150..154) are measured within the window
    # after the scene's end: five after_scene and none repeated, live and in the re-check of
    # the recording.
    import dataclasses

    from rts_scenario.pipeline import Pipeline, RunOptions
    from rts_scenario.recheck import check_log
    from rts_scenario.scenario import load_scenario

    scene = load_scenario(approach(tmp_path))
    log = tmp_path / "drive.blf"
    options = RunOptions(mapping=str(autosar), bus_log=str(log))
    copied = []
    with Pipeline.for_scene(scene, options) as pipeline:
        sink = pipeline.output._sink

        def with_copy_after_the_scene(cycles):
            if cycles and cycles[-1].cycle == 149:
                last = cycles[-1]
                copied.append(last.count)
                after = [dataclasses.replace(last, cycle=150 + k, t_s=last.t_s + 0.05 * (k + 1))
                         for k in range(8)]
                cycles = [*cycles, *after, after[0]]
            sink(cycles)

        pipeline.output._sink = with_copy_after_the_scene
        live = pipeline.run(scene).report
    again = check_log(scene, log).report
    for report in (live, again):
        assert report.frames["total"] == report.frames["checked"] == 150
        assert (report.frames["after_scene"], report.frames["repeated"]) == (5, 0)
        assert report.bus["duplicates"] == 1 + copied[0]
        assert report.bus["reordered"] == copied[0]
        assert report.bus["conflicts"] == 0
        assert report.passed, report.reasons
    assert again.frames == live.frames


def _live_and_re_checked(autosar, tmp_path, monkeypatch, *, copy_before=None, lost=()):
    """Run the approaching target with the AUTOSAR-style radar, recording its bus, and
    re-check the recording: return both reports and the messages of each cycle sent.

    ``copy_before``: (k, j): cycle j's messages go on the bus again just before cycle k's
    header (a gateway repeating them). ``lost``: cycles that never reach the bus.
    """
    from rts_scenario.canbus import ListenerBus
    from rts_scenario.pipeline import Pipeline, RunOptions
    from rts_scenario.recheck import check_log
    from rts_scenario.scenario import load_scenario

    sent: list[list[can.Message]] = []

    class Repeating(ListenerBus):
        def send(self, msg, timeout=None):
            if msg.arbitration_id == HEADER_ID:
                if copy_before is not None and len(sent) == copy_before[0]:
                    for old in sent[copy_before[1]]:
                        super().send(can.Message(
                            arbitration_id=old.arbitration_id, is_extended_id=False,
                            data=old.data, timestamp=msg.timestamp - 0.001))
                sent.append([])
            sent[-1].append(msg)
            super().send(msg)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", Repeating)
    scene = load_scenario(approach(tmp_path))
    log = tmp_path / "drive.blf"
    with Pipeline.for_scene(scene, RunOptions(mapping=str(autosar), bus_log=str(log))) as run:
        sink = run.output._sink
        run.output._sink = lambda cycles: sink([c for c in cycles if c.cycle not in lost])
        live = run.run(scene).report
    return live, check_log(scene, log).report, sent


def test_a_cycle_repeated_seven_back_on_a_counter_wrapping_after_14_is_a_copy_live_and_re_checked(
        autosar, tmp_path, monkeypatch):
    # Cycle 20's messages come again just before cycle 28's header: alive 5 after alive 12,
    # seven back on a counter of 15 values. Every message of it is a copy (duplicates), its
    # detections parts of a cycle before the latest too (reordered messages; no cycle came
    # late); no cycle is numbered anew: the 150 cycles are all checked and none is repeated
    # or missing, live and in the re-check of the recording.
    live, again, sent = _live_and_re_checked(autosar, tmp_path, monkeypatch,
                                             copy_before=(28, 20))
    assert [m.data[1] & 0x0F for m in (sent[20][0], sent[27][0])] == [5, 12]
    for report in (live, again):
        assert report.frames["total"] == report.frames["checked"] == 150
        assert (report.frames["missing"], report.frames["repeated"],
                report.frames["after_scene"]) == (0, 0, 0)
        assert report.bus["duplicates"] == len(sent[20])
        assert report.bus["reordered"] == len(sent[20]) - 1
        assert report.frames["late"] == 0  # cycles; reordered counts messages
        assert report.bus["conflicts"] == 0
        assert report.passed, report.reasons
    assert again.frames == live.frames
    assert again.bus["duplicates"] == live.bus["duplicates"]
    assert again.bus["reordered"] == live.bus["reordered"]


def test_a_counter_wrapping_after_14_jumping_seven_on_is_six_missing_cycles_live_and_re_checked(
        autosar, tmp_path, monkeypatch):
    # Cycles 21..26 never come: alive 12 (cycle 27) follows alive 5 (cycle 20), seven steps on
    # on a counter of 15 values. Six cycles are missing, the other 144 checked, live and in
    # the re-check of the recording.
    live, again, sent = _live_and_re_checked(autosar, tmp_path, monkeypatch,
                                             lost=range(21, 27))
    assert [m[0].data[1] & 0x0F for m in sent[20:22]] == [5, 12]
    for report in (live, again):
        assert report.frames["total"] == 150
        assert (report.frames["missing"], report.frames["checked"]) == (6, 144)
        assert (report.frames["repeated"], report.frames["late"]) == (0, 0)
        assert report.bus["duplicates"] == report.bus["reordered"] == 0
    assert again.frames == live.frames


# A radar whose alive counter runs 1 to 14 (0 and 15 are never sent), header and detections.
ONE_BASED_DBC = AUTOSAR_DBC.replace("Hdr_Alive : 8|4@1+ (1,0) [0|14]",
                                    "Hdr_Alive : 8|4@1+ (1,0) [1|14]")
ONE_BASED_MAPPING = AUTOSAR_MAPPING.replace("  counter_max: 14\n",
                                            "  counter_min: 1\n  counter_max: 14\n")


@pytest.fixture
def one_based(tmp_path):
    (tmp_path / "autosar.dbc").write_text(ONE_BASED_DBC)
    path = tmp_path / "one_based.mapping.yaml"
    path.write_text(ONE_BASED_MAPPING)
    return path


def test_a_counter_running_1_to_14_steps_from_14_to_1(one_based):
    mapping = CanMapping.from_file(one_based)
    assert mapping.counter_modulus == 14
    alive = [1 + k % 14 for k in range(40)]  # 14 -> 1 is one step, twice
    messages = []
    for k, a in enumerate(alive):
        messages += [header_p2(a, 1, stamp=0.05 * k), detection_p5(a, 0, 10.0 + k, 0.0, 0.0,
                                                                    stamp=0.05 * k)]
    receiver, got = receive(one_based, messages)
    assert receiver.stats.clean, receiver.stats
    assert all(c.complete for c in got) and len(got) == 40
    # The cycles count from the counter's first value: 1 is 0, 14 is 13.
    assert [c.cycle for c in got] == [a - 1 for a in alive]
    from rts_scenario.detections import sequential_numbers

    steps = sequential_numbers(np.array([c.cycle for c in got]), mapping.counter_modulus,
                               0.05 * np.arange(40), 0.05)
    np.testing.assert_array_equal(steps, np.arange(40))  # no cycle lost at the wraps
    np.testing.assert_allclose([c.range_m[0] for c in got], 10.0 + np.arange(40))
    # 0 and 15 are values it never takes: refused.
    receiver, got = receive(one_based, [header_p2(14, 0), header_p2(0, 0), header_p2(15, 0),
                                        header_p2(1, 0)])
    assert receiver.stats.decode_errors == 2 and [c.cycle for c in got] == [13, 0]


def test_the_simulated_radar_counts_1_to_14(one_based):
    mapping = CanMapping.from_file(one_based)
    recorder = Recorder()
    publisher = DetectionPublisher(recorder, mapping=mapping)
    publisher.publish_many([Detections(cycle=k, t_s=0.05 * k, range_m=np.array([20.0]),
                                       az_deg=np.zeros(1), radial_velocity_mps=np.zeros(1))
                            for k in range(30)])
    db = mapping.db
    alive = [db.decode_message(m.arbitration_id, m.data, scaling=False)
             for m in recorder]
    assert [a["Hdr_Alive"] for a in alive if "Hdr_Alive" in a] == [1 + k % 14
                                                                  for k in range(30)]
    assert [a["Det_Alive"] for a in alive if "Det_Alive" in a] == [1 + k % 14
                                                                  for k in range(30)]


def test_a_run_and_its_recheck_pass_with_a_counter_running_1_to_14(one_based, tmp_path,
                                                                     capsys):
    scene = approach(tmp_path)
    log = tmp_path / "drive.blf"
    assert cli.main(["run", str(scene), "--mapping", str(one_based), "--record",
                     str(log)]) == 0, capsys.readouterr().out
    capsys.readouterr()
    alive = [m.data[1] & 0x0F for m in can.LogReader(str(log)) if m.arbitration_id == HEADER_ID]
    assert len(alive) > 30 and set(alive) == set(range(1, 15))
    assert cli.main(["check", str(scene), "--log", str(log)]) == 0, capsys.readouterr().out


def test_counter_min_dbc_takes_the_signal_s_minimum(tmp_path):
    (tmp_path / "autosar.dbc").write_text(ONE_BASED_DBC)
    path = tmp_path / "m.mapping.yaml"
    path.write_text(ONE_BASED_MAPPING.replace("counter_min: 1", "counter_min: dbc"))
    assert CanMapping.from_file(path).counter_modulus == 14
    # Without counter_max, the counter runs to what its bits carry: 1 to 15.
    path.write_text(ONE_BASED_MAPPING.replace("  counter_max: 14\n", ""))
    assert CanMapping.from_file(path).counter_modulus == 15


class Recorder(list):
    """A ``send`` target that keeps the messages."""

    send = list.append


BAD = [
    ("counter-max-beyond-width", ("counter_max: 14", "counter_max: 16"), "header.counter_max",
     r"got 16: the 4-bit signal 'Hdr_Alive' counts to 15 at most; allowed: 3 to 15"),
    ("counter-min-not-below-max", ("counter_max: 14", "counter_min: 14\n  counter_max: 14"),
     "header.counter_min", r"got 14: the counter must take 4 values at least, from "
                           r"counter_min to 14 \(counter_max\): with fewer, the header after "
                           r"one lost cycle cannot be told from a copy of a cycle before; "
                           r"allowed: 0 to 11, or dbc"),
    # A counter of 2 or 3 values takes one lost cycle's header for a copy of a cycle before.
    ("counter-max-three-values", ("counter_max: 14", "counter_max: 2"), "header.counter_max",
     r"got 2: the counter must take 4 values at least, from 0 to counter_max: with fewer, "
     r"the header after one lost cycle cannot be told from a copy of a cycle before; "
     r"allowed: 3 to 15, or dbc"),
    ("counter-max-two-values", ("counter_max: 14", "counter_max: 1"), "header.counter_max",
     r"got 1: the counter must take 4 values at least"),
    ("counter-max-dbc-three-values", (("counter_max: 14", "counter_max: dbc"),
                                      ("[0|14]", "[0|2]")), "header.counter_max",
     r"dbc: the DBC states no whole maximum from 3 to 15"),
    ("counter-min-three-values", ("counter_max: 14", "counter_min: 1\n  counter_max: 3"),
     "header.counter_min", r"got 1: the counter must take 4 values at least, from "
                           r"counter_min to 3 \(counter_max\): with fewer, the header after "
                           r"one lost cycle cannot be told from a copy of a cycle before; "
                           r"allowed: 0 to 0, or dbc"),
    ("counter-of-one-bit", (("  counter_max: 14\n", ""),
                            ("Hdr_Alive : 8|4@1+ (1,0) [0|14]", "Hdr_Alive : 8|1@1+ (1,0) [0|1]")),
     "header.counter", r"got 'Hdr_Alive': the 1-bit signal takes 2 values; a counter must "
                       r"take 4 at least: with fewer, the header after one lost cycle cannot "
                       r"be told from a copy of a cycle before$"),
    ("counter-min-negative", ("counter_max: 14", "counter_min: -1\n  counter_max: 14"),
     "header.counter_min", r"must be >= 0, got -1"),
    ("counter-min-dbc-without-minimum", (("counter_max: 14",
                                          "counter_min: dbc\n  counter_max: 14"),
                                         ("[0|14]", "[-0.5|14]")), "header.counter_min",
     r"dbc: the DBC states no whole minimum from 0 to 11"),
    ("counter-max-dbc-without-maximum", (("counter_max: 14", "counter_max: dbc"),
                                         ("[0|14]", "[0|0]")), "header.counter_max",
     r"dbc: the DBC states no whole maximum from 3 to 15"),
    ("unknown-scheme", ("scheme: autosar-e2e-p5", "scheme: crc16"),
     "detection.checksum.scheme", r"got 'crc16'; allowed values: 'crc32-low-byte', "
                                  r"'crc8-sae-j1850', 'autosar-e2e-p2', 'autosar-e2e-p5'$"),
    ("p2-not-in-byte-0", ("signal: Hdr_CRC, scheme: autosar-e2e-p2",
                          "signal: Hdr_J1850, scheme: autosar-e2e-p2"), "header.checksum",
     r"signal 'Hdr_J1850' of message 'Rad_Header' must fill its bytes to be a checksum "
     r"of scheme autosar-e2e-p2 \(byte 0: "),
    ("p5-on-a-byte", ("signal: Det_CRC, scheme: autosar-e2e-p5",
                      "signal: Det_Idx, scheme: autosar-e2e-p5"), "detection.checksum",
     r"signal 'Det_Idx' of message 'Rad_Det' must fill its bytes to be a checksum "
     r"of scheme autosar-e2e-p5 \(bytes 0 and 1: 16 unsigned bits from bit 0 Intel"),
    ("e2e-without-data-id", (f", data_id: {DET_ID}}}", "}"), "detection.checksum",
     r"scheme autosar-e2e-p5 needs data_id"),
    ("data-id-for-j1850", ("scheme: autosar-e2e-p2", "scheme: crc8-sae-j1850"),
     "header.checksum.data_id", r"scheme crc8-sae-j1850 takes no data ID"),
    ("p5-data-id-list", (f"data_id: {DET_ID}", f"data_id: {HEADER_IDS}"),
     "detection.checksum.data_id", r"scheme autosar-e2e-p5 takes one data ID"),
    ("p2-data-id-too-big", (f"data_id: {HEADER_IDS}", "data_id: 300"),
     "header.checksum.data_id", r"got 300: a data ID of scheme autosar-e2e-p2 is 0 to 255"),
    ("data-id-of-another-message", (f"data_id: {DET_ID}", "data_id: {Rad_Header: 5}"),
     "detection.checksum.data_id.Rad_Header",
     r"message 'Rad_Header' carries no checksum 'Det_CRC'; messages: Rad_Det"),
]


@pytest.mark.parametrize(("changes", "key", "pattern"), [c[1:] for c in BAD],
                         ids=[c[0] for c in BAD])
def test_a_bad_checksum_or_counter_entry_is_one_located_error(tmp_path, capsys, changes, key,
                                                              pattern):
    dbc, mapping = AUTOSAR_DBC, AUTOSAR_MAPPING
    for old, new in (changes if isinstance(changes[0], tuple) else [changes]):
        assert old in dbc + mapping, old
        dbc, mapping = dbc.replace(old, new), mapping.replace(old, new)
    (tmp_path / "autosar.dbc").write_text(dbc)
    path = tmp_path / "bad.mapping.yaml"
    path.write_text(mapping)
    code = cli.main(["run", str(ROOT / "scenarios" / "cut_in.scenario.yaml"),
                     "--mapping", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    lines = [line for line in err.splitlines() if "error: " in line]
    assert len(lines) == 1, err
    message = lines[0].split("error: ", 1)[1]
    assert re.match(rf"--mapping {re.escape(str(path))}:\d+:\d+: {re.escape(key)}: {pattern}",
                    message), message


# --- logs of a bench with several CAN channels ----------------------------------------------

def resealed(msg, channel, shift):
    """The message as another radar of the family sends it on another bus: its counter
    ``shift`` cycles on (within 0..14), its checksum computed again, on ``channel``."""
    data = bytearray(msg.data)
    if msg.arbitration_id == HEADER_ID:
        data[1] = (data[1] & 0xF0) | ((data[1] & 0x0F) + shift) % 15
        data[0] = crc8_h2f(bytes(data[1:]) + bytes([HEADER_IDS[data[1] & 0x0F]]))
    else:
        data[2] = (data[2] & 0xF0) | ((data[2] & 0x0F) + shift) % 15
        crc = crc16_ccitt(bytes(data[2:]) + bytes([DET_ID & 0xFF, DET_ID >> 8]))
        data[0], data[1] = crc & 0xFF, crc >> 8
    return can.Message(arbitration_id=msg.arbitration_id, is_extended_id=False, data=data,
                       timestamp=msg.timestamp + 0.003, channel=channel)


def write_log(path, messages):
    with can.Logger(str(path)) as logger:
        for msg in sorted(messages, key=lambda m: m.timestamp):
            logger.on_message_received(msg)


def two_channel_log(path, messages):
    """The radar's messages on channel 0 and a sibling's, same identifiers, on channel 1."""
    mine = [can.Message(arbitration_id=m.arbitration_id, is_extended_id=m.is_extended_id,
                        data=m.data, timestamp=m.timestamp, channel=0) for m in messages]
    write_log(path, mine + [resealed(m, 1, 5) for m in messages])


def test_a_channel_of_a_log_is_read_alone(autosar, tmp_path):
    messages = []
    for k in range(20):
        messages += [header_p2(k % 15, 1, stamp=0.05 * k),
                     detection_p5(k % 15, 0, 10.0 + k, 0.0, 0.0, stamp=0.05 * k)]
    log = tmp_path / "bench.blf"
    two_channel_log(log, messages)
    from rts_scenario.recheck import read_cycles

    mapping = CanMapping.from_file(autosar)
    cycles, stats = read_cycles(log, mapping, 0.05, channel="0")
    assert [c.detections.cycle for c in cycles] == [k % 15 for k in range(20)]
    assert all(c.detections.complete for c in cycles)
    np.testing.assert_allclose([c.detections.range_m[0] for c in cycles],
                               [10.0 + k for k in range(20)])
    assert stats["other_channels"] == 40
    assert (stats["duplicates"], stats["conflicts"], stats["reordered"]) == (0, 0, 0)
    # Read whole, the sibling's cycles join the radar's.
    _, mixed = read_cycles(log, mapping, 0.05)
    assert mixed["conflicts"] + mixed["duplicates"] + mixed["reordered"] > 0


@pytest.fixture
def recorded(autosar, tmp_path, capsys):
    scene = approach(tmp_path)
    log = tmp_path / "drive.blf"
    assert cli.main(["run", str(scene), "--mapping", str(autosar), "--record", str(log)]) == 0
    capsys.readouterr()
    return scene, log


def test_run_record_keeps_the_channel_it_listened_on(recorded):
    import json

    _, log = recorded
    sidecar = json.loads(Path(f"{log}.rts.json").read_text())
    assert sidecar["can_interface"] == "virtual"
    assert sidecar["can_channel"].startswith("rts-scenario-")


def test_check_of_a_log_with_the_radar_s_identifiers_on_two_channels(recorded, autosar,
                                                                     tmp_path, capsys):
    scene, log = recorded
    messages = list(can.LogReader(str(log)))
    n = len([m for m in messages if m.arbitration_id in (HEADER_ID, DETECTION_ID)])
    bench = tmp_path / "bench.blf"  # another tool's log: no sidecar
    two_channel_log(bench, messages)
    code = cli.main(["check", str(scene), "--log", str(bench), "--mapping", str(autosar)])
    out, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in err
    (line,) = [x for x in err.splitlines() if "error: " in x]
    assert line == (f"error: --log {bench}: holds the radar's messages (the identifiers of "
                    f"mapping 'autosar-radar') on 2 channels: 0 ({n} messages), 1 ({n} "
                    f"messages); which is the radar's is not guessed: give --log-channel CH "
                    f"(the channel as python-can reads it from the log)"), line
    code = cli.main(["check", str(scene), "--log", str(bench), "--mapping", str(autosar),
                     "--log-channel", "0"])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "other channels" in out  # the report's bus names the messages left out
    code = cli.main(["check", str(scene), "--log", str(bench), "--mapping", str(autosar),
                     "--log-channel", "can0"])
    _, err = capsys.readouterr()
    assert code == 2
    assert (f"error: --log-channel can0: the log {bench} holds none of the radar's messages "
            f"(the identifiers of mapping 'autosar-radar') on channel can0; its channels with "
            f"them: 0 ({n} messages), 1 ({n} messages)") in err, err
    code = cli.main(["check", str(scene), "--log", str(bench), "--log-channel", " "])
    _, err = capsys.readouterr()
    assert code == 2 and "error: --log-channel ' ': empty" in err, err


def test_check_reads_the_channel_the_run_listened_on_where_the_sidecar_says_it(
        recorded, tmp_path, capsys):
    scene, log = recorded
    bench = tmp_path / "bench.blf"
    two_channel_log(bench, list(can.LogReader(str(log))))
    Path(f"{bench}.rts.json").write_text(Path(f"{log}.rts.json").read_text())
    code = cli.main(["check", str(scene), "--log", str(bench)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "read channel 0, the one the run listened on" in out, out


def test_a_log_holding_the_radar_on_another_channel_than_the_run_s_says_so():
    # The sidecar says the run listened on vcan0 (a BLF numbers it 0); the log holds the
    # radar's messages on channel 1 alone: read, with a note (a log of another bus?).
    from collections import Counter

    from rts_scenario.canbus import CanMapping
    from rts_scenario.recheck import pick_channel

    sidecar = {"can_channel": "vcan0"}
    picked, note = pick_channel("bench.blf", None, Counter({"1": 40}), CanMapping.builtin(),
                                sidecar)
    assert picked is None and "on channel 1 only, not on the one the run listened on " \
        "('vcan0', its sidecar)" in note
    assert pick_channel("bench.blf", None, Counter({"0": 40}), CanMapping.builtin(),
                        sidecar) == (None, None)
    assert pick_channel("bench.blf", None, Counter({"1": 40}), CanMapping.builtin(),
                        None) == (None, None)


@pytest.mark.usefixtures("unnamed_channel")
@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_a_log_of_messages_that_named_no_channel_is_read_as_the_run_s_without_a_note(
        tmp_path, capsys, suffix):
    # An interface that names no channel on its messages (python-can's udp_multicast): a log
    # writes them on its format's default channel (0 in a .blf or .asc, vcan0 in a .log),
    # not on the one the run listened on. They are the run's: no note says otherwise.
    import json

    log = tmp_path / f"bench{suffix}"
    code = cli.main(["run", str(APPROACH), "--can-channel", "239.74.163.2", "--record",
                     str(log)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    sidecar = json.loads(Path(f"{log}.rts.json").read_text())
    assert (sidecar["can_channel"], sidecar["can_channel_named"]) == ("239.74.163.2", False)
    code = cli.main(["check", str(APPROACH), "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "listened on" not in out + err, out + err
    # Where the messages named the channel, another in the log is still worth the note.
    from collections import Counter

    from rts_scenario.recheck import pick_channel

    named = {**sidecar, "can_channel_named": True}
    default = "vcan0" if suffix == ".log" else "0"
    picked, note = pick_channel(log, None, Counter({default: 40}), CanMapping.builtin(), named)
    assert picked is None and "not on the one the run listened on" in note, note
    assert pick_channel(log, None, Counter({default: 40}), CanMapping.builtin(),
                        sidecar) == (None, None)


# --- a live run on an interface that listens on several channels ---------------------------

def two_channel_interface(monkeypatch):
    """Make the run's in-process bus an interface listening on two channels: the radar's
    messages come on channel 0 (python-can's ``Message.channel``, as a Vector interface
    given ``0,1`` numbers them), a sibling radar's with the same identifiers (its counter 5
    cycles on) on channel 1."""
    from rts_scenario.canbus import ListenerBus

    class TwoChannels(ListenerBus):
        def send(self, msg, timeout=None):
            twin = resealed(msg, 1, 5)
            msg.channel, msg.is_rx, twin.is_rx = 0, True, True
            for listener in self._listeners:
                listener.on_message_received(msg)
                listener.on_message_received(twin)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", TwoChannels)


APPROACH = ROOT / "scenarios" / "approaching_target.scenario.yaml"


def test_a_run_hearing_the_radar_s_identifiers_on_two_channels_fails_naming_them(
        autosar, tmp_path, monkeypatch, capsys):
    import json

    two_channel_interface(monkeypatch)
    out_json, log = tmp_path / "report.json", tmp_path / "bench.blf"
    code = cli.main(["run", str(approach(tmp_path)),
                     "--mapping", str(autosar), "--json", str(out_json),
                     "--record", str(log)])
    out, err = capsys.readouterr()
    assert code == 1, out + err
    report = json.loads(out_json.read_text())
    (reason,) = [r for r in report["reasons"] if "channels" in r]
    assert re.fullmatch(
        r"the radar's messages \(the identifiers of mapping 'autosar-radar'\) came on 2 "
        r"channels: 0 \((\d+) messages\), 1 \(\1 messages\): the radar's cycles and another "
        r"bus's were mixed; give --radar-channel CH \(the channel as python-can gives it\)",
        reason), reason
    # Which channel was the radar's is not known: the sidecar names none, and the log's
    # check does not pick one either.
    assert json.loads(Path(f"{log}.rts.json").read_text())["can_channel"] is None
    code = cli.main(["check", str(approach(tmp_path)), "--log", str(log)])
    _, err = capsys.readouterr()
    assert code == 2 and "which is the radar's is not guessed" in err, err


def test_run_radar_channel_reads_one_channel_and_the_log_s_check_reads_the_same(
        autosar, tmp_path, monkeypatch, capsys):
    import json

    two_channel_interface(monkeypatch)
    log = tmp_path / "bench.blf"
    out_json = tmp_path / "report.json"
    code = cli.main(["run", str(approach(tmp_path)),
                     "--mapping", str(autosar), "--radar-channel", "0",
                     "--record", str(log), "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    report = json.loads(out_json.read_text())
    bus = report["bus"]
    assert bus["other_channels"] == bus["messages"] > 0  # the sibling's, one per radar message
    assert (bus["conflicts"], bus["duplicates"], bus["reordered"]) == (0, 0, 0)
    sidecar = json.loads(Path(f"{log}.rts.json").read_text())
    assert sidecar["can_channel"] == "0"
    # The log holds both channels; its check reads the one the run read.
    code = cli.main(["check", str(approach(tmp_path)), "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "read channel 0, the one the run listened on ('0', its sidecar)" in out, out


def test_run_radar_channel_without_the_radar_on_it_fails_naming_the_channels(
        autosar, tmp_path, monkeypatch, capsys):
    import json

    two_channel_interface(monkeypatch)
    out_json = tmp_path / "report.json"
    code = cli.main(["run", str(approach(tmp_path)),
                     "--mapping", str(autosar), "--radar-channel", "2",
                     "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 1, out + err
    reasons = json.loads(out_json.read_text())["reasons"]
    assert any(re.fullmatch(
        r"--radar-channel 2: none of the radar's messages \(the identifiers of mapping "
        r"'autosar-radar'\) came on channel 2; the channels they came on: 0 \((\d+) "
        r"messages\), 1 \(\1 messages\)", r) for r in reasons), reasons
    code = cli.main(["run", str(APPROACH), "--radar-channel", " "])
    _, err = capsys.readouterr()
    assert code == 2 and "error: --radar-channel ' ': empty" in err, err


def test_a_run_hearing_the_radar_on_one_channel_keeps_it_in_the_sidecar(
        autosar, tmp_path, monkeypatch, capsys):
    # The interface names the channel the radar came on (socketcan bound to every device
    # names each message's): the sidecar keeps that one, as the log names it.
    import json

    from rts_scenario.canbus import ListenerBus

    class Named(ListenerBus):
        def send(self, msg, timeout=None):
            msg.channel, msg.is_rx = "vcan1", True
            for listener in self._listeners:
                listener.on_message_received(msg)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", Named)
    log = tmp_path / "drive.blf"
    assert cli.main(["run", str(approach(tmp_path)), "--mapping", str(autosar), "--record",
                     str(log)]) == 0
    capsys.readouterr()
    assert json.loads(Path(f"{log}.rts.json").read_text())["can_channel"] == "vcan1"


# --- a log cut short ---------------------------------------------------------------------------

def test_a_blf_cut_short_fails_its_check_saying_where_it_ends(recorded, tmp_path, capsys):
    import json

    scene, log = recorded
    whole = log.read_bytes()
    messages = list(can.LogReader(str(log)))
    cut = tmp_path / "cut.blf"
    cut.write_bytes(whole[: len(whole) * 6 // 10])
    Path(f"{cut}.rts.json").write_text(Path(f"{log}.rts.json").read_text())
    kept = list(can.LogReader(str(cut)))
    assert 0 < len(kept) < len(messages)  # python-can reads it as a shorter log, silently
    out_json = tmp_path / "check.json"
    code = cli.main(["check", str(scene), "--log", str(cut), "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 1 and "Traceback" not in err, out + err
    report = json.loads(out_json.read_text())
    expected = (f"the log {cut} was cut short: its header says {len(whole)} bytes, the file "
                f"holds {len(whole) * 6 // 10}; it ends at log time {kept[-1].timestamp:.6f} s "
                f"(its last message read): what the radar sent after it is not in it")
    assert expected in report["reasons"], report["reasons"]
    assert report["alignment"]["log_cut_short"] == {
        "header_bytes": len(whole), "file_bytes": len(whole) * 6 // 10, "line": None,
        "last_message_t_s": kept[-1].timestamp}
    assert expected in out
    # The whole log has nothing of the kind.
    assert cli.main(["check", str(scene), "--log", str(log), "--json", str(out_json)]) == 0
    assert json.loads(out_json.read_text())["alignment"]["log_cut_short"] is None


def test_a_blf_its_writer_never_closed_fails_its_check(recorded, tmp_path, capsys):
    # A recording stopped without closing its writer (the process killed): python-can's BLF
    # header still says 144 bytes and no object, the messages in its buffer are lost.
    scene, log = recorded
    messages = list(can.LogReader(str(log)))
    open_log = tmp_path / "open.blf"
    Path(f"{open_log}.rts.json").write_text(Path(f"{log}.rts.json").read_text())
    writer = can.BLFWriter(str(open_log), max_container_size=1024)  # flushed as it goes
    for msg in messages:
        writer.on_message_received(msg)
    writer.file.flush()
    size = open_log.stat().st_size
    kept = list(can.LogReader(str(open_log)))
    assert 0 < len(kept) < len(messages)
    code = cli.main(["check", str(scene), "--log", str(open_log)])
    out, err = capsys.readouterr()
    writer.file.close()
    assert code == 1 and "Traceback" not in err, out + err
    assert (f"the log {open_log} was cut short: its header says 144 bytes (the tool that "
            f"wrote it never closed it), the file holds {size}; it ends at log time "
            f"{kept[-1].timestamp:.6f} s") in out, out


def test_an_asc_cut_short_fails_its_check(autosar, tmp_path, capsys):
    scene = approach(tmp_path)
    log = tmp_path / "drive.asc"
    assert cli.main(["run", str(scene), "--mapping", str(autosar), "--record", str(log)]) == 0
    capsys.readouterr()
    lines = log.read_text().splitlines(keepends=True)
    assert lines[-1].strip() == "End TriggerBlock"
    log.write_text("".join(lines[: len(lines) // 2]))
    last = list(can.LogReader(str(log)))[-1].timestamp
    code = cli.main(["check", str(scene), "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 1 and "Traceback" not in err, out + err
    assert (f"the log {log} was cut short: it lacks the 'End TriggerBlock' line an ASC log "
            f"ends with; it ends at log time {last:.6f} s") in out, out


def test_the_check_of_a_run_whose_radar_channel_held_none_does_not_read_another(
        autosar, tmp_path, monkeypatch, capsys):
    # The radar's messages come on channel 0 only; the run was told --radar-channel 1, read
    # none and failed. The log holds them (on channel 0): its check must not judge them as
    # the run's, which read none: it says so, as for a run that heard several channels.
    import json

    from rts_scenario.canbus import ListenerBus

    class ChannelZero(ListenerBus):
        def send(self, msg, timeout=None):
            msg.channel, msg.is_rx = 0, True
            for listener in self._listeners:
                listener.on_message_received(msg)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", ChannelZero)
    log, out_json = tmp_path / "bench.blf", tmp_path / "report.json"
    code = cli.main(["run", str(approach(tmp_path)),
                     "--mapping", str(autosar), "--radar-channel", "1",
                     "--record", str(log), "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 1, out + err
    assert any(r.startswith("--radar-channel 1: none of the radar's messages")
               for r in json.loads(out_json.read_text())["reasons"])
    code = cli.main(["check", str(approach(tmp_path)), "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert ("the run read channel 1 alone (run --radar-channel, its sidecar), and the log holds "
            "none of the radar's messages (the identifiers of mapping 'autosar-radar') there: "
            "only on 0 (") in err, err
    # Told which channel to judge, it judges that one.
    assert cli.main(["check", str(approach(tmp_path)),
                     "--log", str(log), "--log-channel", "0"]) == 0
    capsys.readouterr()
    # A run that read its --radar-channel: its log's check reads it, also where the log's
    # format names the channel otherwise (a canutils .log writes channel 0 as can0).
    log = tmp_path / "bench.log"
    code = cli.main(["run", str(approach(tmp_path)),
                     "--mapping", str(autosar), "--radar-channel", "0",
                     "--record", str(log)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    code = cli.main(["check", str(approach(tmp_path)), "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 0, out + err


ASC_HEAD = "date Fri Nov 27 02:30:00.000 pm 2026\nbase hex  timestamps absolute\n"
ASC_MESSAGES = (" 0.010000 1  101             Rx   d 8 13 01 50 46 8D BD D9 F4\n"
                " 0.060000 1  101             Rx   d 8 13 02 FD 09 96 F8 FF 3A\n")


@pytest.mark.parametrize(("text", "cut"), [
    # Vector's casing, another tool's, and no trigger block at all (can-utils' log2asc):
    # complete logs.
    (ASC_HEAD + "Begin Triggerblock Fri Nov 27 02:30:00.000 pm 2026\n" + ASC_MESSAGES
     + "End TriggerBlock\n", False),
    (ASC_HEAD + "begin triggerblock Fri Nov 27 02:30:00.000 pm 2026\n" + ASC_MESSAGES
     + "end Triggerblock\r\n", False),
    (ASC_HEAD + "no internal events logged\n" + ASC_MESSAGES, False),
    # A trigger block opened and never closed: cut short.
    (ASC_HEAD + "Begin Triggerblock Fri Nov 27 02:30:00.000 pm 2026\n" + ASC_MESSAGES, True),
    (ASC_HEAD + "Begin Triggerblock Fri Nov 27 02:30:00.000 pm 2026\n" + ASC_MESSAGES
     + "End TriggerBlock\nBegin Triggerblock Fri Nov 27 02:31:00.000 pm 2026\n"
     + ASC_MESSAGES, True),
    # The end line written without a line end (some tools): complete.
    (ASC_HEAD + "Begin Triggerblock Fri Nov 27 02:30:00.000 pm 2026\n" + ASC_MESSAGES
     + "End TriggerBlock", False),
    # No trigger block, its last message line written in part (python-can reads 4 of its 8
    # data bytes): cut short.
    (ASC_HEAD + "no internal events logged\n" + ASC_MESSAGES[:-13], True),
])
def test_an_asc_log_is_cut_short_where_a_trigger_block_it_opened_never_ends(tmp_path, text,
                                                                             cut):
    from rts_scenario.recheck import log_cut_short

    log = tmp_path / "drive.asc"
    log.write_bytes(text.encode())
    assert len(list(can.LogReader(str(log)))) in (2, 4)
    said = log_cut_short(log, 0.06)
    assert (said is not None) == cut, said


# --- survey and calibrate on an interface that listens on several channels -----------------

def bridged_twice(monkeypatch):
    """Make the in-process bus an interface listening on two channels that both carry the
    radar's messages: on channel 0, and again 3 ms later on channel 1 (the same bus bridged
    twice, or a sibling radar of the family speaking the same identifiers)."""
    from rts_scenario.canbus import ListenerBus

    class Bridged(ListenerBus):
        def send(self, msg, timeout=None):
            twin = can.Message(arbitration_id=msg.arbitration_id,
                               is_extended_id=msg.is_extended_id, data=bytes(msg.data),
                               timestamp=msg.timestamp + 0.003, channel=1, is_rx=True)
            msg.channel, msg.is_rx = 0, True
            for listener in self._listeners:
                listener.on_message_received(msg)
                listener.on_message_received(twin)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", Bridged)


MIXED = (r"the radar's messages \(the identifiers of mapping 'rts-detections'\) came on 2 "
         r"channels: 0 \((\d+) messages\), 1 \(\1 messages\): the radar's cycles and another "
         r"bus's were mixed; give --radar-channel CH \(the channel as python-can gives it\)")


@pytest.mark.parametrize("command", [
    ["survey", "kit-table1", "--radar", "paper"],
    ["calibrate", "kit-table1", "--inject-phase-deg", "30", "--seed", "1"]])
def test_a_measurement_hearing_the_radar_on_two_channels_is_refused_naming_them(
        command, tmp_path, monkeypatch, capsys):
    bridged_twice(monkeypatch)
    out_json, rig_out = tmp_path / "out.json", tmp_path / "out.rig.yaml"
    code = cli.main([*command, "--json", str(out_json), "--write", str(rig_out)])
    out, err = capsys.readouterr()
    # A measurement failed (exit 1, as a survey missing an FE and a failed calibration do):
    # one error line naming the channels; nothing measured from the mixed cycles is written.
    assert code == 1, out + err
    (line,) = [e for e in err.splitlines() if e.startswith("error: ")]
    assert re.fullmatch(rf"error: {command[0]}: {MIXED}; nothing written", line), line
    assert not out_json.exists() and not rig_out.exists()


def test_survey_radar_channel_reads_the_radar_s_channel_alone(tmp_path, monkeypatch, capsys):
    import json

    alone = tmp_path / "alone.json"
    assert cli.main(["survey", "kit-table1", "--radar", "paper", "--json", str(alone)]) == 0
    bridged_twice(monkeypatch)
    both = tmp_path / "both.json"
    code = cli.main(["survey", "kit-table1", "--radar", "paper", "--radar-channel", "0",
                     "--json", str(both)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    reference, read = json.loads(alone.read_text()), json.loads(both.read_text())
    assert reference["radar_channel"] is None and read["radar_channel"] == "0"
    # The same measurement as on a bus carrying the radar alone (the simulated radar is
    # deterministic without noise).
    assert read["front_ends"] == reference["front_ends"]


def test_calibrate_radar_channel_reads_the_radar_s_channel_alone(tmp_path, monkeypatch,
                                                                 capsys):
    import json

    bridged_twice(monkeypatch)
    out_json = tmp_path / "cal.json"
    code = cli.main(["calibrate", "kit-table1", "--inject-phase-deg", "30", "--seed", "1",
                     "--radar-channel", "0", "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    data = json.loads(out_json.read_text())
    assert data["passed"] and data["radar_channel"] == "0"
    for channel in data["channels"]:
        assert abs((channel["recovered_phase_deg"] - channel["injected_phase_deg"] + 180) % 360
                   - 180) < 0.5


@pytest.mark.parametrize("command", [
    ["survey", "kit-table1", "--radar", "paper"],
    ["calibrate", "kit-table1"]])
def test_a_measurement_s_radar_channel_without_the_radar_on_it_is_refused(
        command, tmp_path, monkeypatch, capsys):
    bridged_twice(monkeypatch)
    code = cli.main([*command, "--radar-channel", "2"])
    out, err = capsys.readouterr()
    assert code == 1, out + err
    (line,) = [e for e in err.splitlines() if e.startswith("error: ")]
    assert re.fullmatch(
        rf"error: {command[0]}: --radar-channel 2: none of the radar's messages \(the "
        r"identifiers of mapping 'rts-detections'\) came on channel 2; the channels they came "
        r"on: 0 \((\d+) messages\), 1 \(\1 messages\); nothing written", line), line
    code = cli.main([*command, "--radar-channel", " "])
    _, err = capsys.readouterr()
    assert code == 2 and "error: --radar-channel ' ': empty" in err, err


# --- survey and calibrate with a third-party radar's DBC (--mapping, --can-fd) -------------

BENCH_COMMANDS = [["survey", "kit-table1", "--radar", "paper"],
                  ["calibrate", "kit-table1", "--inject-phase-deg", "30", "--seed", "1"]]
OBJECT_LIST = ROOT / "scenarios" / "can" / "object_list.mapping.yaml"


def one_error_line(err):
    assert "Traceback" not in err, err
    (line,) = err.splitlines()
    return line


@pytest.mark.parametrize("command", BENCH_COMMANDS)
def test_a_measurement_s_missing_mapping_is_one_error_naming_the_option(command, tmp_path,
                                                                        capsys):
    missing = tmp_path / "radar.mapping.yaml"
    out_json = tmp_path / "out.json"
    code = cli.main([*command, "--mapping", str(missing), "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert one_error_line(err) == (f"error: --mapping {missing}: cannot read file: No such file "
                                   f"or directory")
    assert out == "" and not out_json.exists()


@pytest.mark.parametrize("command", BENCH_COMMANDS)
def test_a_measurement_s_bad_mapping_is_one_located_error_naming_the_option(command, tmp_path,
                                                                            capsys):
    bad = tmp_path / "objects.mapping.yaml"
    (tmp_path / "object_list.dbc").write_text((OBJECT_LIST.parent / "object_list.dbc").read_text())
    bad.write_text(OBJECT_LIST.read_text().replace("range_m: Obj_Range", "range_m: Obj_Rnage"))
    code = cli.main([*command, "--mapping", str(bad)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    line = one_error_line(err)
    assert re.match(rf"error: --mapping {re.escape(str(bad))}:\d+:\d+: detection\.range_m: ",
                    line), line
    assert "Obj_Rnage" in line


@pytest.mark.parametrize("command", BENCH_COMMANDS)
def test_a_measurement_s_can_fd_with_a_mapping_without_an_fd_message_is_refused(command,
                                                                                capsys):
    code = cli.main([*command, "--can-fd", "--mapping", str(OBJECT_LIST)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert one_error_line(err) == (
        f"error: --can-fd: the mapping {OBJECT_LIST} has no fd_message (the radar's CAN FD "
        f"detection message) for --can-fd to use; add fd_message to the mapping or leave out "
        f"--can-fd")


def test_survey_over_can_fd_sees_what_classic_can_sees(tmp_path):
    import json

    outs = []
    for name, extra in (("classic", []), ("fd", ["--can-fd"])):
        out = tmp_path / f"{name}.json"
        assert cli.main(["survey", "kit-table1", "--radar", "paper", *extra, "--json",
                         str(out)]) == 0
        outs.append(json.loads(out.read_text()))
    classic, fd = outs
    assert (classic["can_fd"], fd["can_fd"]) == (False, True)
    for a, b in zip(classic["front_ends"], fd["front_ends"], strict=True):
        assert b["seen_az_deg"] == pytest.approx(a["seen_az_deg"], abs=0.006)
        assert b["seen_el_deg"] == pytest.approx(a["seen_el_deg"], abs=0.006)


@pytest.mark.parametrize("command", BENCH_COMMANDS)
def test_a_measurement_s_json_counts_the_messages_of_the_other_channels(command, tmp_path,
                                                                        monkeypatch, capsys):
    # Every message of the radar comes again on channel 1 (`bridged_twice`): read on channel
    # 0, the measurement skipped exactly as many messages as the radar sent.
    import json

    import rts_scenario.pipeline as pipeline

    bridged_twice(monkeypatch)
    sent = []
    bridged_send = pipeline.ListenerBus.send

    def counting(self, msg, timeout=None):
        sent.append(msg.arbitration_id)
        return bridged_send(self, msg, timeout)

    monkeypatch.setattr(pipeline.ListenerBus, "send", counting)
    out_json = tmp_path / "out.json"
    code = cli.main([*command, "--radar-channel", "0", "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    data = json.loads(out_json.read_text())
    assert len(sent) > 0 and data["other_channels"] == len(sent)
    # Without --radar-channel every channel is read: nothing skipped to count.
    monkeypatch.undo()
    assert cli.main([*command, "--json", str(out_json)]) == 0
    assert json.loads(out_json.read_text())["other_channels"] is None


@pytest.mark.parametrize("command", BENCH_COMMANDS)
def test_a_measurement_through_a_mapping_without_elevation_is_refused_naming_it(command,
                                                                                capsys):
    # The cluster list is a 2-D radar's (distance long/lat, no height): it carries no
    # elevation, which a survey and a calibration measure. Not a radar that saw nothing.
    clusters = ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml"
    code = cli.main([*command, "--mapping", str(clusters)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert one_error_line(err) == (
        f"error: --mapping {clusters}: the mapping 'cluster-list' carries no elevation_deg, "
        f"which {command[0]} measures (of each detection it needs: "
        f"{'range_m, ' if command[0] == 'calibrate' else ''}azimuth_deg, elevation_deg, "
        f"rcs_dbsm)")
    assert out == ""
