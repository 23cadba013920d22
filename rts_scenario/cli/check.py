"""``rts-scenario check``: re-check a recorded CAN log against its scene."""

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
    check_number,
    check_writable_file,
    named_file,
    write_json,
)


def _do_check(args: argparse.Namespace) -> int:
    with command_imports():  # paused collector (`rts_scenario.startup`)
        from ..canbus.mapping import CanMapping
        from ..check import tolerances_below_bus_steps
        from ..errors import RtsError
        from ..recheck import check_log, check_log_file, log_variant
        from ..scenario import load_scenario

    if args.mapping:
        named_file("--mapping", CanMapping.from_file, args.mapping)
    if args.log_channel is not None and not args.log_channel.strip():
        raise RtsError(f"--log-channel {args.log_channel!r}: empty; give the channel of the "
                       f"radar's messages as python-can reads it from the log (e.g. 0)")
    if args.time_offset_s is not None:
        # A log time: seconds since 1970 up to the year 2286, or an interface's own clock.
        check_number("--time-offset-s", args.time_offset_s, low=-1e10, high=1e10)
    check_distinct_paths([("--json", args.json)],
                         [("SCENE", args.scene), ("--log", args.log),
                          ("--log's sidecar", f"{args.log}.rts.json"), ("--mapping", args.mapping)])
    if args.json:
        check_writable_file("--json", args.json)
    check_log_file(args.log)
    # A log records one run: of a parametrized scene, the variant --variant or the log's
    # sidecar names, never the file as written.
    variant, overrides = log_variant(args.scene, args.log, args.variant)
    scene = load_scenario(args.scene, overrides)
    if variant:
        print(f"variant {scene.label}" + ("" if args.variant else " (from the log's sidecar)"))
    result = check_log(scene, args.log, mapping=args.mapping, time_offset_s=args.time_offset_s,
                       method=args.method, channel=args.log_channel)
    report = result.report
    print(f"log {args.log}: {result.alignment.describe()}")
    for note in result.alignment.notes:
        print(f"note: {note}")
    if result.mapping is not None:
        # The finer of the classic and the FD messages' steps: the log's bus is not known here.
        for line in tolerances_below_bus_steps(scene.expectations, result.mapping.steps(None),
                                               result.mapping.name):
            print(f"warning: {line}", file=sys.stderr)
    print(report.table())
    if args.json:
        entry = {"file": args.scene, "log": args.log,
                 "status": "pass" if report.passed else "fail", **report.to_dict(),
                 "alignment": result.alignment.to_dict()}
        write_json("--json", args.json, entry)
        print(f"wrote {args.json}")
    return EXIT_OK if report.passed else EXIT_FAIL


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``check`` subcommand."""
    parser = subparsers.add_parser(
        "check", help="re-check a recorded CAN log against its scene", parents=parents,
        description="Decode a CAN log (.blf, .asc, .csv, .log, .trc, .mf4 with asammdf) and check "
                    "its detections against the scene, aligned by time. A log recorded by "
                    "`run --record` is aligned by its sidecar (LOG.rts.json) and gives the live "
                    "verdict; any other log is aligned by its timestamps (offset estimated "
                    "unless --time-offset-s). A log is one run: of a parametrized scene, the "
                    "variant its sidecar or --variant names. Exit 0 pass, 1 fail, 2 bad input, "
                    "3 runtime error.",
    )
    parser.add_argument("scene", metavar="SCENE", help="the *.scenario.yaml that was played")
    parser.add_argument("--log", required=True, metavar="LOG", help="the recorded CAN log")
    parser.add_argument("--mapping", default=None,
                        help="*.mapping.yaml of the radar's DBC (default: the sidecar's, else "
                             "rts-scenario's messages)")
    parser.add_argument("--log-channel", default=None, metavar="CH",
                        help="read only the log's messages of this channel (as python-can reads "
                             "it from the log, e.g. 0 for a BLF's or ASC's first); default: the "
                             "one channel holding the radar's messages (several: the sidecar's, "
                             "else refused, listing them)")
    parser.add_argument("--time-offset-s", type=float, default=None, metavar="S",
                        help="log time of the scene's time 0 (default: estimated from the data)")
    parser.add_argument("--method", default=None, choices=METHODS,
                        help="solver method of the played schedule (default: the sidecar's, "
                             "else exact)")
    parser.add_argument("--variant", default=None, metavar="ID",
                        help="the combination of the scene's parametrize block the log is of, "
                             "as pytest names it (default: the sidecar's; a parametrized scene "
                             "needs one of them)")
    parser.add_argument("--json", metavar="REPORT", help="write the report as JSON")
    parser.set_defaults(handler=_do_check)
