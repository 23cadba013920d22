"""``rts-scenario validate``: check scene files the way ``run`` will use them."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..errors import located
from ..startup import command_imports
from .common import EXIT_BAD_INPUT, EXIT_OK, METHODS, show_traceback


def _do_validate(args: argparse.Namespace) -> int:
    with command_imports():  # paused collector (`rts_scenario.startup`)
        from ..errors import RtsError
        from ..preflight import preflight, vacuous_empty_bench
        from ..radar.simulate import near_field_warning
        from ..scenario import load_scenario, parametrizations
        from ..schedule.build import delay_step_note, if_distance_note

    bad = 0
    for path in args.scenes:
        try:
            combos = parametrizations(path)
        except RtsError as exc:
            show_traceback(args)
            print(f"error: {located(path, exc)}", file=sys.stderr)
            bad += 1
            continue
        errors: dict[str, list[str]] = {}  # message -> the combinations that hit it
        # Notes of a rig and radar: once per file, so each file's lines say all of its bench.
        reported: set[str] = set()
        for ident, overrides in combos:
            label = f"{path}[{ident}]" if ident else str(path)
            try:
                scene = load_scenario(path, overrides)
                pre = preflight(scene, args.method)
            except RtsError as exc:
                show_traceback(args)
                bad += 1
                errors.setdefault(located(path, exc), []).append(ident)
                continue
            # Limits the scene does not declare fail a run's verdict: a warning here, an error
            # with --strict. Declared ones are shown and fail nothing.
            kind = "error" if args.strict else "warning"
            unexpected = pre.unexpected()
            for line in unexpected:
                print(f"{kind}: {label}: {line}", file=sys.stderr)
            for line in pre.expected_lines():
                print(f"note: {label}: {line}")
            bad += args.strict and bool(unexpected)
            vacuous = vacuous_empty_bench(scene, scene.radar_options)
            declared = "nothing_checked" in scene.expectations.expected_limits
            for note in (near_field_warning(scene.radar, scene.rig),
                         delay_step_note(scene.rig, scene.radar),
                         if_distance_note(scene.rig, scene.radar)):
                if note and note not in reported:
                    reported.add(note)
                    print(f"note: {label}: {note}")
            if vacuous:  # the scene's own: said for each scene
                print(f"note: {label}: on the built-in simulated radar a run "
                      f"{'reports' if declared else 'fails with'} nothing_checked"
                      f"{' (expected)' if declared else ''}: {vacuous}")
            crowded = pre.crowded_analytic_frames
            crowded_declared = "crowded_in_analytic" in scene.expectations.expected_limits
            if crowded:
                print(f"note: {label}: on the built-in simulated radar a run "
                      f"{'reports' if crowded_declared else 'fails with'} crowded_in_analytic"
                      f"{' (expected)' if crowded_declared else ''}: in {crowded} of its frames "
                      f"targets share a range-Doppler neighbourhood, which the analytic "
                      f"fidelity the scene forces reads as if each were alone (fidelity auto "
                      f"or adc runs them through the beat-signal cube)")
            if not (args.strict and unexpected):
                # The file is valid; what a run of it would fail on is said beside it.
                # "ok" only where nothing said fails a run: a valid file a run of which fails
                # says so in its status word.
                n, k = len(scene.targets), len(unexpected)
                # An empty bench the simulated radar cannot fail: a run of it there fails.
                fails_empty = bool(vacuous) and not declared
                fails_crowded = bool(crowded) and not crowded_declared
                status = ("valid, a run fails" if unexpected or fails_empty or fails_crowded
                          else "ok")
                print(f"{status}: {label}: {scene.n_frames} frames, {n} target"
                      f"{'' if n == 1 else 's'}, schedule built"
                      + (f"; the {k} warning{' says' if k == 1 else 's say'} why (--strict: "
                         f"errors)" if unexpected else "")
                      + ("; on the built-in simulated radar, with nothing_checked (the note "
                         "says why)" if fails_empty and not unexpected else "")
                      + ("; on the built-in simulated radar, with crowded_in_analytic (the "
                         "note says why)" if fails_crowded and not unexpected else ""))
        # An error several combinations share, once, naming them all.
        for message, idents in errors.items():
            where = ("" if idents == [""] else
                     " [every variant]" if len(idents) == len(combos) > 1 else
                     f" [{', '.join(idents)}]")
            print(f"error: {message}{where}", file=sys.stderr)
    return EXIT_BAD_INPUT if bad else EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``validate`` subcommand."""
    parser = subparsers.add_parser(
        "validate", help="check scene files", parents=parents,
        description="Load each scene and every combination of its parametrize block and build "
                    "its schedule, as run does; print a warning per target and limit of the bench "
                    "or the radar it hits that the scene does not declare in expected_limits (out "
                    "of coverage, too close, ...). Exit 0 if all are valid, 2 "
                    "otherwise.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    parser.add_argument("--strict", action="store_true",
                        help="a limit the scene does not declare is an error (exit 2)")
    parser.add_argument("--method", default="exact", choices=METHODS,
                        help="weight solver the schedule is built with (default exact)")
    parser.set_defaults(handler=_do_validate)
