"""The fast CAN path packs exactly what cantools' own strict encoder packs, and decodes alike.

The publisher checks values against their signals for a whole batch of cycles at once and
packs them with cantools' compiled formats; the receiver unpacks raw values the same way and
scales them per message. Reference: cantools' public ``Message.encode(strict=True)`` and
``Message.decode``, on every message and page of the shipped DBCs and of one written here
with Motorola, signed, float, scaled and multiplexed signals.
"""

from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from rts_scenario.canbus import (
    DetectionPublisher,
    DetectionReceiver,
    ListenerBus,
    _Codec,
    _range_of,
)
from rts_scenario.canbus.mapping import CanMapping, pages
from rts_scenario.detections import Detections

ROOT = Path(__file__).resolve().parents[1]
MAPPINGS = [None, ROOT / "scenarios/can/object_list.mapping.yaml",
            ROOT / "scenarios/can/cluster_list.mapping.yaml"]

MIXED_DBC = """VERSION ""
BU_: RADAR
BO_ 1056 Mixed: 8 RADAR
 SG_ Moto12 : 7|12@0- (0.25,-3) [-100|100] "m" Vector__XXX
 SG_ Intel10 : 16|10@1+ (0.1,5) [5|100] "deg" Vector__XXX
 SG_ MotoByte : 39|8@0+ (1,0) [0|255] "" Vector__XXX
 SG_ Flag : 26|1@1+ (1,0) [0|1] "" Vector__XXX
 SG_ Wide : 40|24@1- (0.001,0) [-8000|8000] "" Vector__XXX
BO_ 1057 Muxed: 8 RADAR
 SG_ Page M : 0|2@1+ (1,0) [0|3] "" Vector__XXX
 SG_ A m0 : 8|16@1- (0.01,0) [-300|300] "" Vector__XXX
 SG_ B m1 : 15|16@0+ (0.5,-10) [-10|1000] "" Vector__XXX
 SG_ C m1 : 24|8@1+ (1,0) [0|200] "" Vector__XXX
 SG_ Common : 56|8@1+ (1,0) [0|255] "" Vector__XXX
BO_ 1058 Floaty: 8 RADAR
 SG_ F : 0|32@1- (1,0) [-1000|1000] "" Vector__XXX
 SG_ G : 32|16@1+ (0.02,-1) [-1|1000] "" Vector__XXX
SIG_VALTYPE_ 1058 F : 1;
"""


def _messages_and_pages():
    out = []
    db = cantools.database.load_string(MIXED_DBC, "dbc")
    out += [(m, p) for m in db.messages for p in pages(m)]
    for path in MAPPINGS:
        mapping = CanMapping.builtin() if path is None else CanMapping.from_file(path)
        out += [(m, p) for m in mapping.db.messages for p in pages(m)]
    return out


CASES = _messages_and_pages()


@pytest.mark.parametrize(("message", "page"), CASES,
                         ids=[f"{m.name}-{p}" for m, p in CASES])
def test_packing_matches_cantools_strict_encoder(message, page):
    codec = _Codec(message, page, None)
    rng = np.random.default_rng(message.frame_id * 10 + (page or 0))
    for _ in range(200):
        physical = {}
        for name, sig in codec.signals.items():
            low, high = _range_of(sig)
            if sig.is_multiplexer and page is not None:
                physical[name] = page
            elif rng.random() < 0.1:
                physical[name] = low if rng.random() < 0.5 else high  # the very ends
            else:
                physical[name] = float(rng.uniform(low, high))
        raw = {name: codec.raw(name, value) for name, value in physical.items()}
        # The column conversion is the scalar one, value for value.
        for name, value in physical.items():
            assert codec.raw_column(name, np.array([value]))[0] == raw[name]
        expected = message.encode(raw, scaling=False, strict=True)
        data = codec.encode(raw)
        assert data == expected
        decoded = message.decode(data, decode_choices=False, scaling=False)
        assert codec.decode(data) == {k: decoded[k] for k in codec.signals}


