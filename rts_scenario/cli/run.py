"""``rts-scenario run``: run scenes end to end and check the radar."""

from __future__ import annotations

import argparse
from typing import Any

from .common import EXIT_FAIL, EXIT_OK, Progress, writing


def _do_run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..pipeline import RunOptions, run_scene

    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel, can_fd=args.can_fd,
                         mapping=args.mapping, method=args.method, record=bool(args.plot))
    reports = []
    for path in args.scenes:
        result = run_scene(path, options, progress=Progress(Path(path).name))
        report = result.report
        reports.append(report.to_dict())
        print(report.table())
        print("timing: " + ", ".join(
            f"{k.removesuffix('_s')} {v * 1e3:.0f} ms"
            + (f" ({report.solver_plan})" if k == "plan_s" else "")
            for k, v in report.timing.items()))
        if args.plot:
            from ..plots import write_plots

            with writing("--plot", args.plot):
                written_plots = write_plots(result, args.plot)
            for written in written_plots:
                print(f"wrote {written}")
        print()
    if args.json:
        payload = reports[0] if len(reports) == 1 else reports
        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {args.json}")
    return EXIT_OK if all(r["passed"] for r in reports) else EXIT_FAIL


def add_parser(subparsers: Any) -> None:
    """Add the ``run`` subcommand."""
    parser = subparsers.add_parser(
        "run", help="run scenes end to end and check the radar",
        description="Load each scene, build its schedule, play it (by default on the built-in "
                    "simulated radar), read the detections over CAN and check them. Exit 0 if "
                    "every scene passes, 1 if one fails, 2 on bad input.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    parser.add_argument("--output", default="simulated-radar",
                        help="simulated-radar (default), udp://HOST:PORT or file:PATH")
    parser.add_argument("--can-interface", default="virtual",
                        help="python-can interface (default virtual)")
    parser.add_argument("--can-channel", default=None, help="CAN channel (default: private)")
    parser.add_argument("--can-fd", action="store_true", help="CAN FD detection messages")
    parser.add_argument("--mapping", default=None,
                        help="*.mapping.yaml for a third-party radar's DBC")
    parser.add_argument("--method", default="exact", choices=["exact", "paper"],
                        help="weight solver (default exact)")
    parser.add_argument("--json", metavar="REPORT", help="write the report as JSON")
    parser.add_argument("--plot", metavar="DIR", help="write PNG plots (needs matplotlib)")
    parser.set_defaults(handler=_do_run)
