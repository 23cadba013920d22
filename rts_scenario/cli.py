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


def _calibrate(args: argparse.Namespace) -> int:
    import can
    import numpy as np

    from . import calibration as cal
    from .canbus import DetectionPublisher, DetectionReceiver, open_bus
    from .outputs import Output, open_output
    from .outputs.radar import SimulatedRadarOutput
    from .radar.profile import RadarProfile
    from .radar.profile import preset_names as radar_presets
    from .radar.simulate import ChannelErrors
    from .rig import Rig
    from .rig import preset_names as rig_presets

    rig = Rig.preset(args.rig) if args.rig in rig_presets() else Rig.from_file(args.rig)
    radar = (RadarProfile.preset(args.radar) if args.radar in radar_presets()
             else RadarProfile.from_file(args.radar))
    rng = np.random.default_rng(args.seed)
    errors = ChannelErrors.random(rig.n_front_ends, rng, phase_deg=args.inject_phase_deg,
                                  gain_db=args.inject_gain_db)
    channel = args.can_channel or f"rts-calibrate-{args.seed}"
    listen = open_bus(args.can_interface, channel)
    talk = None
    receiver = DetectionReceiver()
    notifier = can.Notifier(listen, [receiver], timeout=0.05)
    output: Output
    try:
        if args.output == "simulated-radar":
            talk = open_bus(args.can_interface, channel)
            publisher = DetectionPublisher(talk)
            output = SimulatedRadarOutput(profile=radar, rig=rig, sink=publisher.publish,
                                          fidelity=args.fidelity, noise=args.noise,
                                          errors=errors, rng=rng)
        else:
            output = open_output(args.output)
        measure = cal.can_measure(output, receiver)
        before = cal.grid_errors(rig, radar, measure)
        result = cal.calibrate(rig, radar, measure, progress=_Progress("calibrate"))
        calibrated = result.apply(rig)
        if args.output == "simulated-radar":
            output = SimulatedRadarOutput(profile=radar, rig=calibrated, sink=publisher.publish,
                                          fidelity=args.fidelity, noise=args.noise,
                                          errors=errors, rng=rng)
            measure = cal.can_measure(output, receiver)
        after = cal.grid_errors(calibrated, radar, measure)
    finally:
        notifier.stop()
        listen.shutdown()
        if talk is not None:
            talk.shutdown()
    injected = args.output == "simulated-radar" and (args.inject_phase_deg or args.inject_gain_db)
    print(f"{'FE':>3} {'phase deg':>10} {'gain dB':>8}"
          + (f" {'injected phase':>15} {'injected gain':>14}" if injected else ""))
    for q in range(rig.n_front_ends):
        line = f"{q:>3} {result.phase_deg[q]:>10.2f} {result.gain_db[q]:>8.3f}"
        if injected:
            ref_p = (errors.phase_deg[q] - errors.phase_deg[0] + 180) % 360 - 180
            line += f" {ref_p:>15.2f} {errors.gain_db[q] - errors.gain_db[0]:>14.3f}"
        print(line)
    print("pair residuals: " + ", ".join(
        f"{p.a}-{p.b} {rp:+.2f} deg {rg:+.3f} dB" for p, rp, rg in
        zip(result.pairs, result.phase_residual_deg, result.gain_residual_db, strict=True)))
    for suspect in result.suspects:
        print(f"suspect: {suspect}")

    def summary(err: np.ndarray) -> str:
        mag = np.hypot(err[:, 0], err[:, 1])
        return (f"rms {np.sqrt(np.nanmean(mag**2)):.4f} deg, max {np.nanmax(mag):.4f} deg, "
                f"{int(np.isnan(mag).sum())} missed")

    print(f"angle error before: {summary(before)}")
    print(f"angle error after:  {summary(after)}")
    if args.write:
        cal.write_rig(calibrated, args.write)
        print(f"wrote {args.write}")
    if args.plot:
        from .plots import write_calibration_plot

        print(f"wrote {write_calibration_plot(result, args.plot, rig.name)}")
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

    calibrate = sub.add_parser(
        "calibrate", help="calibrate the phase and gain of the RTS channels",
        description="Pairwise phase sweeps, then each pair at its coherence point, through the "
                    "output and the CAN checker; least squares over all pairs gives per-channel "
                    "phase and gain offsets. On the simulated radar, --inject-* adds random "
                    "channel errors to recover.",
    )
    calibrate.add_argument("rig", metavar="RIG", help="rig preset or *.rig.yaml")
    calibrate.add_argument("--radar", default="paper", help="radar profile (default paper)")
    calibrate.add_argument("--output", default="simulated-radar",
                           help="simulated-radar (default) or udp://HOST:PORT")
    calibrate.add_argument("--can-interface", default="virtual")
    calibrate.add_argument("--can-channel", default=None)
    calibrate.add_argument("--fidelity", default="analytic", choices=["analytic", "adc"])
    calibrate.add_argument("--noise", action="store_true", help="thermal noise (simulated)")
    calibrate.add_argument("--inject-phase-deg", type=float, default=0.0,
                           help="simulated radar: random channel phase errors within +-this")
    calibrate.add_argument("--inject-gain-db", type=float, default=0.0,
                           help="simulated radar: random channel gain errors within +-this")
    calibrate.add_argument("--seed", type=int, default=0, help="seed of the injected errors")
    calibrate.add_argument("--write", metavar="RIG_OUT", help="write the calibrated rig file")
    calibrate.add_argument("--plot", metavar="DIR", help="plot the sweeps (needs matplotlib)")
    calibrate.set_defaults(handler=_calibrate)

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
