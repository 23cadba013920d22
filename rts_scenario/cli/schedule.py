"""``rts-scenario schedule``: export a scene's schedule to an output."""

from __future__ import annotations

import argparse
from typing import Any

from .common import EXIT_OK, METHODS, check_distinct_paths, check_output

# Target-frames per batch: the schedule streams to the output like a run does.
_BATCH_TARGET_FRAMES = 200_000


def _do_schedule(args: argparse.Namespace) -> int:
    from dataclasses import replace

    import numpy as np

    from ..kinematics import compute_tracks
    from ..outputs import open_output, split_spec
    from ..scenario import load_scenario, select_variant
    from ..schedule import build_schedule

    check_output("--output", args.output, run=False)
    name, argument = split_spec(args.output)
    if name == "file":
        check_distinct_paths([("--output", argument)], [("SCENE", args.scene)])
    _, overrides = select_variant(args.scene, args.variant)
    scene = load_scenario(args.scene, overrides)
    step = max(1, _BATCH_TARGET_FRAMES // max(1, len(scene.targets)))
    emitted = total = 0
    with open_output(args.output) as out:
        for first in range(0, scene.n_frames, step):
            frames = np.arange(first, min(first + step, scene.n_frames))
            schedule = build_schedule(compute_tracks(scene, scene.t_s[frames], frames),
                                      scene.rig, scene.radar, method=args.method,
                                      estimator=scene.radar_options.estimator,
                                      frame_rate_hz=scene.frame_rate_hz)
            out.write(replace(schedule, frame_index=frames))
            emitted += int(schedule.emitted.sum())
            total += schedule.emitted.size
    label = f"{args.scene}[{scene.variant}]" if scene.variant else args.scene
    print(f"{label}: {scene.n_frames} frames x {len(scene.targets)} targets, "
          f"{emitted / max(total, 1):.0%} of entries emitted -> {args.output}")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``schedule`` subcommand."""
    parser = subparsers.add_parser(
        "schedule", help="export a scene's schedule", parents=parents,
        description="Build a scene's schedule and send it to an output (no radar, no check).",
    )
    parser.add_argument("scene", metavar="SCENE")
    parser.add_argument("--output", required=True, help="file:PATH (.npz, .csv) or udp://...")
    parser.add_argument("--method", default="exact", choices=METHODS)
    parser.add_argument("--variant", default=None, metavar="ID",
                        help="the combination of the scene's parametrize block, as pytest names "
                             "it (a parametrized scene needs one)")
    parser.set_defaults(handler=_do_schedule)
