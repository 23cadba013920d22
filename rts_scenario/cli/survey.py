"""``rts-scenario survey``: where the radar sees each front end alone."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..errors import MeasurementError, RtsError
from .common import (
    EXIT_FAIL,
    EXIT_OK,
    add_bench_arguments,
    bench_of,
    check_bench_paths,
    check_rig_out,
    check_writable_file,
    host_clock_lines,
    mapping_record,
    write_json,
    writing,
)

# What the command reads of each detection (a --mapping must carry them).
MEASURED = ("azimuth_deg", "elevation_deg", "rcs_dbsm")


def _do_survey(args: argparse.Namespace) -> int:
    import numpy as np

    from ..pipeline import Pipeline, RunOptions
    from ..scenario.model import RadarOptions
    from ..survey import placed_by_survey, survey

    rig, radar = bench_of(args, "survey", MEASURED)
    if args.place and not args.write:
        raise RtsError("--place: needs --write RIG_OUT (the rig file to write the placed FEs to)")
    check_bench_paths(args, [("--json", args.json), ("--write", args.write)])
    if args.json:
        check_writable_file("--json", args.json)
    if args.write:
        check_rig_out("--write", args.write)
    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel, can_fd=args.can_fd,
                         radar_channel=args.radar_channel, mapping=args.mapping)
    try:
        with Pipeline(rig, radar, options,
                      radar_options=RadarOptions(fidelity=args.fidelity, noise=args.noise,
                                                 estimator=args.estimator)) as bench:
            result = survey(rig, radar, bench.play)
    except MeasurementError as exc:
        # The radar's cycles mixed with another bus's (or none on --radar-channel): a
        # measurement that failed, as one missing an FE does.
        print(f"error: survey: {exc}; nothing written", file=sys.stderr)
        return EXIT_FAIL
    steps = bench.measurement_steps
    seen = np.isfinite(result.seen_az_deg) & np.isfinite(result.seen_el_deg)
    if not seen.any():
        # A measurement that failed, as one missing an FE (below): not bad input.
        channel = f":{args.can_channel}" if args.can_channel else ""
        print(f"error: survey: the radar saw none of the {rig.n_front_ends} front ends (no "
              f"detection came over CAN {args.can_interface}{channel} while {args.output} "
              f"played them); check that the radar sees the rig and reports on that bus; "
              f"nothing written", file=sys.stderr)
        return EXIT_FAIL
    print(result.table())
    if bench.measurement_late_frames:
        print(f"note: {bench.measurement_late_frames} pattern frames went out after the radar "
              f"cycle that measures them (the host held the sender): not measured")
    for line in host_clock_lines(steps):
        print(line)
    from ..radar.simulate import near_field_warning

    note = near_field_warning(radar, rig)
    if note:
        print(f"note: {note}")
    if args.json:
        write_json("--json", args.json, {
            **result.to_dict(), "mapping": mapping_record(args.mapping),
            "can_fd": args.can_fd, "radar_channel": args.radar_channel,
            "other_channels": None if args.radar_channel is None
            else bench.measurement_other_channels,
            "host_clock_steps": steps})
        print(f"wrote {args.json}")
    missed = [str(q) for q in np.flatnonzero(~seen)]
    if missed:
        # Printed and in the JSON (null), but never stored in a rig as if it had been measured.
        fes = f"FE{'s' if len(missed) > 1 else ''} {', '.join(missed)}"
        print(f"error: the radar did not see {fes}" + (
            f"; --write {args.write}: not written (a rig is written only from a survey that saw "
            f"every front end)" if args.write else ""), file=sys.stderr)
        return EXIT_FAIL
    if args.write:
        import dataclasses

        measured = np.stack([result.seen_az_deg, result.seen_el_deg, result.level_db], axis=1)
        out = dataclasses.replace(rig, seen=measured)
        if args.place:
            out = placed_by_survey(rig, radar, result, estimator=args.estimator)
            for q in range(rig.n_front_ends):
                print(f"FE {q} placed at az {out.az_deg[q]:+.4f} el {out.el_deg[q]:+.4f} deg "
                      f"(moved {out.az_deg[q] - rig.az_deg[q]:+.4f}, "
                      f"{out.el_deg[q] - rig.el_deg[q]:+.4f})")
        with writing("--write", args.write):
            out.write(args.write)
        print(f"wrote {args.write}")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``survey`` subcommand."""
    parser = subparsers.add_parser(
        "survey", help="where the radar sees each front end alone", parents=parents,
        description="Play each front end alone at the rig's reference range and level and report "
                    "where the radar sees it and how strong (simulated radar, or a real bench "
                    "over --output and CAN).",
    )
    add_bench_arguments(parser, "awr1843boost")
    parser.add_argument("--json", metavar="OUT",
                        help='write {"rig", "radar", "front_ends": [{"index", "az_deg", "el_deg", '
                             '"seen_az_deg", "seen_el_deg", "level_db"}, ...], "mapping", '
                             '"can_fd", "radar_channel", "other_channels", '
                             '"host_clock_steps": [...]}')
    parser.add_argument("--write", metavar="RIG_OUT",
                        help="write the rig with each FE's seen direction and level ('seen')")
    parser.add_argument("--place", action="store_true",
                        help="with --write: move each FE's direction so that the solver's "
                             "modeled response is seen where the radar saw it (a misplaced FE)")
    parser.set_defaults(handler=_do_survey)
