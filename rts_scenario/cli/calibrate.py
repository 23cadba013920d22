"""``rts-scenario calibrate``: phase and gain of the RTS channels."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from typing import Any

from .common import (
    EXIT_FAIL,
    EXIT_OK,
    Progress,
    add_bench_arguments,
    bench_of,
    check_bench_paths,
    check_number,
    check_rig_out,
    check_writable_file,
    check_writable_folder,
    host_clock_lines,
    mapping_record,
    write_json,
    writing,
)

MAX_INJECT_GAIN_DB = 20.0
# The library's default, without importing numpy and scipy to build the parser.
MAX_EXCESS_ERROR_DEG = 0.1

# What the command reads of each detection (a --mapping must carry them).
MEASURED = ("range_m", "azimuth_deg", "elevation_deg", "rcs_dbsm")


def _do_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import calibration as cal
    from ..errors import MeasurementError, RtsError
    from ..pipeline import Pipeline, RunOptions
    from ..radar.simulate import ChannelErrors
    from ..rig import Rig
    from ..scenario.model import RadarOptions

    check_number("--inject-phase-deg", args.inject_phase_deg, low=0.0, high=180.0)
    check_number("--inject-gain-db", args.inject_gain_db, low=0.0, high=MAX_INJECT_GAIN_DB)
    if args.seed < 0:
        raise RtsError(f"--seed: must be >= 0, got {args.seed}")
    if args.output != "simulated-radar" and (args.inject_phase_deg or args.inject_gain_db):
        # The errors would be drawn and never played: a real RTS's channels carry their own.
        which = "--inject-phase-deg" if args.inject_phase_deg else "--inject-gain-db"
        raise RtsError(f"{which}: injects errors into the built-in simulated radar's channels; "
                       f"with --output {args.output} the RTS's channels carry their own (to "
                       f"rehearse, give the errors to `rts-scenario emulate --inject-phase-deg "
                       f"... --inject-gain-db ...`)")
    if not (math.isfinite(args.max_error_deg) and args.max_error_deg > 0.0):
        raise RtsError(f"--max-error-deg: must be a finite number > 0, got "
                       f"{args.max_error_deg}")
    rig, radar = bench_of(args, "calibrate", MEASURED)
    check_bench_paths(args, [("--json", args.json), ("--write", args.write),
                             ("--plot", args.plot)])
    if args.json:
        check_writable_file("--json", args.json)
    if args.write:
        check_rig_out("--write", args.write)
    if args.plot:
        from ..plots import require_matplotlib

        require_matplotlib()
        check_writable_folder("--plot", args.plot)
    rng = np.random.default_rng(args.seed)
    errors = ChannelErrors.random(rig.n_front_ends, rng, phase_deg=args.inject_phase_deg,
                                  gain_db=args.inject_gain_db)
    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel or f"rts-calibrate-{args.seed}",
                         can_fd=args.can_fd, radar_channel=args.radar_channel,
                         mapping=args.mapping)
    radar_options = RadarOptions(fidelity=args.fidelity, noise=args.noise,
                                 estimator=args.estimator)
    # The check grid's weights: exact for a Bartlett radar, aimed at any other estimator.
    method = "exact" if args.estimator == "bartlett" else "estimator"

    benches: list[Pipeline] = []

    def bench(on: Rig) -> Pipeline:
        # The same physical bench (injected errors included) driven with the rig's settings.
        benches.append(Pipeline(on, radar, options, radar_options=radar_options, errors=errors,
                                rng=rng))
        return benches[-1]

    def late_note() -> str:
        late = sum(b.measurement_late_frames for b in benches)
        return (f"{late} pattern frames went out after the radar cycle that measures them "
                f"(the host held the sender)" if late else "")

    # The steps of the host's clock during the measurements, numbered over both benches.
    steps: list[dict[str, Any]] = []
    # The messages of other channels than --radar-channel skipped, over both benches.
    other_channels = 0
    try:
        # Check-grid measurements played a second time (the calibration's are its own).
        grid_again: list[str] = []
        with bench(rig) as pipeline:
            before = cal.check_grid(rig, radar, pipeline.play, method, args.estimator,
                                    grid_again, "check grid before calibration")
            result = cal.calibrate(rig, radar, pipeline.play, estimator=args.estimator,
                                   progress=Progress("calibrate", unit="FE pairs measured",
                                                     minimum=1))
        steps += pipeline.measurement_steps
        other_channels += pipeline.measurement_other_channels
        calibrated = result.apply(rig)
        with bench(calibrated) as checked:
            after = cal.check_grid(calibrated, radar, checked.play, method, args.estimator,
                                   grid_again, "check grid after calibration")
        result = dataclasses.replace(result, remeasured=(*result.remeasured, *grid_again))
        steps += [{**s, "measurement": int(s["measurement"]) + pipeline.measurements}
                  for s in checked.measurement_steps]
        other_channels += checked.measurement_other_channels
    except MeasurementError as exc:
        # The radar's cycles mixed with another bus's (or none on --radar-channel), or a
        # pair it did not report: a measurement that failed, as a calibration that did not
        # pass does.
        late = late_note()
        print(f"error: calibrate: {exc}{f'; {late}' if late else ''}; nothing written",
              file=sys.stderr)
        return EXIT_FAIL
    failed = cal.failures(result, before, after, args.max_error_deg, radar=radar.name,
                          estimator=args.estimator)
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
    if result.remeasured:
        late = late_note()
        print(f"note: measured again, some cycles missing the first time: "
              f"{', '.join(result.remeasured)}{f'; {late}' if late else ''}")

    def summary(grid: cal.GridCheck) -> str:
        stats = grid.summary()
        played = f" ({stats['not_played']} not played)" if stats["not_played"] else ""
        if stats["max_error_deg"] is None:
            return f"none measured, {stats['missed']} missed{played}"
        return (f"rms {stats['rms_error_deg']:.4f} deg, max {stats['max_error_deg']:.4f} deg "
                f"({stats['max_excess_error_deg']:.4f} off the predicted angle), "
                f"{stats['missed']} missed{played}")

    print(f"angle error before: {summary(before)}")
    print(f"angle error after:  {summary(after)}")
    for line in host_clock_lines(steps):
        print(line)
    if args.json:
        write_json("--json", args.json, {
            **calibration_report(result, errors if injected else None, before, after,
                                 args.estimator, method, failed),
            "mapping": mapping_record(args.mapping), "can_fd": args.can_fd,
            "radar_channel": args.radar_channel,
            "other_channels": None if args.radar_channel is None else other_channels,
            "host_clock_steps": steps})
        print(f"wrote {args.json}")
    if args.plot:
        from ..plots import write_calibration_plot

        with writing("--plot", args.plot):
            written = write_calibration_plot(result, args.plot, rig.name)
        print(f"wrote {written}")
    if failed:
        # A rig is a promise that its offsets were measured and verified: none from a failure.
        for reason in failed:
            print(f"error: calibration failed: {reason}", file=sys.stderr)
        if args.write:
            print(f"error: --write {args.write}: not written (a rig is written only from a "
                  f"calibration that passed)", file=sys.stderr)
        return EXIT_FAIL
    print("calibration passed")
    if args.write:
        with writing("--write", args.write):
            calibrated.write(args.write)
        print(f"wrote {args.write}")
    return EXIT_OK


def calibration_report(result: Any, errors: Any, before: Any, after: Any, estimator: str,
                       method: str, failed: list[str]) -> dict[str, Any]:
    """Return the ``--json`` document (docs/cli.md).

    The verdict (``passed`` and the ``reasons`` it failed), per channel the injected and
    recovered offsets (relative to FE 0; injected ones null on a real bench) and its level
    played alone, per pair the swept channel's weight played and the residuals, the
    measurements played a second time, and the check grid's errors (`GridCheck.summary`)
    before and after.
    """
    import numpy as np

    def wrap(deg: float) -> float:
        return float((deg + 180.0) % 360.0 - 180.0)

    def number(x: float) -> float | None:
        return float(x) if np.isfinite(x) else None

    channels = []
    for q in range(result.phase_deg.size):
        channels.append({
            "fe": q,
            "injected_phase_deg": None if errors is None
            else wrap(errors.phase_deg[q] - errors.phase_deg[0]),
            "recovered_phase_deg": wrap(result.phase_deg[q]),
            "injected_gain_db": None if errors is None
            else float(errors.gain_db[q] - errors.gain_db[0]),
            "recovered_gain_db": float(result.gain_db[q]),
            "single_rcs_dbsm": number(result.single_rcs_dbsm[q]),
        })
    pairs = [{"fe_a": p.a, "fe_b": p.b, "phase_deg": p.phase_deg, "gain_db": p.gain_db,
              "swept_weight_db": p.weight_db,
              "phase_residual_deg": float(rp), "gain_residual_db": float(rg),
              "fit_rms_deg": number(p.fit_rms_deg)}
             for p, rp, rg in zip(result.pairs, result.phase_residual_deg,
                                  result.gain_residual_db, strict=True)]
    return {"passed": not failed, "reasons": failed, "estimator": estimator, "method": method,
            "channels": channels, "pairs": pairs, "suspects": result.suspects,
            "remeasured": list(result.remeasured),
            "before": before.summary(), "after": after.summary()}


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``calibrate`` subcommand."""
    parser = subparsers.add_parser(
        "calibrate", help="calibrate the phase and gain of the RTS channels", parents=parents,
        description="Each FE alone first (its level at the radar, the RCS it reports), "
                    "then pairwise delay sweeps (converted to phase by the rig's RTS delay "
                    "model), the swept channel's weight set from those levels so that it "
                    "arrives at half the other's amplitude, through the output and the CAN "
                    "checker; each sweep fitted with the radar's array, its modeled FE "
                    "responses and its estimator; least squares over all pairs gives "
                    "per-channel phase and gain offsets. Each cycle is read at its strongest "
                    "detection within a gate about the pattern's echo (its range, from the "
                    "played delay, plus or minus two range bins; its radial velocity, -1 m/s, "
                    "plus or minus two velocity bins), never at a stronger reflection in the "
                    "room; an FE or pair with detections but none in the gate fails, naming "
                    "the strongest outside it. On the simulated radar, --inject-* adds random "
                    "channel errors to recover.",
    )
    add_bench_arguments(parser, "paper")
    parser.add_argument("--json", metavar="OUT",
                        help="write channels, pair residuals and grid errors as JSON")
    parser.add_argument("--inject-phase-deg", type=float, default=0.0,
                        help="simulated radar: random channel phase errors within +-this "
                             "(0..180)")
    parser.add_argument("--inject-gain-db", type=float, default=0.0,
                        help="simulated radar: random channel gain errors within +-this "
                             f"(0..{MAX_INJECT_GAIN_DB:g})")
    parser.add_argument("--seed", type=int, default=0, help="seed of the injected errors (>= 0)")
    parser.add_argument("--max-error-deg", type=float, default=MAX_EXCESS_ERROR_DEG,
                        help="fail when, after calibration, the radar sees a check-grid point "
                             "further than this off the angle the schedule predicts (default "
                             f"{MAX_EXCESS_ERROR_DEG:g})")
    parser.add_argument("--write", metavar="RIG_OUT",
                        help="write the calibrated rig file (only if the calibration passed)")
    parser.add_argument("--plot", metavar="DIR", help="plot the sweeps (needs matplotlib)")
    parser.set_defaults(handler=_do_calibrate)