def test_ranges_are_what_the_bits_carry_within_the_dbc():
    db = cantools.database.load_string(MIXED_DBC, "dbc")
    sig = db.get_message_by_name("Mixed").get_signal_by_name("Moto12")
    # 12 signed bits at 0.25 carry [-515, 508.75]; the DBC narrows it to [-100, 100].
    assert _range_of(sig) == (-100.0, 100.0)
    wide = db.get_message_by_name("Mixed").get_signal_by_name("Wide")
    # 24 signed bits at 0.001 carry [-8388.608, 8388.607]; the DBC says [-8000, 8000].
    assert _range_of(wide) == (-8000.0, 8000.0)
    unbounded = cantools.database.can.Signal("U", start=0, length=8, minimum=None,
                                             maximum=None)
    assert _range_of(unbounded) == (0.0, 255.0)


def test_a_short_message_is_a_decode_error_and_padding_is_ignored():
    mapping = CanMapping.builtin()
    receiver = DetectionReceiver(mapping)
    header = mapping.db.get_message_by_name(mapping.header)
    receiver.on_message_received(can.Message(arbitration_id=header.frame_id, data=b"\x01\x02",
                                            is_extended_id=header.is_extended_frame))
    assert receiver.stats.decode_errors + receiver.stats.checksum_errors == 1
    codec = _Codec(header, None, None)
    data = codec.encode(codec.defaults)
    assert codec.decode(data + b"\x00" * 4) == codec.decode(data)


@pytest.mark.parametrize("path", MAPPINGS, ids=["builtin", "object_list", "cluster_list"])
@pytest.mark.parametrize("fd", [False, True])
def test_batches_round_trip_exactly_as_cycles_one_by_one(path, fd):
    mapping = None if path is None else CanMapping.from_file(path)
    rng = np.random.default_rng(7)
    cycles = []
    for k in range(30):
        n = int(rng.integers(0, 9))
        cycles.append(Detections(
            cycle=100 + k, t_s=0.05 * k, range_m=rng.uniform(1, 90, n),
            radial_velocity_mps=rng.uniform(-30, 30, n), az_deg=rng.uniform(-50, 50, n),
            el_deg=rng.uniform(-10, 10, n), rcs_dbsm=rng.uniform(-20, 40, n),
            snr_db=rng.uniform(0, 60, n)))
    cycles[3] = Detections(cycle=103, t_s=0.15, range_m=np.array([-1.0, 20.0, np.nan]),
                           radial_velocity_mps=np.zeros(3), az_deg=np.zeros(3),
                           el_deg=np.zeros(3), rcs_dbsm=np.zeros(3), snr_db=np.zeros(3))

    def send(batch):
        got: list[can.Message] = []

        class Keep(can.Listener):
            def on_message_received(self, msg):
                got.append(msg)

        receiver = DetectionReceiver(mapping)
        with ListenerBus([Keep(), receiver]) as bus:
            publisher = DetectionPublisher(bus, fd=fd, mapping=mapping)
            if batch:
                publisher.publish_many(cycles, np.arange(30) * 0.05)
            else:
                for k, c in enumerate(cycles):
                    publisher.publish(c, k * 0.05)
        return got, receiver.flush(), publisher

    many, out_many, pub_many = send(True)
    one, out_one, pub_one = send(False)
    assert [bytes(m.data) for m in many] == [bytes(m.data) for m in one]
    assert [m.timestamp for m in many] == [m.timestamp for m in one]
    assert pub_many.unsendable == pub_one.unsendable
    assert len(out_many) == 30 and all(c.complete for c in out_many)
    assert [c.count for c in out_many] == [c.count for c in out_one]
    if path is not None:
        return  # (what third-party layouts carry: tests/test_real_dbc.py)
    assert pub_many.unsendable_detections == 2  # a negative range and a NaN
    for sent, back in zip(cycles, out_many, strict=True):
        keep = np.isfinite(sent.range_m) & (sent.range_m >= 0)
        assert back.cycle % 256 == sent.cycle % 256 and back.count == keep.sum()
        np.testing.assert_allclose(back.range_m, sent.range_m[keep], atol=0.05)
