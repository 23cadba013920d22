import errno
import os
import re
import socket
import sys
import time
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

import rts_scenario.outputs as outputs
import rts_scenario.registry as registry
from rts_scenario import OutputError
from rts_scenario.kinematics import compute_tracks
from rts_scenario.outputs import available_outputs, open_output
from rts_scenario.outputs.file import read_schedule
from rts_scenario.outputs.udp import (
    ENTRY,
    HEADER,
    KIND_DELTA,
    KIND_FULL,
    SEQUENCE_WINDOW,
    FaultInjector,
    UdpReceiver,
    encode_frame,
    frame_entries,
)
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def schedule():
    scene = load_scenario(ROOT / "scenarios" / "dense_traffic.scenario.yaml")
    return build_schedule(compute_tracks(scene), scene.rig, scene.radar)


def assert_same(a, b):
    for name in ("t_s", "frame_index", "quad", "fe", "weight", "attenuation_db", "delay_s",
                 "doppler_hz", "phase_rad", "active", "status", "angle_error_deg"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.names == b.names


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_file_round_trip(tmp_path, schedule, suffix):
    path = tmp_path / f"s{suffix}"
    with open_output(f"file:{path}") as out:
        out.write(schedule.frames(0, 123))
        out.write(schedule.frames(123, schedule.n_frames))
    assert_same(read_schedule(path), schedule)


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_file_output_memory_does_not_grow_with_the_schedule(tmp_path, schedule, suffix):
    """Four times the frames, the same peak: batches go to disk as they come."""
    import tracemalloc
    from copy import deepcopy
    from dataclasses import replace

    batch = schedule.frames(0, 10)

    def peak_writing(n_batches):
        tracemalloc.start()
        with open_output(f"file:{tmp_path / f'{n_batches}{suffix}'}") as out:
            for i in range(n_batches):
                # Arrays of its own, as a pipeline's batches have: an output that held on to
                # its batches would grow by each of them.
                out.write(deepcopy(replace(batch, frame_index=batch.frame_index + 10 * i)))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak

    # 30 batches more (a batch is 22 kB) are 0.7 MB more in an output that keeps them.
    short, long = peak_writing(10), peak_writing(40)
    assert long < 1.25 * short
    written = read_schedule(tmp_path / f"40{suffix}")
    assert written.n_frames == 400 and written.frame_index[-1] == 399
    assert_same(written.frames(390, 400), replace(batch, frame_index=batch.frame_index + 390))


def test_output_contract(tmp_path, schedule):
    out = open_output(f"file:{tmp_path / 'x.npz'}")
    out.close()
    out.close()
    with pytest.raises(OutputError, match="write after close"):
        out.write(schedule)


def test_registry_errors_list_valid_names(tmp_path):
    assert {"file", "udp"} <= set(available_outputs())
    with pytest.raises(OutputError, match="valid outputs: .*file.*udp"):
        open_output("carrier-pigeon:somewhere")
    with pytest.raises(OutputError, match="valid: .npz, .csv"):
        open_output(f"file:{tmp_path / 'x.txt'}")
    with pytest.raises(OutputError, match="HOST:PORT"):
        open_output("udp://localhost")


def test_plugins_come_from_the_entry_point_group(monkeypatch, schedule):
    plugin = EntryPoint(name="dummy", value="dummy_output:DummyOutput",
                        group=outputs.ENTRY_POINT_GROUP)
    broken = EntryPoint(name="broken", value="no_such_module:Driver",
                        group=outputs.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "entry_points", lambda group: [plugin, broken])
    assert {"dummy", "broken"} <= set(available_outputs())
    with open_output("dummy:rig-7") as out:
        out.write(schedule.frames(0, 10))
    assert out.argument == "rig-7" and out.frames == 10 and out.closes == 1
    with pytest.raises(OutputError, match="output 'broken' cannot be loaded"):
        open_output("broken")


@pytest.mark.parametrize("mode", ["full", "delta"])
def test_udp_loopback_applies_every_frame(schedule, mode):
    receiver = UdpReceiver().start()
    with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast", mode=mode) as out:
        out.write(schedule)
    stats = receiver.stop()
    assert stats.clean, stats
    assert stats.frames_applied == schedule.n_frames
    # The endpoint's table equals the last frame's active channels.
    last = schedule.n_frames - 1
    k, c = np.nonzero(schedule.active[last])
    state = receiver.state
    got = {(int(e["target"]), int(e["channel"])): e for e in state}
    assert set(got) == set(zip(k.tolist(), c.tolist(), strict=True))
    for kk, cc in zip(k, c, strict=True):
        e = got[(kk, cc)]
        assert e["delay_s"] == schedule.delay_s[last, kk, cc]
        assert e["attenuation_db"] == np.float32(schedule.attenuation_db[last, kk, cc])


@pytest.mark.parametrize("fault, counter", [
    ("drop", "lost_datagrams"), ("duplicate", "duplicates"), ("reorder", "reordered"),
    ("corrupt", "corrupted"),
])
def test_udp_faults_are_detected_and_nothing_bad_is_applied(schedule, fault, counter):
    receiver = UdpReceiver(keep_applied=True).start()
    out = open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast")
    injector = FaultInjector(out.transmit, np.random.default_rng(5), **{fault: 0.05})
    out.send = injector
    out.write(schedule)
    injector.flush()
    out.close()
    stats = receiver.stop()
    assert injector.log[fault] > 0
    assert getattr(stats, counter) >= injector.log[fault] if fault != "reorder" else \
        stats.reordered > 0
    assert not stats.clean
    # Every applied frame is exactly what the schedule says, in order.
    frames = [f for f, _, _ in receiver.applied]
    assert frames == sorted(frames)
    for frame, _, entries in receiver.applied:
        k, c = entries["target"].astype(int), entries["channel"].astype(int)
        np.testing.assert_array_equal(entries["delay_s"], schedule.delay_s[frame, k, c])
        assert schedule.active[frame, k, c].all()
        assert len(entries) == schedule.active[frame].sum()
    if fault in ("drop", "corrupt"):
        assert stats.lost_frames > 0 and stats.frames_applied < schedule.n_frames


def test_udp_receiver_keeps_no_record_of_a_long_stream():
    """The reference RTS's memory does not grow with the stream; its counters stay exact."""
    receiver = UdpReceiver()
    entries = np.zeros(60, dtype=ENTRY)  # two datagrams per frame (48 entries fit one)
    entries["target"], entries["channel"] = np.arange(60) // 4, np.arange(60) % 4
    entries["flags"] = 1
    n_frames, lost = 3 * SEQUENCE_WINDOW, 100
    first = last = []
    for frame in range(n_frames):  # ten minutes at 20 frames/s
        datagrams = encode_frame(entries, kind=KIND_FULL, frame=frame, t_s=frame / 20.0,
                                 first_sequence=2 * frame)
        if frame != lost:  # both datagrams of one frame are lost
            for datagram in datagrams:
                receiver.handle(datagram)
        first = first or datagrams
        last = datagrams
    receiver.handle(last[1])  # a copy of the newest datagram
    receiver.handle(first[0])  # the first, 2 * n_frames - 1 datagrams later: too old to apply
    stats = receiver.stop(drain_s=0.0)
    assert stats.frames_applied == n_frames - 1
    assert (stats.lost_frames, stats.lost_datagrams) == (1, 2)
    assert (stats.duplicates, stats.stale, stats.reordered) == (1, 1, 0)
    # Nothing per frame or per datagram is kept: the emulator's RTS runs for hours.
    assert len(receiver.applied) == len(receiver.arrival_s) == 0
    assert len(receiver._seen) <= 2 * SEQUENCE_WINDOW


def test_a_new_sender_s_first_frame_starts_a_new_stream():
    """Run after run against one RTS: each run's sender opens a stream; counters are per stream."""
    receiver = UdpReceiver(keep_applied=True)
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1

    def frame(n, sequence, kind=KIND_FULL):
        return encode_frame(entries, kind=kind, frame=n, t_s=n / 20.0, first_sequence=sequence)[0]

    first, second = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
    for n in range(5):
        receiver.handle(frame(n, n), first)
    assert receiver.streams == 1 and receiver.stats.frames_applied == 5
    # The next run's frames from another socket: its frame 0 is not a late copy of the first's.
    receiver.handle(frame(0, 0), second)
    receiver.handle(frame(1, 1), second)
    assert receiver.streams == 2
    assert (receiver.stats.frames_applied, receiver.stats.duplicates) == (2, 0)
    assert receiver.current is not None and receiver.current[0] == 1
    # A datagram of the first run that comes late is the stream before's: stale, dropped.
    receiver.handle(frame(5, 5), first)
    # Another sender's datagram that opens no stream (not sequence 0) changes nothing.
    receiver.handle(frame(7, 7), ("127.0.0.1", 40003))
    stats = receiver.stop(drain_s=0.0)
    assert receiver.streams == 2 and receiver.current[0] == 1
    assert (stats.frames_applied, stats.stale, stats.lost_frames) == (2, 2, 0)
    assert [f for f, _, _ in receiver.applied] == [0, 1, 2, 3, 4, 0, 1]  # for a consumer


def test_a_stream_opens_by_its_header_whatever_its_entries():
    """udp-protocol.md, receiver rules: a run on another rig is a stream of its own, counted
    malformed there; a datagram too short for a header is malformed, not corrupted."""
    receiver = UdpReceiver(n_front_ends=4)
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1
    entries["fe"] = np.arange(4)
    other_rig = entries.copy()
    other_rig["fe"] = [5, 6, 10, 11]

    def frame(values, n):
        return encode_frame(values, kind=KIND_FULL, frame=n, t_s=n / 20.0, first_sequence=n)[0]

    receiver.handle(frame(entries, 0), ("127.0.0.1", 40001))
    receiver.handle(frame(entries, 1), ("127.0.0.1", 40001))
    receiver.handle(frame(other_rig, 0), ("127.0.0.1", 40002))
    assert receiver.streams == 2
    receiver.handle(frame(other_rig, 1), ("127.0.0.1", 40002))
    receiver.handle(b"RTSS\x01", ("127.0.0.1", 40002))
    counters = receiver.status_counters()
    assert (counters["datagrams"], counters["malformed"], counters["corrupted"],
            counters["frames_applied"]) == (3, 3, 0, 0)


@pytest.mark.parametrize("field, value", [("channel", 4), ("channel", 255), ("fe", 6),
                                          ("fe", -1)])
def test_an_entry_naming_a_channel_or_fe_the_rts_lacks_is_malformed_not_applied(field, value):
    """A datagram with a valid CRC is still refused if an entry names no channel of a quad
    (0..3) or an emitting one no FE of the RTS's rig: it is counted, and the receiver goes on."""
    receiver = UdpReceiver(n_front_ends=6)
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1
    entries["fe"] = [0, 1, 3, 4]
    bad = entries.copy()
    bad[field][2] = value

    def frame(n, values):
        return encode_frame(values, kind=KIND_FULL, frame=n, t_s=n / 20.0, first_sequence=n)[0]

    receiver.handle(frame(0, entries))
    receiver.handle(frame(1, bad))
    receiver.handle(frame(2, entries))
    stats = receiver.stop(drain_s=0.0)
    assert (stats.malformed, stats.frames_applied, stats.lost_frames) == (1, 2, 1)
    assert receiver.current is not None and receiver.current[0] == 2


def test_a_target_on_fes_that_make_no_quad_of_the_rts_s_rig_is_refused():
    """An RTS with as many FEs as the run's rig, laid out otherwise (5 rows of 3, the run's 3
    rows of 5): each target's channels name FEs that are no quad of the RTS's rig. The frames
    are refused (malformed, counted apart as ``other_rig``), never played on that geometry.
    FEs of a quad of its own are played, on whichever channels (a test pattern plays one FE,
    or a pair, from channel 0 on)."""
    from rts_scenario.rig import Rig

    rts_rig = Rig.grid(az_deg=[-10.0, 0.0, 10.0], el_deg=[-8.0, -4.0, 0.0, 4.0, 8.0])
    assert rts_rig.n_front_ends == 15
    receiver = UdpReceiver(n_front_ends=rts_rig.n_front_ends, quads=rts_rig.quads)
    entries = np.zeros(8, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = np.arange(8) // 4, np.arange(8) % 4, 1

    def frame(n, fe):
        values = entries.copy()
        values["fe"] = fe
        return encode_frame(values, kind=KIND_FULL, frame=n, t_s=n / 20.0, first_sequence=n)[0]

    receiver.handle(frame(0, [0, 1, 3, 4, 4, 5, 7, 8]))  # two quads of 5 rows of 3
    receiver.handle(frame(1, [0, 1, 5, 6, 1, 2, 6, 7]))  # quads of 3 rows of 5
    receiver.handle(frame(2, [0, 1, 3, 4, 1, 0, 4, 3]))  # the second one's channels swapped
    receiver.handle(frame(3, [0, 1, 3, 4, 0, 1, 7, 8]))  # the second one across two quads
    receiver.handle(frame(4, [3, 4, 6, 7, 0, 1, 3, 4]))
    receiver.handle(frame(5, [0, 1, 2, 0, 4, 5, 7, 8]))  # the first across two quads
    pattern = np.zeros(1, dtype=ENTRY)  # a survey's frame: FE 13 alone, on channel 0
    pattern["flags"], pattern["fe"] = 1, 13
    receiver.handle(encode_frame(pattern, kind=KIND_FULL, frame=6, t_s=0.3,
                                 first_sequence=6)[0])
    stats = receiver.stop(drain_s=0.0)
    assert (stats.frames_applied, stats.malformed, stats.other_rig) == (4, 3, 3)
    assert receiver.current is not None and receiver.current[0] == 6


def _wide_schedule(n_targets, frame=0, active=(-1,)):
    """One frame of ``n_targets`` targets, those of ``active`` emitting on FEs 0..3."""
    from rts_scenario.schedule import Schedule, Status

    shape = (1, n_targets, 4)
    on = np.zeros(shape, dtype=bool)
    on[0, list(active)] = True
    values = np.where(on, 1.0, np.nan)
    return Schedule(
        t_s=np.array([frame / 20.0]), frame_index=np.array([frame]),
        names=tuple(f"t{i}" for i in range(n_targets)), quad=np.where(on.any(-1), 0, -1),
        fe=np.where(on, np.arange(4), -1), weight=on.astype(float), attenuation_db=values,
        delay_s=values * 1e-7, doppler_hz=values, phase_rad=values * 0.0, active=on,
        status=np.full((1, n_targets), Status.OK, dtype=np.uint16),
        angle_error_deg=np.zeros((1, n_targets, 2)))


def test_udp_refuses_more_targets_than_its_target_field_numbers():
    """``target`` is u16: target 65536 would go out as target 0, silently. The stream takes
    65536 targets (0..65535) and refuses more with one error naming the limit, sending
    nothing."""
    receiver = UdpReceiver(keep_applied=True).start()
    host, port = receiver.address
    try:
        with outputs.open_output(f"udp://{host}:{port}", pacing="fast") as out:
            sent: list[bytes] = []
            transmit = out.send

            def record(datagram):
                sent.append(datagram)
                transmit(datagram)

            out.send = record
            out.write(_wide_schedule(65536))  # the last target is the highest u16
            with pytest.raises(OutputError, match=r"udp: 65537 targets: the stream's `target` "
                                                  r"field \(u16\) numbers at most 65536"):
                out.write(_wide_schedule(65537, frame=1))
            assert len(sent) == 1
    finally:
        receiver.stop(drain_s=0.2)
    (_, _, entries), = receiver.applied
    assert set(entries["target"].tolist()) == {65535}


def test_udp_sequence_wraps_at_2_32_and_the_receiver_follows():
    """``sequence`` counts datagrams modulo 2^32: after 4294967295 comes 0. The receiver
    takes the wrap for what it is (no stale, duplicate or lost datagram), and still tells a
    copy and a gap across it."""
    from rts_scenario.outputs.udp import HEADER, UdpOutput

    out = UdpOutput("127.0.0.1:9", pacing="fast")
    sent: list[bytes] = []
    out.send = sent.append
    out._sequence = 2**32 - 3
    for frame in range(6):
        out.write(_wide_schedule(1, frame=frame, active=(0,)))
    out.close()
    sequences = [HEADER.unpack(d[:HEADER.size])[3] for d in sent]
    assert sequences == [2**32 - 3, 2**32 - 2, 2**32 - 1, 0, 1, 2]
    receiver = UdpReceiver(n_front_ends=4)
    for datagram in sent:
        receiver.handle(datagram)
    stats = receiver.stop(drain_s=0.0)
    assert (stats.frames_applied, stats.stale, stats.duplicates, stats.reordered) == (6, 0, 0, 0)
    assert (stats.lost_datagrams, stats.lost_frames) == (0, 0)
    receiver = UdpReceiver(n_front_ends=4)
    for datagram in [*sent[:2], sent[3], sent[2], sent[3], *sent[5:]]:  # 4 lost, 2 late
        receiver.handle(datagram)
    stats = receiver.stop(drain_s=0.0)
    assert (stats.duplicates, stats.reordered, stats.lost_datagrams) == (1, 1, 1)
    assert stats.frames_applied == 4  # 0, 1, 3, 5: 2 came after 3, 4 never


def test_a_frame_that_comes_after_a_newer_one_is_late_not_lost():
    """Frame 1 comes after frame 2 (reordered on the way): not applied (frames are applied in
    order), but it came: counted as a late frame, not a lost one; its datagram is reordered
    and stale, none lost. Frame 5's second part comes after frame 6: late too. Frame 8 never
    comes: lost. The status reply's ``lost_frames`` (version 1: every frame not applied)
    holds both."""
    receiver = UdpReceiver(n_front_ends=4)
    one = np.zeros(4, dtype=ENTRY)
    one["channel"], one["flags"], one["fe"] = np.arange(4), 1, np.arange(4)
    two = np.zeros(52, dtype=ENTRY)  # 13 targets: two datagrams
    two["target"], two["channel"], two["flags"] = np.arange(52) // 4, np.arange(52) % 4, 1
    two["fe"] = two["channel"]
    sent = [0]  # the sender numbers its datagrams in the order of its frames

    def frame(n, entries=one):
        datagrams = encode_frame(entries, kind=KIND_FULL, frame=n, t_s=n / 20.0,
                                 first_sequence=sent[0])
        sent[0] += len(datagrams)
        return datagrams

    def send(*datagrams):
        for datagram in datagrams:
            receiver.handle(datagram)

    f0, f1, f2, f3, f4 = (frame(n) for n in range(5))
    send(*f0, *f2, *f1, *f3, *f4)
    f5, f6, f7 = frame(5, two), frame(6), frame(7)
    frame(8)  # lost on the way
    send(f5[0], *f6, f5[1], *f7, *frame(9))
    assert receiver.status_counters()["lost_frames"] == 3  # 1, 5, 8: not applied
    stats = receiver.stop(drain_s=0.0)
    assert stats.frames_applied == 7
    assert (stats.stale_frames, stats.lost_frames) == (2, 1)
    assert (stats.reordered, stats.stale, stats.lost_datagrams) == (2, 2, 1)


def test_an_off_entry_of_a_delta_needs_no_fe():
    receiver = UdpReceiver(n_front_ends=4)
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1
    entries["fe"] = np.arange(4)
    off = entries.copy()
    off["flags"], off["fe"] = 0, -1
    receiver.handle(encode_frame(entries, kind=KIND_FULL, frame=0, t_s=0.0, first_sequence=0)[0])
    receiver.handle(encode_frame(off, kind=KIND_DELTA, frame=1, t_s=0.05, first_sequence=1)[0])
    stats = receiver.stop(drain_s=0.0)
    assert (stats.malformed, stats.frames_applied) == (0, 2)
    assert receiver.state.size == 0


def test_after_a_quiet_spell_a_stream_opens_from_the_same_port_or_without_its_first(
        monkeypatch):
    import rts_scenario.outputs.udp as udp

    clock = [0.0]
    monkeypatch.setattr(udp.time, "perf_counter", lambda: clock[0])
    receiver = UdpReceiver()
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1

    def frame(n, sequence, kind=KIND_FULL):
        return encode_frame(entries, kind=kind, frame=n, t_s=n / 2.0, first_sequence=sequence)[0]

    sender = ("127.0.0.1", 40001)
    for n in range(3):  # a slow stream: 2 frames/s, quiet between its own frames
        clock[0] += 0.5
        receiver.handle(frame(n, n), sender)
    assert receiver.streams == 1 and receiver.stats.frames_applied == 3
    clock[0] += 0.01
    receiver.handle(frame(0, 0), sender)  # a copy of its first datagram, soon: a duplicate
    assert receiver.streams == 1 and receiver.stats.duplicates == 1
    clock[0] += 1.0  # the next run's socket got the same port
    receiver.handle(frame(0, 0), sender)
    receiver.handle(frame(1, 1, KIND_DELTA), sender)
    assert receiver.streams == 2 and receiver.stats.frames_applied == 2
    clock[0] += 1.0  # the run after lost its first datagram: its full frame 1 opens it
    other = ("127.0.0.1", 40002)
    receiver.handle(frame(1, 1), other)
    assert receiver.streams == 3 and receiver.stats.frames_applied == 1
    clock[0] += 0.01
    receiver.handle(frame(3, 3), sender)  # the run before's, late: stale
    assert receiver.streams == 3 and receiver.stats.stale == 1


def test_udp_paced_streaming_follows_the_frame_clock(schedule):
    receiver = UdpReceiver().start()
    part = schedule.frames(0, 20)
    with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="realtime") as out:
        start = time.perf_counter()
        out.write(part)
        elapsed = time.perf_counter() - start
    receiver.stop()
    # Functional check only (the jitter figure is the benchmark's): frames follow the clock.
    assert elapsed == pytest.approx(part.t_s[-1] - part.t_s[0], abs=0.1)
    assert max(out.sent_t_s(part) - part.t_s) < 0.05


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_a_file_output_cut_short_is_not_named_as_the_schedule(tmp_path, schedule, suffix):
    """An export stopped after 3 of its batches leaves PATH.partial with their 30 frames."""
    from dataclasses import replace

    path = tmp_path / f"x{suffix}"
    path.write_text("an earlier export")
    batch = schedule.frames(0, 10)
    with pytest.raises(KeyboardInterrupt), open_output(f"file:{path}") as out:
        for i in range(6):
            if i == 3:
                raise KeyboardInterrupt
            out.write(replace(batch, frame_index=batch.frame_index + 10 * i))
    assert not path.exists()
    assert read_schedule_as(tmp_path / f"x{suffix}.partial", suffix).n_frames == 30
    # Closed whole, it is PATH, and no .partial stays.
    with open_output(f"file:{path}") as out:
        out.write(batch)
    assert read_schedule(path).n_frames == 10 and not (tmp_path / f"x{suffix}.partial").exists()


def read_schedule_as(path, suffix):
    """Read a schedule file whose name does not end in its format's suffix."""
    import shutil

    copy = path.with_name(f"copy{suffix}")
    shutil.copy(path, copy)
    return read_schedule(copy)


def test_a_schedule_without_targets_round_trips_as_npz_and_is_refused_as_csv(tmp_path):
    """An empty bench's 60 frames (3 s at 20 Hz): a .csv, one row per entry, has none."""
    scene = load_scenario(ROOT / "scenarios" / "empty_bench.scenario.yaml")
    empty = build_schedule(compute_tracks(scene), scene.rig, scene.radar)
    with open_output(f"file:{tmp_path / 'e.npz'}") as out:
        out.write(empty)
    back = read_schedule(tmp_path / "e.npz")
    assert (back.n_frames, back.names, back.status.shape) == (60, (), (60, 0))
    np.testing.assert_allclose(back.t_s, np.arange(60) / 20.0)
    refused = r"without targets has no rows for a \.csv.*use \.npz"
    with pytest.raises(OutputError, match=refused), \
            open_output(f"file:{tmp_path / 'e.csv'}") as out:
        out.write(empty)
    assert not list(tmp_path.glob("e.csv*"))


def test_a_run_whose_rts_another_sender_took_over_does_not_take_its_counters(schedule):
    # Run A streams to the RTS; run B's stream takes it over (a second run against the same
    # RTS); A's datagrams after that are stale there. The RTS's counters are per stream: the
    # replies A reads count B's datagrams. A must not report them as its own playback.
    from rts_scenario.playback import playback_reasons

    receiver = UdpReceiver().start()
    address = f"udp://127.0.0.1:{receiver.address[1]}"
    with open_output(address, pacing="fast") as a, open_output(address, pacing="fast") as b:
        a.write(schedule.frames(0, 2))
        alone = a.rts_status(settle_s=0.5)
        b.write(schedule)
        a.write(schedule.frames(2, 4))
        taken = a.rts_status(settle_s=0.5)
        own = b.rts_status(settle_s=0.5)
    receiver.stop()
    assert alone is not None and "foreign_datagrams" not in alone
    assert own is not None and "foreign_datagrams" not in own
    assert taken is not None
    # B's stream counts B's datagrams and A's late ones as stale: beyond what A sent.
    assert taken["foreign_datagrams"] == taken["datagrams"] - a.datagrams_sent > 0
    playback = {"late_frames": 0, "frames_sent": 4, "rts": taken}
    (reason,) = [r for r in playback_reasons(playback, frozenset({"frames_lost"}))
                 if r.startswith("rts_stream:")]
    assert f"count {taken['foreign_datagrams']} datagrams more than this run sent" in reason


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.skipif(sys.platform != "linux", reason="ICMP errors reach an unconnected socket "
                                                    "on Linux only")
def test_datagrams_nothing_received_are_counted_and_the_next_ones_still_go_out(schedule):
    # Nothing listens on the port at first: the host answers each datagram "port unreachable",
    # and the socket fails the send after each. That send did not go out; it must be sent
    # again, or the RTS that comes up misses a datagram of every frame told an error.
    from rts_scenario.playback import playback_not_hit, playback_reasons

    port = _free_udp_port()
    with open_output(f"udp://127.0.0.1:{port}", pacing="fast") as out:
        out.write(schedule.frames(0, 3))
        refused = out.datagrams_sent
        receiver = UdpReceiver(port=port).start()
        try:
            out.write(schedule.frames(3, 6))
            status = out.rts_status(settle_s=0.5)
            gone = out.rts_unreachable()
        finally:
            receiver.stop()
    assert status is not None and status["datagrams"] == out.datagrams_sent - refused
    assert status["frames_applied"] == 3
    assert gone == {"address": f"127.0.0.1:{port}", "datagrams": refused,
                    "error": os.strerror(errno.ECONNREFUSED),
                    "first_s": float(schedule.t_s[0]), "last_s": float(schedule.t_s[2])}
    playback = {"late_frames": 0, "frames_sent": 6, "rts": status, "rts_unreachable": gone}
    (reason,) = [r for r in playback_reasons(playback, frozenset())
                 if r.startswith("rts_unreachable:")]
    assert reason.startswith(f"rts_unreachable: {refused} datagrams to udp://127.0.0.1:{port} "
                             f"came back undelivered (Connection refused) from 0.00 s to 0.10 s")
    assert "nothing listened on that port" in reason
    # Frames the RTS never had are frames lost: expected, they are hit.
    assert playback_reasons(playback, frozenset({"frames_lost"})) == []
    assert playback_not_hit(playback, frozenset({"frames_lost"})) == []


def test_a_stream_everyone_received_says_nothing_came_back(schedule):
    receiver = UdpReceiver().start()
    try:
        with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast") as out:
            out.write(schedule.frames(0, 3))
            assert out.rts_status(settle_s=0.5) is not None
            assert out.rts_unreachable() is None
    finally:
        receiver.stop()


@pytest.mark.parametrize("applied, said", [
    (12, "its echoes came from other directions than the schedule put them in"),
    (0, "it applied none of the run's frames"),
])
def test_a_rig_the_rts_does_not_have_is_said_as_what_it_did(applied, said):
    # An RTS of another rig that played the frames put the echoes elsewhere; one that refused
    # them all played nothing, and the reason must not say it played them from elsewhere.
    from rts_scenario.playback import playback_reasons

    rig = {"front_ends": 4, "geometry_sha256": "a" * 64, "matches_run": False,
           "run": "wide-3x5 (15 FEs)", "run_geometry_sha256": "b" * 64}
    playback = {"late_frames": 0, "frames_sent": 12, "rts_rig": rig,
                "rts": {"datagrams": 12, "frames_applied": applied}}
    (reason,) = [r for r in playback_reasons(playback, frozenset({"frames_lost"}))
                 if r.startswith("rts_rig:")]
    assert reason == (f"rts_rig: the RTS plays a rig of 4 FEs whose geometry (sha256 "
                      f"aaaaaaaaaaaa) is not the run's (wide-3x5 (15 FEs), bbbbbbbbbbbb): {said}; "
                      f"run on the rig the RTS has (emulate: --rig the run's)")


def test_stream_settings_keep_to_the_rig_limits_udp_protocol_md_promises():
    """What an RTS may rely on (docs/udp-protocol.md, Datagram): bounds, grids, stopped entries."""
    import dataclasses
    import struct

    from rts_scenario.outputs.udp import frame_entries
    from rts_scenario.schedule import Status

    scene = load_scenario(ROOT / "scenarios" / "dense_traffic.scenario.yaml")
    limits = dataclasses.replace(scene.rig.limits, attenuation_min_db=2.0,
                                 attenuation_max_db=80.0, attenuation_step_db=0.5,
                                 delay_step_s=1e-10, phase_step_deg=5.625, echoes_per_channel=3)
    rig = dataclasses.replace(scene.rig, limits=limits,
                              cal_phase_deg=np.linspace(-170.0, 170.0, scene.rig.n_front_ends))
    s = build_schedule(compute_tracks(scene), rig, scene.radar, angle_tolerance_deg=(0.5, 1.0))
    changed = s.changed()
    entry = struct.Struct(">HBBhHfdff")
    step_rad = 2.0 * np.pi / round(360.0 / limits.phase_step_deg)
    played = Status.ATTENUATION_CLIPPED | Status.ANGLE_QUANTIZED
    seen = {"emitting": 0, "stopped": 0, "clipped": 0}
    for pos in range(s.n_frames):
        for kind, which in ((KIND_FULL, None), (KIND_DELTA, changed)):
            (datagram,) = encode_frame(frame_entries(s, pos, which), kind=kind, frame=pos,
                                       t_s=float(s.t_s[pos]), first_sequence=0)
            per_fe: dict[int, int] = {}
            for i in range(struct.unpack_from(">H", datagram, 26)[0]):
                _, _, flags, fe, status, att, delay, doppler, phase = entry.unpack_from(
                    datagram, 28 + 28 * i)
                assert flags in (0, 1)
                if not flags:
                    seen["stopped"] += 1
                    assert (fe, att, delay, doppler, phase) == (-1, 0.0, 0.0, 0.0, 0.0)
                    continue
                seen["emitting"] += 1
                seen["clipped"] += bool(status & Status.ATTENUATION_CLIPPED)
                per_fe[fe] = per_fe.get(fe, 0) + 1
                assert status & ~played == 0
                assert limits.attenuation_min_db <= att <= limits.attenuation_max_db
                k = (att - limits.attenuation_min_db) / limits.attenuation_step_db
                assert k == round(k)
                assert delay >= limits.delay_min_s
                assert abs(delay / limits.delay_step_s - round(delay / limits.delay_step_s)) < 1e-6
                assert limits.doppler_min_hz <= doppler <= limits.doppler_max_hz
                assert -np.pi - 1e-6 <= phase < np.pi
                assert abs(phase / step_rad - round(phase / step_rad)) < 1e-5
            if kind == KIND_FULL:
                assert max(per_fe.values(), default=0) <= limits.echoes_per_channel
    assert all(seen.values()), seen


def test_the_receiver_remembers_the_last_sequence_window_numbers_as_documented():
    """udp-protocol.md: the last 4096 sequence numbers tell a copy from a new datagram; an
    older one is stale, however long ago the receiver last pruned what it remembers."""
    entries = np.zeros(4, dtype=ENTRY)
    entries["target"], entries["channel"], entries["flags"] = 0, np.arange(4), 1

    def datagram(n):
        return encode_frame(entries, kind=KIND_FULL, frame=n, t_s=n / 20.0,
                            first_sequence=n)[0]

    for extra in (0, SEQUENCE_WINDOW // 2):  # just after a pruning, and half a window later
        receiver = UdpReceiver()
        newest = 2 * SEQUENCE_WINDOW + 1 + extra
        for n in range(newest + 1):
            receiver.handle(datagram(n))
        receiver.handle(datagram(newest - SEQUENCE_WINDOW + 1))  # the oldest remembered
        assert (receiver.stats.duplicates, receiver.stats.stale) == (1, 0)
        receiver.handle(datagram(newest - SEQUENCE_WINDOW))  # one older: stale
        assert (receiver.stats.duplicates, receiver.stats.stale) == (1, 1)
        receiver.handle(datagram(newest - SEQUENCE_WINDOW - 100))
        assert (receiver.stats.duplicates, receiver.stats.stale) == (1, 2)


def test_a_part_that_disagrees_with_its_frame_s_other_parts_is_malformed():
    """The parts of a frame share its kind, part count and time (udp-protocol.md); a part that
    does not is not assembled into the frame."""
    entries = np.zeros(60, dtype=ENTRY)  # two parts per frame
    entries["target"], entries["channel"], entries["flags"] = np.arange(60) // 4, \
        np.arange(60) % 4, 1
    receiver = UdpReceiver(keep_applied=True)
    first, _ = encode_frame(entries, kind=KIND_FULL, frame=0, t_s=0.0, first_sequence=0)
    _, other_time = encode_frame(entries, kind=KIND_FULL, frame=0, t_s=0.05, first_sequence=0)
    receiver.handle(first)
    receiver.handle(other_time)
    assert (receiver.stats.malformed, receiver.stats.frames_applied) == (1, 0)
    _, second = encode_frame(entries, kind=KIND_FULL, frame=0, t_s=0.0, first_sequence=0)
    receiver.handle(second)
    assert (receiver.stats.malformed, receiver.stats.frames_applied) == (1, 1)


def test_a_delta_stream_is_the_same_however_the_frames_come_in_batches(schedule):
    """A delta lists the targets that changed since the frame before, also across the batches
    a run writes: the first frame of a batch is no full table of every target."""
    def stream(batch_frames):
        out = open_output("udp://127.0.0.1:9", pacing="fast", mode="delta", keyframe_every=20)
        sent = []
        out.send = sent.append
        for start in range(0, schedule.n_frames, batch_frames):
            out.write(schedule.frames(start, start + batch_frames))
        out.close()
        return sent

    whole = stream(schedule.n_frames)
    for size in (1, 37):
        assert stream(size) == whole
    # Against the changes counted frame by frame (keyframes: every active entry).
    receiver = UdpReceiver(keep_applied=True)
    for datagram in whole:
        receiver.handle(datagram)
    assert receiver.stats.clean and receiver.stats.frames_applied == schedule.n_frames
    changed = np.ones(schedule.status.shape, dtype=bool)
    for f in range(1, schedule.n_frames):
        for k in range(schedule.status.shape[1]):
            changed[f, k] = not (
                schedule.status[f, k] == schedule.status[f - 1, k]
                and all(np.array_equal(getattr(schedule, n)[f, k], getattr(schedule, n)[f - 1, k],
                                       equal_nan=getattr(schedule, n).dtype.kind == "f")
                        for n in ("fe", "attenuation_db", "delay_s", "doppler_hz", "phase_rad",
                                  "active")))
    entries = sum(int(schedule.active[f].sum()) if f % 20 == 0
                  else 4 * int(changed[f].sum()) for f in range(schedule.n_frames))
    assert sum(HEADER.unpack_from(d)[8] for d in whole) == entries


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_two_exports_to_one_file_at_once_each_write_their_own(tmp_path, schedule, suffix):
    # Both wrote the same PATH.partial: the second's open cut the first's rows, the first
    # renamed the mix to PATH, and the second then failed; a schedule of two that looked whole.
    from dataclasses import replace

    path = tmp_path / f"s{suffix}"
    first, second = schedule.frames(0, 10), schedule.frames(10, 30)
    with open_output(f"file:{path}") as a, open_output(f"file:{path}") as b:
        a.write(first)
        b.write(second)
        a.write(replace(first, frame_index=first.frame_index + 30))
    # b closed first, then a: PATH is a's schedule, whole (not a mix); nothing else is left.
    got = read_schedule(path)
    assert got.frame_index.tolist() == [*range(10), *range(30, 40)]
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_a_file_export_to_a_link_replaces_the_file_it_names(tmp_path, schedule):
    # The export replaced the link itself, the file it named keeping the old schedule.
    real = tmp_path / "real.csv"
    real.write_text("an earlier export")
    link = tmp_path / "s.csv"
    link.symlink_to(real)
    with open_output(f"file:{link}") as out:
        out.write(schedule.frames(0, 10))
    assert link.is_symlink() and read_schedule(real).n_frames == 10


def test_a_scene_streamed_batch_by_batch_keeps_its_frame_numbers_or_is_refused():
    # The scene in batches of 5 frames, each batch's tracks and schedule built alone. With
    # its frame numbers every frame reaches the RTS; numbered 0..4 again in every batch, the
    # RTS dropped every later batch as stale, and the sender said nothing: now refused.
    from rts_scenario.schedule import ScheduleError

    scene = load_scenario(ROOT / "scenarios" / "cut_in.scenario.yaml")
    frames = np.arange(20)
    receiver = UdpReceiver().start()
    address = f"udp://127.0.0.1:{receiver.address[1]}"
    try:
        with open_output(address, pacing="fast") as out:
            for a in range(0, 20, 5):
                part = frames[a:a + 5]
                tracks = compute_tracks(scene, scene.t_s[part], frame_index=part)
                batch = build_schedule(tracks, scene.rig, scene.radar, frame_index=part)
                np.testing.assert_array_equal(batch.frame_index, part)
                out.write(batch)
            status = out.rts_status(settle_s=0.5)
    finally:
        receiver.stop()
    assert status is not None and status["frames_applied"] == 20
    assert status["stale"] == 0
    first = build_schedule(compute_tracks(scene, scene.t_s[:5]), scene.rig, scene.radar)
    np.testing.assert_array_equal(first.frame_index, np.arange(5))
    with open_output(address, pacing="fast") as out:
        out.write(first)
        with pytest.raises(OutputError, match=r"^udp: frame 0 after frame 4: a stream's frames "
                                              r"go forward .*build_schedule\(\.\.\., "
                                              r"frame_index=\.\.\.\)$"):
            out.write(first)
    tracks = compute_tracks(scene, scene.t_s[:5])
    for bad in (np.arange(4), np.array([0, 1, 1, 2, 3]), np.array([-1, 0, 1, 2, 3]),
                np.linspace(0, 4, 5)):
        with pytest.raises(ScheduleError, match=r"^frame_index: one increasing whole number"):
            build_schedule(tracks, scene.rig, scene.radar, frame_index=bad)


def test_a_copy_the_rts_could_not_read_is_no_one_s_and_no_frame_lost(schedule):
    # A copy of a datagram corrupted on the way: the RTS counts it (datagrams, corrupted) and
    # applies every frame. It is neither another sender's stream (rts_stream) nor a lost frame
    # (the reply to the second-to-last datagram already counted as many datagrams as sent).
    receiver = UdpReceiver().start()
    try:
        with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast") as out:
            out.write(schedule.frames(0, 9))
            good = encode_frame(frame_entries(schedule, 9, None), kind=KIND_FULL, frame=9,
                                t_s=float(schedule.t_s[9]), first_sequence=0)[0]
            out.transmit(good[:-1] + bytes([good[-1] ^ 0xFF]))  # its CRC no longer fits
            out.write(schedule.frames(9, 10))
            status = out.rts_status(settle_s=0.5)
    finally:
        receiver.stop()
    assert status is not None and status["corrupted"] == 1
    assert status["frames_applied"] == 10 and status["lost_frames"] == 0
    assert "foreign_datagrams" not in status


def test_a_delta_stream_lists_unchanged_targets_alike_in_batches_computed_apart(tmp_path):
    # Cars standing before a standing radar: in delta mode they are listed at keyframes only,
    # whether the scene goes in one batch, in batches of 5 or frame by frame (batches
    # computed apart differed by rounding, 1e-12 dB, which re-listed them at batch edges).
    path = tmp_path / "delta.scenario.yaml"
    path.write_text("""\
rts_scenario: 1
name: delta
duration_s: 3.0
frame_rate_hz: 20.0
radar: {profile: awr1843boost, mount: {x_m: 3.7, z_m: 0.5}}
rig: wide-3x5
ego: {motion: {type: stationary, position_m: [0, 0, 0]}}
targets:
  - {name: s1, rcs: {rcs_dbsm: 10}, motion: {type: stationary, position_m: [23.7, 2.0, 0.5]}}
  - {name: s2, rcs: {rcs_dbsm: 10}, motion: {type: stationary, position_m: [33.7, -4.0, 0.9]}}
  - {name: cross, rcs: {rcs_dbsm: 10},
     motion: {type: constant_velocity, position_m: [18.7, 9.0, 0.5], heading_deg: -90,
              speed_mps: 6.0}}
""")
    scene = load_scenario(path)
    n = 60
    streams = []
    for size in (n, 5, 1):
        sent: list[bytes] = []
        out = outputs.udp.UdpOutput("127.0.0.1:9", mode="delta", keyframe_every=50,
                                    pacing="fast")
        out.send = sent.append
        with out:
            for a in range(0, n, size):
                part = np.arange(a, min(n, a + size))
                tracks = compute_tracks(scene, scene.t_s[part], frame_index=part)
                out.write(build_schedule(tracks, scene.rig, scene.radar, frame_index=part))
        streams.append(sent)
    assert len(streams[0]) >= n
    assert streams[1] == streams[0] and streams[2] == streams[0]


def test_frames_the_rts_s_last_reply_does_not_account_for_are_said_as_the_sender_s_count(
        schedule):
    # The last frame's datagrams never reach the RTS: its counters say nothing was lost (the
    # frame is not between two it saw), and the sender counts it. The reason says whose count.
    from rts_scenario.playback import delivery_reasons

    receiver = UdpReceiver().start()
    try:
        with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast") as out:
            out.write(schedule.frames(0, 9))
            out.send = lambda datagram: None  # the last frame: lost on the way
            out.write(schedule.frames(9, 10))
            status = out.rts_status(settle_s=0.3)
    finally:
        receiver.stop()
    assert status is not None and status["frames_applied"] == 9
    assert status["lost_frames"] == status["unaccounted_frames"] == 1
    (reason,) = delivery_reasons(status, None)
    assert reason.startswith("frames_lost: the RTS reports 1 schedule frames it did not apply "
                             "(lost frames 1); 1 of them by the sender's count: frames its last "
                             "reply, waited for at the stream's end, did not count as applied")


@pytest.mark.parametrize(("host", "kind"), [("255.255.255.255", "broadcast"),
                                            ("239.1.2.3", "multicast"), ("[ff02::1]", "multicast")])
def test_a_udp_output_to_a_broadcast_or_multicast_address_is_refused(host, kind):
    # 255.255.255.255 passed the checks before the run and failed at its first frame
    # (a socket may not send there), exit 3 instead of bad input.
    with pytest.raises(OutputError, match=rf"^udp://{re.escape(host)}:5000: .* is a {kind} "
                                          rf"address; give the RTS's own address$"):
        open_output(f"udp://{host}:5000")
