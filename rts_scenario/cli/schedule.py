"""``rts-scenario schedule``: export a scene's schedule to an output."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..startup import command_imports
from .common import (
    EXIT_FAIL,
    EXIT_OK,
    METHODS,
    check_distinct_paths,
    check_output,
    read_by_scenes,
)


def _do_schedule(args: argparse.Namespace) -> int:
    from dataclasses import replace

    with command_imports():  # paused collector (`rts_scenario.startup`)
        from ..outputs import open_output, split_spec
        from ..pipeline import RTS_SETTLE_S
        from ..playback import delivery_reasons, rts_rig_record, stream_reasons
        from ..preflight import LimitCounter, schedule_batches
        from ..scenario import load_scenario, select_variant

    check_output("--output", args.output, run=False)
    name, argument = split_spec(args.output)
    if name == "file":
        check_distinct_paths([("--output", argument)], [("SCENE", args.scene)])
    _, overrides = select_variant(args.scene, args.variant)
    if name == "file":
        check_distinct_paths([("--output", argument)], read_by_scenes([(args.scene, overrides)]))
    scene = load_scenario(args.scene, overrides)
    emitted = total = 0
    limits = LimitCounter(scene)
    with open_output(args.output) as out:
        # In batches of bounded size, as a run streams them: memory does not grow with the scene.
        for frames, tracks, schedule in schedule_batches(scene, args.method):
            out.write(replace(schedule, frame_index=frames))
            emitted += int(schedule.emitted.sum())
            total += schedule.emitted.size
            limits.add(tracks, schedule)
        # What the RTS (or the network) said of the stream, as `run` judges it: an export
        # nothing received is no success.
        rts = out.rts_status(settle_s=RTS_SETTLE_S)
        gone = out.rts_unreachable()
        rig = rts_rig_record(out.rts_rig(), scene.rig)
    label = f"{args.scene}[{scene.variant}]" if scene.variant else args.scene
    # What the schedule does not play as specified, as validate and run say it.
    for line in limits.result().unexpected():
        print(f"warning: {label}: {line}", file=sys.stderr)
    print(f"{label}: {scene.n_frames} frames x {len(scene.targets)} targets, "
          f"{emitted / max(total, 1):.0%} of entries emitted -> {args.output}")
    # As `run` judges them: a scene that declares frames_lost (an RTS that drops some) is told
    # of them, not failed.
    # Another rig, or another sender's stream, fails it whatever the scene declares: what the
    # RTS played is not this schedule.
    foreign = stream_reasons(rts, rig, "schedule")
    for problem in foreign:
        print(f"error: {problem}", file=sys.stderr)
    problems = delivery_reasons(rts, gone, "of the schedule")
    declared = "frames_lost" in scene.expectations.expected_limits
    for problem in problems:
        print(f"note: {problem} (the scene declares frames_lost)" if declared
              else f"error: {problem}", file=sys.stderr)
    return EXIT_FAIL if foreign or (problems and not declared) else EXIT_OK


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
