"""What a command loads before and during a run it has no use for.

Any scipy module costs a command about a tenth of a second or more to import (scipy's array
API layer loads numpy.f2py), so the run loads each where it is used: the Hungarian method only
for frames with a choice, the spline only for spline paths, the CFAR filters only in `adc`
frames.
"""

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np

from rts_scenario.check import _assign

ROOT = Path(__file__).resolve().parents[1]


def _printed(code: str) -> str:
    """What ``code`` prints in a fresh interpreter (which must end without an error)."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_a_cut_in_run_loads_no_scipy_module_it_does_not_use():
    # Nor scipy.special: the radar clock's F test is asked only of cycles that depart from a
    # line by more than rounding. Nor the installed estimators (every installed package's
    # entry points, tens of ms): the scene's estimator is a built-in one.
    code = (
        "import sys\n"
        "from rts_scenario.mf4 import defer\n"
        "defer()\n"
        "from rts_scenario.pipeline import run_scene\n"
        "import rts_scenario.registry as registry\n"
        "calls = []\n"
        "registry.entry_points = lambda **kw: calls.append(kw) or ()\n"
        f"result = run_scene({str(ROOT / 'scenarios' / 'cut_in.scenario.yaml')!r})\n"
        "print(result.report.passed)\n"
        "print(' '.join(sorted(m for m in ('scipy.optimize', 'scipy.sparse', 'scipy.ndimage',"
        " 'scipy.interpolate', 'scipy.special') if m in sys.modules)) or 'none')\n"
        "print(len(calls))\n")
    assert _printed(code).split("\n")[:3] == ["True", "none", "0"]


def test_a_run_of_files_found_valid_before_loads_no_json_schema_validator(tmp_path,
                                                                         monkeypatch):
    # Its scene, rig, radar profile and CAN mapping passed their schemas in an earlier run
    # (the disk cache remembers them, `located_yaml.validate`): jsonschema, about 27 ms of
    # the command's start, is not imported. The first run's, on an empty cache of its own,
    # is.
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path))
    code = (
        "import sys\n"
        "from rts_scenario.pipeline import run_scene\n"
        f"result = run_scene({str(ROOT / 'scenarios' / 'cut_in.scenario.yaml')!r})\n"
        "print(result.report.passed, 'jsonschema' in sys.modules)\n")
    first, again = _printed(code), _printed(code)
    assert first.split("\n")[0] == "True True", first
    assert again.split("\n")[0] == "True False", again


def _best_pairs(cost):
    """The cheapest one-to-one choice of pairs, by trying every one (the reference)."""
    rows, cols = cost.shape
    best, chosen = np.inf, None
    for perm in itertools.permutations(range(cols), rows):
        total = sum(cost[r, c] for r, c in enumerate(perm))
        if total < best:
            best, chosen = total, perm
    return {(r, c) for r, c in enumerate(chosen)}


def test_frames_with_a_choice_still_get_the_cheapest_pairs():
    """Two frames: one where the nearest detection of each target is not the answer (the
    greedy choice costs more), one without a choice; the pairs kept are the optimal ones."""
    rng = np.random.default_rng(5)
    cost3 = np.array([[1.0, 2.0, 9.0], [0.5, 8.0, 9.0], [3.0, 3.5, 0.2]])
    det = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2, 3])
    target = np.array([0, 1, 2, 0, 1, 2, 0, 1, 2, 0])
    cost = np.concatenate([cost3.ravel(), [rng.uniform()]])
    frame_of = np.array([0, 0, 0, 1])  # detections 0-2 in frame 0, detection 3 in frame 1
    kept = _assign(frame_of, det, target, cost, n_targets=3)
    pairs = {(int(det[k]), int(target[k])) for k in kept if frame_of[det[k]] == 0}
    assert pairs == _best_pairs(cost3) == {(0, 1), (1, 0), (2, 2)}
    assert 9 in kept  # the frame without a choice keeps its only pair



def test_a_command_imports_with_the_collector_paused_once_and_only_in_its_own_process():
    code = (
        "import gc\n"
        "from rts_scenario.startup import command_imports, mark_command_process\n"
        "seen = []\n"
        "with command_imports():\n"
        "    seen.append((gc.isenabled(), gc.get_freeze_count()))\n"
        "mark_command_process()\n"
        "with command_imports():\n"
        "    import json\n"
        "    seen.append((gc.isenabled(), gc.get_freeze_count()))\n"
        "frozen = gc.get_freeze_count()\n"
        "seen.append((gc.isenabled(), frozen > 0))\n"
        "with command_imports():\n"
        "    seen.append((gc.isenabled(), gc.get_freeze_count() == frozen))\n"
        "print(seen)\n")
    # Unmarked: as it was; marked: paused, then enabled with the objects frozen; once only.
    assert _printed(code).strip() == "[(True, 0), (False, 0), (True, True), (True, True)]"
