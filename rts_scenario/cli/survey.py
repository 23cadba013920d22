"""``rts-scenario survey``: where the radar sees each front end alone."""

from __future__ import annotations

import argparse
from typing import Any

from .common import (
    EXIT_OK,
    check_can_interface,
    check_output,
    check_writable_file,
    preset_or_file,
    writing,
)


def _do_survey(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..pipeline import Pipeline, RunOptions
    from ..radar.profile import RadarProfile
    from ..radar.profile import preset_names as radar_presets
    from ..rig import Rig
    from ..rig import preset_names as rig_presets
    from ..scenario.model import RadarOptions
    from ..survey import survey

    check_output("--output", args.output, run=True)
    check_can_interface("--can-interface", args.can_interface)
    if args.json:
        check_writable_file("--json", args.json)
    if args.write:
        check_writable_file("--write", args.write)
    rig = preset_or_file("RIG", args.rig, rig_presets(), Rig.preset, Rig.from_file,
                         ".rig.yaml")
    radar = preset_or_file("--radar", args.radar, radar_presets(), RadarProfile.preset,
                           RadarProfile.from_file, ".radar.yaml")
    options = RunOptions(output=args.output, can_interface=args.can_interface,
                         can_channel=args.can_channel)
    with Pipeline(rig, radar, options,
                  radar_options=RadarOptions(fidelity=args.fidelity, noise=args.noise)) as bench:
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
        with writing("--write", args.write):
            dataclasses.replace(rig, seen=seen).write(args.write)
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
    parser.add_argument("rig", metavar="RIG", help="rig preset or *.rig.yaml")
    parser.add_argument("--radar", default="awr1843boost",
                        help="radar profile (default awr1843boost)")
    parser.add_argument("--output", default="simulated-radar",
                        help="simulated-radar (default) or udp://HOST:PORT")
    parser.add_argument("--can-interface", default="virtual")
    parser.add_argument("--can-channel", default=None)
    parser.add_argument("--fidelity", default="analytic", choices=["analytic", "adc"])
    parser.add_argument("--noise", action="store_true", help="thermal noise (simulated)")
    parser.add_argument("--json", metavar="OUT",
                        help='write {"front_ends": [{"index", "az_deg", "el_deg", "seen_az_deg", '
                             '"seen_el_deg", "level_db"}, ...]}')
    parser.add_argument("--write", metavar="RIG_OUT",
                        help="write the rig with each FE's seen direction and level ('seen')")
    parser.set_defaults(handler=_do_survey)
