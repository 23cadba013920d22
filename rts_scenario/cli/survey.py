"""``rts-scenario survey``: where the radar sees each front end alone."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import RtsError
from .common import EXIT_OK, add_bench_arguments, bench_of, check_writable_file, writing


def _do_survey(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..pipeline import Pipeline, RunOptions
    from ..scenario.model import RadarOptions
    from ..survey import placed_by_survey, survey

    rig, radar = bench_of(args)
    if args.json:
        check_writable_file("--json", args.json)
    if args.write:
        check_writable_file("--write", args.write)
    if args.place and not args.write:
        raise RtsError("--place: needs --write RIG_OUT (the rig file to write the placed FEs to)")
    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel)
    with Pipeline(rig, radar, options,
                  radar_options=RadarOptions(fidelity=args.fidelity, noise=args.noise,
                                             estimator=args.estimator)) as bench:
        result = survey(rig, radar, bench.play)
    print(result.table())
    from ..radar.simulate import near_field_warning

    note = near_field_warning(radar, rig)
    if note:
        print(f"note: {note}")
    if args.json:
        with writing("--json", args.json):
            Path(args.json).write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False)
                                       + "\n")
        print(f"wrote {args.json}")
    if args.write:
        import dataclasses

        import numpy as np

        seen = np.stack([result.seen_az_deg, result.seen_el_deg, result.level_db], axis=1)
        out = dataclasses.replace(rig, seen=seen)
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
                        help='write {"front_ends": [{"index", "az_deg", "el_deg", "seen_az_deg", '
                             '"seen_el_deg", "level_db"}, ...]}')
    parser.add_argument("--write", metavar="RIG_OUT",
                        help="write the rig with each FE's seen direction and level ('seen')")
    parser.add_argument("--place", action="store_true",
                        help="with --write: move each FE's direction so that the solver's "
                             "modeled response is seen where the radar saw it (a misplaced FE)")
    parser.set_defaults(handler=_do_survey)
