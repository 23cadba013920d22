"""``rts-scenario calibrate``: phase and gain of the RTS channels."""

from __future__ import annotations

import argparse
from typing import Any

from .common import (
    EXIT_OK,
    Progress,
    add_bench_arguments,
    bench_of,
    check_number,
    check_writable_file,
    check_writable_folder,
    writing,
)

MAX_INJECT_GAIN_DB = 20.0


def _do_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import calibration as cal
    from ..errors import RtsError
    from ..pipeline import Pipeline, RunOptions
    from ..radar.simulate import ChannelErrors
    from ..rig import Rig
    from ..scenario.model import RadarOptions

    check_number("--inject-phase-deg", args.inject_phase_deg, low=0.0, high=180.0)
    check_number("--inject-gain-db", args.inject_gain_db, low=0.0, high=MAX_INJECT_GAIN_DB)
    if args.seed < 0:
        raise RtsError(f"--seed: must be >= 0, got {args.seed}")
    rig, radar = bench_of(args)
    if args.write:
        check_writable_file("--write", args.write)
    if args.plot:
        from ..plots import require_matplotlib

        require_matplotlib()
        check_writable_folder("--plot", args.plot)
    rng = np.random.default_rng(args.seed)
    errors = ChannelErrors.random(rig.n_front_ends, rng, phase_deg=args.inject_phase_deg,
                                  gain_db=args.inject_gain_db)
    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel or f"rts-calibrate-{args.seed}")
    radar_options = RadarOptions(fidelity=args.fidelity, noise=args.noise)

    def bench(on: Rig) -> Pipeline:
        # The same physical bench (injected errors included) driven with the rig's settings.
        return Pipeline(on, radar, options, radar_options=radar_options, errors=errors, rng=rng)

    with bench(rig) as pipeline:
        before = cal.grid_errors(rig, radar, pipeline.play)
        result = cal.calibrate(rig, radar, pipeline.play, progress=Progress("calibrate"))
    calibrated = result.apply(rig)
    with bench(calibrated) as pipeline:
        after = cal.grid_errors(calibrated, radar, pipeline.play)
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
        with writing("--write", args.write):
            calibrated.write(args.write)
        print(f"wrote {args.write}")
    if args.plot:
        from ..plots import write_calibration_plot

        with writing("--plot", args.plot):
            written = write_calibration_plot(result, args.plot, rig.name)
        print(f"wrote {written}")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``calibrate`` subcommand."""
    parser = subparsers.add_parser(
        "calibrate", help="calibrate the phase and gain of the RTS channels", parents=parents,
        description="Pairwise phase sweeps, then each pair at its coherence point, through the "
                    "output and the CAN checker; least squares over all pairs gives per-channel "
                    "phase and gain offsets. On the simulated radar, --inject-* adds random "
                    "channel errors to recover.",
    )
    add_bench_arguments(parser, "paper")
    parser.add_argument("--inject-phase-deg", type=float, default=0.0,
                        help="simulated radar: random channel phase errors within +-this "
                             "(0..180)")
    parser.add_argument("--inject-gain-db", type=float, default=0.0,
                        help="simulated radar: random channel gain errors within +-this "
                             f"(0..{MAX_INJECT_GAIN_DB:g})")
    parser.add_argument("--seed", type=int, default=0, help="seed of the injected errors (>= 0)")
    parser.add_argument("--write", metavar="RIG_OUT", help="write the calibrated rig file")
    parser.add_argument("--plot", metavar="DIR", help="plot the sweeps (needs matplotlib)")
    parser.set_defaults(handler=_do_calibrate)
