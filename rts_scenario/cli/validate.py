"""``rts-scenario validate``: check scene files the way ``run`` will use them."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from .common import EXIT_BAD_INPUT, EXIT_OK, located

if TYPE_CHECKING:
    from ..scenario import Scenario

# Target-frames per schedule batch: validation streams like a run, so memory stays bounded.
_BATCH_TARGET_FRAMES = 200_000


def schedule_limits(scene: Scenario, method: str = "exact") -> dict[str, dict[str, int]]:
    """Build the whole schedule batch by batch; count the frames each target hits a limit.

    Returns ``{target: {status flag name: frames}}`` for every flag but ``NOT_PRESENT`` (a
    target outside its presence window is the scene's intent, not a limit).

    Raises
    ------
    ScheduleError
        When ``run`` would fail to build the schedule (e.g. the rig's update rate).
    """
    import numpy as np

    from ..kinematics import compute_tracks
    from ..schedule import Status, build_schedule

    names = [t.name for t in scene.targets]
    flags = [f for f in Status if f not in (Status.OK, Status.NOT_PRESENT)]
    counts = np.zeros((len(flags), len(names)), dtype=np.int64)
    step = max(1, _BATCH_TARGET_FRAMES // max(1, len(names)))
    t_all = scene.t_s
    for first in range(0, scene.n_frames, step):
        frames = np.arange(first, min(first + step, scene.n_frames))
        tracks = compute_tracks(scene, t_all[frames], frames)
        status = build_schedule(tracks, scene.rig, scene.radar, method=method,
                                frame_rate_hz=scene.frame_rate_hz).status
        for i, flag in enumerate(flags):
            counts[i] += np.count_nonzero(status & flag, axis=0)
    return {name: {str(flag.name): int(counts[i, k]) for i, flag in enumerate(flags)
                   if counts[i, k]}
            for k, name in enumerate(names)}


def _do_validate(args: argparse.Namespace) -> int:
    from ..errors import RtsError
    from ..scenario import load_scenario, parametrizations

    bad = 0
    for path in args.scenes:
        try:
            combos = parametrizations(path)
        except RtsError as exc:
            print(f"error: {located(path, exc)}", file=sys.stderr)
            bad += 1
            continue
        reported: set[str] = set()
        for ident, overrides in combos:
            label = f"{path}[{ident}]" if ident else str(path)
            try:
                scene = load_scenario(path, overrides)
                limits = schedule_limits(scene, args.method)
            except RtsError as exc:
                bad += 1
                message = located(path, exc)
                if message not in reported:  # an error every combination shares, once
                    reported.add(message)
                    where = f" [{ident}]" if ident else ""
                    print(f"error: {message}{where}", file=sys.stderr)
                continue
            kind = "error" if args.strict else "warning"
            for target, hits in limits.items():
                for flag, frames in hits.items():
                    print(f"{kind}: {label}: target {target!r}: {flag} in {frames} of "
                          f"{scene.n_frames} frames", file=sys.stderr)
                    bad += args.strict
            if not (args.strict and any(limits.values())):
                print(f"ok: {label}: {scene.n_frames} frames, {len(scene.targets)} targets, "
                      f"schedule built")
    return EXIT_BAD_INPUT if bad else EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``validate`` subcommand."""
    parser = subparsers.add_parser(
        "validate", help="check scene files", parents=parents,
        description="Load each scene and every combination of its parametrize block and build "
                    "its schedule, as run does; print a warning per target and bench limit it "
                    "hits (out of coverage, too close, ...). Exit 0 if all are valid, 2 "
                    "otherwise.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    parser.add_argument("--strict", action="store_true",
                        help="a target hitting a bench limit is an error (exit 2)")
    parser.add_argument("--method", default="exact", choices=["exact", "paper"],
                        help="weight solver the schedule is built with (default exact)")
    parser.set_defaults(handler=_do_validate)
