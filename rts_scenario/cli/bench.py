"""``rts-scenario bench``: speed against angle error of every solver method."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import RtsError
from .common import EXIT_OK, check_number, check_writable_file, report_written, writing

# One throughput run holds a few arrays of this many targets in memory (about 1 kB each).
MAX_TARGETS = 10_000_000
MAX_REPEATS = 100


def _do_bench(args: argparse.Namespace) -> int:
    from .. import bench
    from ..rig import preset_names

    if not 1 <= args.targets <= MAX_TARGETS:
        raise RtsError(f"--targets: must be within 1..{MAX_TARGETS}, got {args.targets}")
    if not 1 <= args.repeats <= MAX_REPEATS:
        raise RtsError(f"--repeats: must be within 1..{MAX_REPEATS}, got {args.repeats}")
    check_number("--scene-s", args.scene_s, low=0.0, high=86400.0)
    check_number("--scale-s", args.scale_s, low=0.0, high=3600.0)
    if args.rig not in preset_names():
        raise RtsError(f"unknown rig preset {args.rig!r}; valid presets: "
                       f"{', '.join(preset_names())} (--rig)")
    if args.json:
        check_writable_file("--json", args.json)
    if args.markdown:
        check_writable_file("--markdown", args.markdown)
        if args.json and Path(args.json).resolve() == Path(args.markdown).resolve():
            raise RtsError(f"--json {args.json} and --markdown {args.markdown}: the same file; "
                           f"give each its own")
    rows = bench.run(targets=args.targets, repeats=args.repeats, rig_name=args.rig)
    print(bench.format_table(rows))
    quantized = bench.quantization(rig_name=args.rig)
    print()
    print(bench.format_quantization(quantized))
    honest_rows = [] if args.no_honest else bench.honest(rig_name=args.rig)
    if honest_rows:
        print()
        print(bench.format_honest(honest_rows))
    end = None
    if args.scene_s > 0:
        end = bench.end_to_end(args.scene_s)
        print()
        print(bench.format_end_to_end(end))
    figures = []
    if not args.no_performance:
        from .. import perf

        # The shipped cut-in scene: from the current folder, else beside the package's source.
        shipped = Path("scenarios") / "cut_in.scenario.yaml"
        beside = Path(perf.__file__).resolve().parent.parent / shipped
        cut_in = next((p for p in (shipped, beside) if p.is_file()), None)
        if cut_in is None:
            print(f"note: {shipped} not found here or beside the package: the repeated cut-in "
                  f"run is not measured", file=sys.stderr)
        figures = perf.all_figures(cut_in, args.scale_s)
        print()
        print(perf.format_figures(figures))
    if args.json:
        with writing("--json", args.json):
            bench.write_json(rows, quantized, args.json, end, honest_rows, figures)
        report_written(args.json)
        print(f"wrote {args.json}")
    if args.markdown:
        with writing("--markdown", args.markdown):
            bench.write_markdown(rows, quantized, args.markdown, end, honest_rows, figures)
        print(f"wrote {args.markdown}")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``bench`` subcommand."""
    parser = subparsers.add_parser(
        "bench", help="speed against angle error of every solver method", parents=parents,
        description="Table of solver methods x array presets: throughput (target-frames/s) and "
                    "angle error measured by an independent beamformer peak search.",
    )
    parser.add_argument("--json", metavar="OUT", help="also write the table as JSON")
    parser.add_argument("--markdown", metavar="OUT",
                        help="also write the tables as Markdown, as the README shows them")
    parser.add_argument("--scene-s", type=float, default=60.0,
                        help="length of the motorway scene run end to end through the pipeline "
                             "(default 60 s; 0 skips it)")
    parser.add_argument("--targets", type=int, default=1_000_000,
                        help="targets per throughput run (default 1,000,000)")
    parser.add_argument("--repeats", type=int, default=3,
                        help="throughput runs, best kept (default 3)")
    parser.add_argument("--rig", default="kit-table1", help="rig preset (default kit-table1)")
    parser.add_argument("--no-performance", action="store_true",
                        help="skip the performance figures (CAN, solver against the paper "
                             "method, radar, quantization, 512 targets, start-up), each "
                             "measured beside its comparison")
    parser.add_argument("--scale-s", type=float, default=60.0,
                        help="length of the 8- and 512-target runs of the performance "
                             "figures (default 60; 0 skips them)")
    parser.add_argument("--no-honest", action="store_true",
                        help="skip the honest-bench rows (method x radar x estimator x "
                             "fidelity on the simulated radar)")
    parser.set_defaults(handler=_do_bench)
