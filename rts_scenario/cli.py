"""Command line: ``rts-scenario SUBCOMMAND ...``.

Exit codes: 0 success, 1 a check failed, 2 bad input. Errors print ``error: ...`` without a
traceback unless ``--debug`` is given.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from .errors import RtsError

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_BAD_INPUT = 2


def _bench(args: argparse.Namespace) -> int:
    from . import bench

    if args.targets < 1 or args.repeats < 1:
        raise RtsError(
            f"--targets and --repeats: must be >= 1, got {args.targets} and {args.repeats}"
        )
    rows = bench.run(targets=args.targets, repeats=args.repeats, rig_name=args.rig)
    print(bench.format_table(rows))
    quantized = bench.quantization(rig_name=args.rig)
    print()
    print(bench.format_quantization(quantized))
    if args.json:
        bench.write_json(rows, quantized, args.json)
        print(f"wrote {args.json}")
    return EXIT_OK


def _validate(args: argparse.Namespace) -> int:
    from .errors import ScenarioError
    from .kinematics import compute_tracks
    from .scenario import load_scenario

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


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="rts-scenario",
        description="Replay traffic scenes on a radar target simulator with 2-D angle of arrival.",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    bench = sub.add_parser(
        "bench", help="speed against angle error of every solver method",
        description="Table of solver methods x array presets: throughput (target-frames/s) and "
                    "angle error measured by an independent beamformer peak search.",
    )
    bench.add_argument("--json", metavar="OUT", help="also write the table as JSON")
    bench.add_argument("--targets", type=int, default=1_000_000,
                       help="targets per throughput run (default 1,000,000)")
    bench.add_argument("--repeats", type=int, default=3, help="throughput runs, best kept")
    bench.add_argument("--rig", default="kit-table1", help="rig preset (default kit-table1)")
    bench.set_defaults(handler=_bench)

    validate = sub.add_parser(
        "validate", help="check scene files",
        description="Load and check scene files; exit 0 if all are valid, 2 otherwise.",
    )
    validate.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    validate.set_defaults(handler=_validate)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.handler(args)
        return code
    except RtsError as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_FAIL


if __name__ == "__main__":
    sys.exit(main())
