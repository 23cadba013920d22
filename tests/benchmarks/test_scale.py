"""Hundreds of targets: a 60 s run's time per target-frame and its memory against 8 targets.

Run: ``pytest tests/benchmarks/test_scale.py -s``. Each run is a fresh process (its peak
resident memory is its own), 8 targets and 512 targets in the same session: the analytic
radar, CAN FD (a classic frame numbers 256 detections per cycle), targets 12-60 m away
across +-15 deg on the wide grid with enough echo slots per channel. Acceptance: time per
target-frame at 512 targets at most 2x the 8-target case; memory linear in targets.
"""

import json
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import json, sys, tempfile, time
    from pathlib import Path
    import numpy as np, yaml
    from rts_scenario.pipeline import RunOptions, run_scene
    from rts_scenario.scenario import load_scenario

    k, duration = int(sys.argv[1]), float(sys.argv[2])
    folder = Path(tempfile.mkdtemp())
    source = Path(sys.argv[3]).read_text()
    rig = yaml.safe_load(source)
    rig["name"] = "wide-many"
    rig.setdefault("limits", {})["echoes_per_channel"] = 1024
    (folder / "wide.rig.yaml").write_text(yaml.safe_dump(rig))
    rng = np.random.default_rng(5)
    targets = []
    for i in range(k):
        x, az = 12 + 48 * i / k, np.radians(rng.uniform(-15, 15))
        targets.append({"name": f"t{i}", "frame": "ego", "rcs": {"rcs_dbsm": 10.0},
                        "motion": {"type": "constant_velocity",
                                   "position_m": [float(x), float(x * np.tan(az)), 0.6],
                                   "speed_mps": float(rng.uniform(0, 0.2))}})
    scene = {"rts_scenario": 1, "name": f"scale-{k}", "duration_s": duration,
             "frame_rate_hz": 20.0, "rig": "wide.rig.yaml", "seed": 1,
             "radar": {"profile": "awr1843boost", "fidelity": "analytic"},
             "ego": {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                                "speed_mps": 22.0}},
             "targets": targets}
    path = folder / "scale.scenario.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    loaded = load_scenario(path)
    start = time.perf_counter()
    result = run_scene(loaded, RunOptions(can_fd=True))
    seconds = time.perf_counter() - start
    peak = next(int(line.split()[1]) for line in open("/proc/self/status")
                if line.startswith("VmHWM"))
    print(json.dumps({"targets": k, "frames": loaded.n_frames, "seconds": seconds,
                      "peak_mb": peak / 1024, "passed": result.report.passed,
                      "timing": result.report.timing}))
""")


def _run(k: int, duration_s: float) -> dict:
    from importlib import resources

    rig = resources.files("rts_scenario").joinpath("data/rigs/wide-3x5.rig.yaml")
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(k), str(duration_s), str(rig)],
                         capture_output=True, text=True, check=True, timeout=1800)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("duration_s", [60.0])
def test_512_targets_cost_per_target_frame_and_memory(duration_s):
    runs = {k: _run(k, duration_s) for k in (8, 128, 512)}
    per_tf = {k: r["seconds"] / (k * r["frames"]) for k, r in runs.items()}
    print()
    for k, r in runs.items():
        print(f"{k:4d} targets x {r['frames']} frames: {r['seconds']:6.2f} s, "
              f"{per_tf[k] * 1e6:6.1f} us per target-frame, peak {r['peak_mb']:6.0f} MB, "
              f"passed {r['passed']}")
    ratio = per_tf[512] / per_tf[8]
    slope = (runs[512]["peak_mb"] - runs[128]["peak_mb"]) / 384
    print(f"512 vs 8 targets per target-frame: {ratio:.2f}x; memory "
          f"{slope:.2f} MB per added target (128 -> 512)")
    assert all(r["passed"] for r in runs.values())
    assert ratio <= 2.0
    # Linear in targets: the 128 -> 512 slope no steeper than the 8 -> 128 one (with slack).
    first = (runs[128]["peak_mb"] - runs[8]["peak_mb"]) / 120
    assert slope <= max(2.0 * first, 0.5)
