"""``rts-scenario list``: shipped scenes, rig presets and radar profiles."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import EXIT_OK


def _do_list(args: argparse.Namespace) -> int:
    from ..errors import RtsError, one_line
    from ..radar.profile import preset_names as radar_presets
    from ..rig import preset_names as rig_presets
    from ..scenario import SCENE_SUFFIX, parametrizations

    scenes = sorted(Path("scenarios").glob(f"*{SCENE_SUFFIX}"))
    print("scenes (scenarios/ in the current folder; a parametrized one with its variants):"
          if scenes else "scenes: none (no scenarios/*.scenario.yaml in the current folder)")
    for scene in scenes:
        try:
            variants = [ident for ident, _ in parametrizations(scene) if ident]
        except RtsError as exc:
            print(f"  {scene.as_posix()} (its parametrize block: {one_line(exc)})")
            continue
        print(f"  {scene.as_posix()}")
        for ident in variants:
            print(f"    [{ident}]")
    print("rig presets:")
    for name in rig_presets():
        print(f"  {name}")
    print("radar profiles:")
    for name in radar_presets():
        print(f"  {name}")
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``list`` subcommand."""
    parser = subparsers.add_parser(
        "list", help="list the shipped scenes, rig presets and radar profiles", parents=parents,
        description="Scenes in scenarios/ under the current folder (each variant of a "
                    "parametrized one, as pytest names it), the rig presets and the radar "
                    "profiles a scene can name.",
    )
    parser.set_defaults(handler=_do_list)
