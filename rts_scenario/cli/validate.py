"""``rts-scenario validate``: load and check scene files."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from .common import EXIT_BAD_INPUT, EXIT_OK


def _do_validate(args: argparse.Namespace) -> int:
    from ..errors import ScenarioError
    from ..kinematics import compute_tracks
    from ..scenario import load_scenario

    failed = 0
    for path in args.scenes:
        try:
            scene = load_scenario(path)
            tracks = compute_tracks(scene)
        except ScenarioError as exc:
            print(f"error: {exc}", file=sys.stderr)
            failed += 1
            continue
        share = tracks.checkable.mean() if tracks.checkable.size else 0.0
        print(f"ok: {path}: {scene.n_frames} frames, {len(scene.targets)} targets, "
              f"{share:.0%} of target-frames checkable")
    return EXIT_BAD_INPUT if failed else EXIT_OK


def add_parser(subparsers: Any) -> None:
    """Add the ``validate`` subcommand."""
    parser = subparsers.add_parser(
        "validate", help="check scene files",
        description="Load and check scene files; exit 0 if all are valid, 2 otherwise.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    parser.set_defaults(handler=_do_validate)
