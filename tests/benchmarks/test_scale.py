"""Hundreds of targets: a 60 s run's time per target-frame and its memory against 8 targets.

Run: ``pytest tests/benchmarks/test_scale.py -s``. Each run is a fresh process (its peak
resident memory is its own): the analytic radar, CAN FD (a classic frame numbers 256 detections
per cycle), targets 12-60 m away across +-15 deg on the wide grid with enough echo slots per
channel (`rts_scenario.perf.scale_run`). Acceptance: time per target-frame at 512 targets at
most 2x the 8-target case; memory linear in targets (its growth per target from 320 to 512 no
steeper than twice that from 128 to 320: `rts_scenario.perf.MEMORY_TARGETS`).
"""

from rts_scenario import perf


def test_512_targets_cost_per_target_frame_and_memory():
    runs = {k: perf.scale_run(k, 60.0) for k in (8, *perf.MEMORY_TARGETS, 512)}
    per_tf = {k: r["seconds"] / (k * r["frames"]) for k, r in runs.items()}
    print()
    for k, r in runs.items():
        print(f"{k:4d} targets x {r['frames']} frames: {r['seconds']:6.2f} s, "
              f"{per_tf[k] * 1e6:6.1f} us per target-frame, peak {r['peak_mb']:6.0f} MB, "
              f"passed {r['passed']}")
    ratio = per_tf[512] / per_tf[8]
    first, slope, linear = perf.memory_slopes({k: runs[k] for k in (*perf.MEMORY_TARGETS, 512)})
    print(f"512 vs 8 targets per target-frame: {ratio:.2f}x; memory {first:.2f} MB per added "
          f"target (128 -> 320), {slope:.2f} MB (320 -> 512)")
    assert all(r["passed"] for r in runs.values())
    assert ratio <= perf.SCALE_GOAL
    # Linear in targets: the 320 -> 512 slope no steeper than twice the 128 -> 320 one.
    assert linear
