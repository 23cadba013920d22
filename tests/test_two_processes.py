"""The bench workflow across processes, as on a real bench: `emulate` is an uncalibrated RTS with
its radar in a process of its own, the schedule goes to it over UDP and its detections come back
on a CAN bus two processes share (python-can's `udp_multicast`, on this host's loopback).

Calibrate it over the network, write the calibrated rig, then run a scene on that rig: it
passes; the same scene on the uncalibrated rig fails on its angles. The injected channel errors
are the known values the calibration must recover.
"""

import itertools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

# In wall-clock time: run with the session's heap frozen (conftest `frozen_heap`).
REAL_TIME = True

GROUP = "239.74.163.{}"
_groups = itertools.count(40 + os.getpid() % 150)


def _multicast_loops_back(group: str) -> bool:
    try:
        import can

        with can.Bus(interface="udp_multicast", channel=group) as a, \
                can.Bus(interface="udp_multicast", channel=group) as b:
            a.send(can.Message(arbitration_id=0x7A, data=b"\x01", is_extended_id=False))
            return b.recv(1.0) is not None
    except Exception:  # no msgpack, no multicast route: the bench cannot be built here
        return False


@pytest.fixture
def group():
    """A multicast group of this test's own; None where multicast does not loop back here."""
    name = GROUP.format(next(_groups))
    return name if _multicast_loops_back(name) else None


def _cli(*args: str, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rts_scenario.cli", *args],
                          capture_output=True, text=True, timeout=timeout)


def _scene(folder: Path, rig: str) -> Path:
    # A car 12 m ahead, 0.8 deg left and 1.5 deg up: inside the kit's one quad.
    x, az, el = 12.0, np.radians(0.8), np.radians(1.5)
    path = folder / f"on-{Path(rig).stem}.scenario.yaml"
    path.write_text(yaml.safe_dump({
        "rts_scenario": 1, "name": f"on-{Path(rig).stem}", "duration_s": 1.5,
        "frame_rate_hz": 20.0, "radar": {"profile": "awr1843boost", "noise": False,
                                         "fidelity": "analytic"},
        "rig": rig,
        "targets": [{"name": "car", "rcs": {"rcs_dbsm": 10.0}, "motion": {
            "type": "stationary",
            "position_m": [float(v) for v in (x * np.cos(el) * np.cos(az),
                                              x * np.cos(el) * np.sin(az), x * np.sin(el))]}}],
        "expectations": {"tolerances": {"range_m": 0.3, "radial_velocity_mps": 0.3,
                                        "az_deg": 0.3, "el_deg": 0.3},
                         "detection_rate": 0.9},
    }, sort_keys=False))
    return path


def test_calibrate_an_emulated_rts_over_the_network_then_run_on_the_calibrated_rig(tmp_path,
                                                                                   group):
    """Across processes where multicast loops back; else the same commands in this process
    against an emulator on a virtual bus (the network path is then loopback UDP only)."""
    if group is None:
        _workflow_in_process(tmp_path)
        return
    # `emulate` outlives the quiet between the three processes (each starts Python, loads its
    # scene and solves it: several seconds on a loaded machine, where 5 s of quiet stopped it
    # before the last run); it is stopped below once they are done.
    emulate = subprocess.Popen(
        [sys.executable, "-m", "rts_scenario.cli", "emulate", "--listen", "udp://127.0.0.1:0",
         "--rig", "kit-table1", "--radar", "awr1843boost", "--can-interface", "udp_multicast",
         "--can-channel", group, "--inject-phase-deg", "180", "--inject-gain-db", "1",
         "--seed", "4", "--seconds", "60", "--wait", "120"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert emulate.stdout is not None
        lines = [emulate.stdout.readline() for _ in range(7)]
        port = re.search(r"listening on udp://127\.0\.0\.1:(\d+);", lines[0])
        assert port, lines
        # The channel errors it plays, relative to FE 0 (its table: FE, phase deg, gain dB).
        assert lines[1].startswith("channel errors injected (--seed 4)"), lines
        injected = np.array([[float(v) for v in line.split()[1:]] for line in lines[3:7]])
        output = f"udp://127.0.0.1:{port.group(1)}"
        bus = ("--can-interface", "udp_multicast", "--can-channel", group)

        def command(*args: str) -> tuple[int, str]:
            done = _cli(*args)
            return done.returncode, done.stdout + done.stderr

        _calibrate_then_run(tmp_path, command, output, bus, injected)
    finally:
        emulate.terminate()
        emulate.communicate(timeout=30)


def _workflow_in_process(tmp_path: Path) -> None:
    import rts_scenario as rs
    from rts_scenario import cli
    from rts_scenario.emulator import Emulator
    from rts_scenario.radar.profile import RadarProfile
    from rts_scenario.radar.simulate import ChannelErrors

    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    rng = np.random.default_rng(4)
    errors = ChannelErrors.random(rig.n_front_ends, rng, phase_deg=180.0, gain_db=1.0)
    injected = np.column_stack([(errors.phase_deg - errors.phase_deg[0] + 180.0) % 360.0
                                - 180.0, errors.gain_db - errors.gain_db[0]])
    channel = f"rts-two-processes-{os.getpid()}"
    emulator = Emulator(rig, radar, can_channel=channel, noise=False, errors=errors,
                        rng=rng).start()

    def command(*args: str) -> tuple[int, str]:
        import contextlib
        import io

        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            code = cli.main(list(args))
        return code, out.getvalue()

    try:
        host, port = emulator.address
        _calibrate_then_run(tmp_path, command, f"udp://{host}:{port}",
                            ("--can-channel", channel), injected)
    finally:
        emulator.stop()


def _calibrate_then_run(tmp_path, command, output, bus, injected) -> None:
    """Calibrate over ``output``, check the injected errors came back, run on both rigs."""
    lab = tmp_path / "lab.rig.yaml"
    report = tmp_path / "cal.json"
    code, text = command("calibrate", "kit-table1", "--radar", "awr1843boost", "--output",
                         output, *bus, "--json", str(report), "--write", str(lab))
    assert code == 0, text
    data = json.loads(report.read_text())
    assert data["passed"] and len(data["pairs"]) == 6 and data["after"]["missed"] == 0
    phase = np.array([c["recovered_phase_deg"] for c in data["channels"]])
    gain = np.array([c["recovered_gain_db"] for c in data["channels"]])
    np.testing.assert_allclose((phase - injected[:, 0] + 180.0) % 360.0 - 180.0, 0.0,
                               atol=0.5)
    np.testing.assert_allclose(gain, injected[:, 1], atol=0.05)
    # The same scene on the rig as the file says and on the calibrated one.
    plain_code, plain = command("run", str(_scene(tmp_path, "kit-table1")), "--output",
                                output, *bus)
    calibrated_code, calibrated = command("run", str(_scene(tmp_path, lab.name)), "--output",
                                          output, *bus)
    assert calibrated_code == 0 and "PASS" in calibrated, calibrated
    # Uncalibrated channels move the synthesized target off its angle (or split it).
    assert plain_code == 1 and "FAIL" in plain, plain
