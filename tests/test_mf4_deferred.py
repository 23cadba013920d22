"""The command defers python-can's MF4 support (asammdf, ~0.7 s) to the first MF4 log.

`rts_scenario.mf4`: a command that uses no MF4 log never loads asammdf; one that records or
reads a MF4 log gets python-can's MF4 writer and reader working as without the deferral.
"""

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("asammdf", reason="asammdf (the 'mf4' extra) is not installed")

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenarios" / "approaching_target.scenario.yaml"


def python(code):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_python_can_loads_without_asammdf_until_a_mf4_log_is_ready():
    out = python(
        "import sys\n"
        "from rts_scenario import mf4\n"
        "mf4.defer()\n"
        "import can, cantools\n"
        "print('before', 'asammdf' in sys.modules, can.io.mf4.asammdf is None)\n"
        "mf4.ready('x.blf')\n"
        "print('blf', 'asammdf' in sys.modules)\n"
        "mf4.ready('x.MF4')\n"
        "print('after', 'asammdf' in sys.modules, can.io.mf4.asammdf is not None)\n")
    assert out.split("\n")[:3] == ["before False True", "blf False", "after True True"]
    # Without the deferral (the library, the pytest plugin) python-can loads it as it does.
    assert python("import sys, can\nprint('asammdf' in sys.modules)").strip() == "True"


def test_the_command_records_and_checks_a_mf4_log(tmp_path):
    scene = tmp_path / "short.scenario.yaml"
    scene.write_text(SCENE.read_text().replace("duration_s: 7.5", "duration_s: 2.0"))
    log = tmp_path / "run.mf4"
    run = subprocess.run([sys.executable, "-m", "rts_scenario", "run", str(scene), "--record",
                          str(log)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    check = subprocess.run([sys.executable, "-m", "rts_scenario", "check", str(scene),
                            "--log", str(log)], capture_output=True, text=True, timeout=300)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "PASS" in check.stdout
    # What was written is a MF4 file asammdf reads (not another format under its name).
    from asammdf import MDF

    assert len(MDF(log).groups) > 0
