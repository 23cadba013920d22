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


class _Progress:
    """A one-line progress bar on stderr, only when it is a terminal."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.active = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        if not self.active or total < 200:
            return
        width = 30
        filled = int(width * done / total)
        sys.stderr.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total} frames")
        if done >= total:
            sys.stderr.write("\r" + " " * (len(self.label) + width + 24) + "\r")
        sys.stderr.flush()


def _run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from .runner import RunOptions, run_scene

    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel, can_fd=args.can_fd,
                         mapping=args.mapping, method=args.method)
    reports = []
    for path in args.scenes:
        result = run_scene(path, options, progress=_Progress(Path(path).name))
        report = result.report
        reports.append(report.to_dict())
        print(report.table())
        print("timing: " + ", ".join(f"{k.removesuffix('_s')} {v * 1e3:.0f} ms"
                                     for k, v in report.timing.items()))
        if args.plot:
            from .plots import write_plots

            for written in write_plots(result, args.plot):
                print(f"wrote {written}")
        print()
    if args.json:
        payload = reports[0] if len(reports) == 1 else reports
        Path(args.json).write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {args.json}")
    return EXIT_OK if all(r["passed"] for r in reports) else EXIT_FAIL


def _schedule(args: argparse.Namespace) -> int:
    from .kinematics import compute_tracks
    from .outputs import open_output
    from .scenario import load_scenario
    from .schedule import build_schedule

    scene = load_scenario(args.scene)
    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar, method=args.method,
                              frame_rate_hz=scene.frame_rate_hz)
    with open_output(args.output) as out:
        out.write(schedule)
    emitted = schedule.emitted
    print(f"{args.scene}: {schedule.n_frames} frames x {len(schedule.names)} targets, "
          f"{emitted.mean():.0%} of entries emitted -> {args.output}")
    return EXIT_OK


def _list_outputs(args: argparse.Namespace) -> int:
    from .outputs import available_outputs

    for name in available_outputs():
        print(name)
    return EXIT_OK


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

    run = sub.add_parser(
        "run", help="run scenes end to end and check the radar",
        description="Load each scene, build its schedule, play it (by default on the built-in "
                    "simulated radar), read the detections over CAN and check them. Exit 0 if "
                    "every scene passes, 1 if one fails, 2 on bad input.",
    )
    run.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    run.add_argument("--output", default="simulated-radar",
                     help="simulated-radar (default), udp://HOST:PORT or file:PATH")
    run.add_argument("--can-interface", default="virtual",
                     help="python-can interface (default virtual)")
    run.add_argument("--can-channel", default=None, help="CAN channel (default: private)")
    run.add_argument("--can-fd", action="store_true", help="CAN FD detection messages")
    run.add_argument("--mapping", default=None,
                     help="*.mapping.yaml for a third-party radar's DBC")
    run.add_argument("--method", default="exact", choices=["exact", "paper"],
                     help="weight solver (default exact)")
    run.add_argument("--json", metavar="REPORT", help="write the report as JSON")
    run.add_argument("--plot", metavar="DIR", help="write PNG plots (needs matplotlib)")
    run.set_defaults(handler=_run)

    schedule = sub.add_parser(
        "schedule", help="export a scene's schedule",
        description="Build a scene's schedule and send it to an output (no radar, no check).",
    )
    schedule.add_argument("scene", metavar="SCENE")
    schedule.add_argument("--output", required=True, help="file:PATH (.npz, .csv) or udp://...")
    schedule.add_argument("--method", default="exact", choices=["exact", "paper"])
    schedule.set_defaults(handler=_schedule)

    outputs = sub.add_parser("list-outputs", help="list the available outputs")
    outputs.set_defaults(handler=_list_outputs)
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
