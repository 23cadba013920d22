"""``rts-scenario schedule``: export a scene's schedule to an output."""

from __future__ import annotations

import argparse
from typing import Any

from .common import EXIT_OK


def _do_schedule(args: argparse.Namespace) -> int:
    from ..kinematics import compute_tracks
    from ..outputs import open_output
    from ..scenario import load_scenario
    from ..schedule import build_schedule

    scene = load_scenario(args.scene)
    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar, method=args.method,
                              frame_rate_hz=scene.frame_rate_hz)
    with open_output(args.output) as out:
        out.write(schedule)
    emitted = schedule.emitted
    print(f"{args.scene}: {schedule.n_frames} frames x {len(schedule.names)} targets, "
          f"{emitted.mean():.0%} of entries emitted -> {args.output}")
    return EXIT_OK


def add_parser(subparsers: Any) -> None:
    """Add the ``schedule`` subcommand."""
    parser = subparsers.add_parser(
        "schedule", help="export a scene's schedule",
        description="Build a scene's schedule and send it to an output (no radar, no check).",
    )
    parser.add_argument("scene", metavar="SCENE")
    parser.add_argument("--output", required=True, help="file:PATH (.npz, .csv) or udp://...")
    parser.add_argument("--method", default="exact", choices=["exact", "paper"])
    parser.set_defaults(handler=_do_schedule)
