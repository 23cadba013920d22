"""``rts-scenario import``: an OpenSCENARIO 1.x file (a documented subset) as a scene file."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from .common import EXIT_OK, check_distinct_paths, check_number, check_writable_file


def _scene_reference(option: str, name: str, presets: list[str], suffix: str,
                     output: Path) -> str:
    """How the scene written to ``output`` names a preset or a file an option gives."""
    from ..errors import RtsError

    if name in presets:
        return name
    path = Path(name)
    if not name.endswith(suffix) and path.is_file():
        # A file of another kind says what it is.
        from ..file_kinds import refuse_other_kind
        from ..located_yaml import load_yaml

        try:
            data = load_yaml(path).data
        except RtsError:
            data = None  # not YAML: no kind to tell
        try:
            refuse_other_kind(name, data, suffix)
        except RtsError as exc:
            raise RtsError(f"{option} {exc}") from None
    if not name.endswith(suffix) or not path.is_file():
        raise RtsError(f"{option} {name!r}: unknown preset and no such *{suffix} file; valid "
                       f"presets: {', '.join(presets)}")
    folder = output.resolve().parent
    resolved = path.resolve()
    if not resolved.is_relative_to(folder):
        raise RtsError(f"{option} {name}: a scene refers to files inside its own folder tree; "
                       f"put the file under {folder} or write the scene next to it")
    return Path(os.path.relpath(resolved, folder)).as_posix()


def _parameters(values: list[str]) -> dict[str, str]:
    from ..errors import RtsError

    out: dict[str, str] = {}
    for item in values:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise RtsError(f"--param {item!r}: expected NAME=VALUE")
        name, value = name.strip(), value.strip()
        # With or without its $: one parameter.
        same = next((given for given in out if given.lstrip("$") == name.lstrip("$")), None)
        if same is not None:
            raise RtsError(f"--param {name}: given twice ({same}={out[same]} and "
                           f"{name}={value}); give each parameter once")
        out[name] = value
    return out


def _do_import(args: argparse.Namespace) -> int:
    from ..errors import RtsError, located
    from ..preflight import preflight
    from ..radar.profile import preset_names as radar_presets
    from ..rig import preset_names as rig_presets
    from ..scenario import SCENE_SUFFIX, load_scenario
    from ..xosc import import_xosc
    from .common import one_line, writing

    output = Path(args.output)
    if not args.output.endswith(SCENE_SUFFIX):
        raise RtsError(f"--output {args.output}: a scene file's name ends in {SCENE_SUFFIX}")
    check_distinct_paths([("--output", output)], [("FILE.xosc", args.file),
                                                   ("--radar", args.radar), ("--rig", args.rig)])
    check_writable_file("--output", output, ".scenario.yaml")
    check_number("--frame-rate-hz", args.frame_rate_hz, low=0.001, high=1000.0)
    check_number("--lane-width-m", args.lane_width_m, low=0.5, high=10.0)
    radar = _scene_reference("--radar", args.radar, radar_presets(), ".radar.yaml", output)
    rig = _scene_reference("--rig", args.rig, rig_presets(), ".rig.yaml", output)
    result = import_xosc(args.file, radar=radar, rig=rig, ego=args.ego,
                         parameters=_parameters(args.param or []),
                         name=output.name.removesuffix(SCENE_SUFFIX),
                         frame_rate_hz=args.frame_rate_hz, lane_width_m=args.lane_width_m)
    # Written next to the output (its relative references hold there) and loaded first: a
    # scene that does not load neither replaces the output nor stays on disk.
    draft = output.with_name(f".{output.name}.{os.getpid()}.draft{SCENE_SUFFIX}")
    try:
        with writing("--output", output):
            with open(draft, "w", encoding="utf-8") as file:
                file.write(result.text)
        try:
            scene = load_scenario(draft)  # what validate and run will read
        except RtsError as exc:
            reason = one_line(exc).replace(str(draft), str(output))
            # Named by the .xosc element the failing key came from, where the import knows it.
            source = result.source_of(getattr(exc, "key_path", None))
            where = (f"{args.file}{f':{source[1]}' if source[1] else ''}: <{source[0]}>"
                     if source else args.file)
            raise RtsError(f"{where}: the scene it converts to does not load (a value "
                           f"beyond the scene format's or the bench's limits); {output} not "
                           f"written: {reason}") from None
        try:
            pre = preflight(scene)  # its whole schedule, built as validate and run build it
        except RtsError as exc:
            reason = located(str(output), exc).replace(str(draft), str(output))
            raise RtsError(f"{args.file}: the scene it converts to cannot be played (its "
                           f"schedule cannot be built); {output} not written: "
                           f"{reason}") from None
        with writing("--output", output):
            os.replace(draft, output)
    finally:
        draft.unlink(missing_ok=True)
    for note in result.notes:
        print(f"note: {note}")
    # What a run of it fails on unless the scene declares it (expected_limits), as validate
    # says it.
    for line in pre.unexpected():
        print(f"warning: {output}: {line}", file=sys.stderr)
    print(f"imported {args.file} -> {output}: ego {result.ego}, {len(scene.targets)} targets, "
          f"{scene.duration_s:g} s")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``import`` subcommand."""
    parser = subparsers.add_parser(
        "import", help="convert an OpenSCENARIO 1.x file to a scene file", parents=parents,
        description="Convert an OpenSCENARIO 1.x file (the subset in docs/import.md: world "
                    "positions, speed and lateral actions, time and distance triggers; no road "
                    "network) to a *.scenario.yaml scene with the ego as the radar carrier. "
                    "Anything outside the subset is one error naming the element and its line.",
    )
    parser.add_argument("file", metavar="FILE.xosc", help="OpenSCENARIO file")
    parser.add_argument("--radar", required=True, help="radar profile preset or *.radar.yaml")
    parser.add_argument("--rig", required=True, help="rig preset or *.rig.yaml")
    parser.add_argument("--ego", default=None,
                        help="entity carrying the radar (default: the one named Ego, any case, "
                             "else the first)")
    parser.add_argument("--param", action="append", metavar="NAME=VALUE",
                        help="override a declared parameter (repeatable)")
    parser.add_argument("--output", required=True, metavar="OUT.scenario.yaml",
                        help="scene file to write")
    parser.add_argument("--frame-rate-hz", type=float, default=20.0,
                        help="the scene's frame rate (default 20)")
    parser.add_argument("--lane-width-m", type=float, default=3.5,
                        help="lane width for RelativeTargetLane (default 3.5)")
    parser.set_defaults(handler=_do_import)
