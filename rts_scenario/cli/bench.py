"""``rts-scenario bench``: speed against angle error of every solver method."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import RtsError
from .common import EXIT_OK, writing


def _do_bench(args: argparse.Namespace) -> int:
    from .. import bench

    if args.targets < 1 or args.repeats < 1:
        raise RtsError(
            f"--targets and --repeats: must be >= 1, got {args.targets} and {args.repeats}"
        )
    if not 0.0 <= args.scene_s <= 86400.0:
        raise RtsError(f"--scene-s: must be within 0..86400 s (0: no end-to-end run), "
                       f"got {args.scene_s}")
    rows = bench.run(targets=args.targets, repeats=args.repeats, rig_name=args.rig)
    print(bench.format_table(rows))
    quantized = bench.quantization(rig_name=args.rig)
    print()
    print(bench.format_quantization(quantized))
    end = None
    if args.scene_s > 0:
        end = bench.end_to_end(args.scene_s)
        print()
        print(bench.format_end_to_end(end))
    if args.json:
        with writing("--json", args.json):
            bench.write_json(rows, quantized, args.json, end)
        print(f"wrote {args.json}")
    return EXIT_OK


def add_parser(subparsers: Any) -> None:
    """Add the ``bench`` subcommand."""
    parser = subparsers.add_parser(
        "bench", help="speed against angle error of every solver method",
        description="Table of solver methods x array presets: throughput (target-frames/s) and "
                    "angle error measured by an independent beamformer peak search.",
    )
    parser.add_argument("--json", metavar="OUT", help="also write the table as JSON")
    parser.add_argument("--scene-s", type=float, default=60.0,
                        help="length of the motorway scene run end to end through the pipeline "
                             "(default 60 s; 0 skips it)")
    parser.add_argument("--targets", type=int, default=1_000_000,
                        help="targets per throughput run (default 1,000,000)")
    parser.add_argument("--repeats", type=int, default=3, help="throughput runs, best kept")
    parser.add_argument("--rig", default="kit-table1", help="rig preset (default kit-table1)")
    parser.set_defaults(handler=_do_bench)
