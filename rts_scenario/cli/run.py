"""``rts-scenario run``: run scenes end to end and check the radar."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO, cast

from .. import interrupts
from ..atomic import Draft, check_draft
from ..errors import RtsError, located, one_line
from ..startup import command_imports
from ..suffixes import LOG_SIDECAR_SUFFIX
from .common import (
    EXIT_BAD_INPUT,
    EXIT_FAIL,
    EXIT_OK,
    EXIT_RUNTIME_ERROR,
    METHODS,
    Progress,
    check_can_interface,
    check_can_opens,
    check_distinct_paths,
    check_fd_mapping,
    check_output,
    check_radar_channel,
    check_writable_file,
    check_writable_folder,
    named_file,
    read_by_scenes,
    replacing_after_stop,
    same_as_any,
    show_traceback,
    takes_placeholder,
    write_json,
    writing,
)


def _error_entry(scene: str, path: str, message: str, variant: str = "",
                 parameters: dict[str, Any] | None = None) -> dict[str, Any]:
    """Return a run's `--json` entry with no verdict: status error, its message (docs/cli.md)."""
    return {"scene": scene, "file": path, "status": "error", "error": message,
            "variant": variant, "parameters": dict(parameters or {})}


def _inputs(args: argparse.Namespace) -> list[str | None]:
    """Return the files the command line names for reading (not those the scenes read)."""
    return [*args.scenes, args.mapping]


def _do_run(args: argparse.Namespace) -> int:
    started = [False]
    try:
        return _run(args, started)
    except KeyboardInterrupt:
        if not started[0]:
            with replacing_after_stop(args.json):
                _write_not_run(args, "not run: interrupted (Ctrl-C or SIGTERM) before it ran")
            _remove_earlier_detections(args)
        raise


def _usage_error(args: argparse.Namespace, message: str) -> None:
    """Write ``--json`` for a command line refused before anything ran (``message``).

    A line argparse refused, or a setting of the environment. An earlier run's
    ``--detections`` goes too (`_remove_earlier_detections`), where it holds our header.
    """
    args = argparse.Namespace(**{**vars(args), "scenes": args.scenes or []})
    _write_not_run(args, f"not run: {message}")
    if getattr(args, "detections", None) and _holds_detections(args.detections):
        _remove_earlier_detections(args)


def _holds_detections(path: str) -> bool:
    """Whether ``path`` begins with the header `run --detections` writes (a file of ours)."""
    from ..check import DETECTION_COLUMNS

    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            first = f.readline(4096)
    except OSError:
        return False
    return first.strip() == ",".join(DETECTION_COLUMNS)


def _remove_earlier_detections(args: argparse.Namespace) -> None:
    """Remove the ``--detections`` file an earlier run left: this one stopped before its scenes.

    Its rows would be read as this run's, as the report is not. The file is removed where its
    draft would have replaced it (a link is followed), unless the command reads it or another
    option writes it, or it is named like a file the tool reads: the checks that refuse those
    may not have run yet.
    """
    record = [args.record, f"{args.record}{LOG_SIDECAR_SUFFIX}"] if args.record else []
    if not args.detections or same_as_any(args.detections, [*_inputs(args), args.json,
                                                            *record]):
        return
    try:
        from ..file_kinds import read_only_kind
    except Exception:  # noqa: BLE001 - a module the stop left half imported: left alone
        return
    real = Path(os.path.realpath(args.detections))
    if read_only_kind(args.detections) is None and read_only_kind(real) is None and \
            real.is_file():
        with contextlib.suppress(OSError):
            real.unlink()


def _write_not_run(args: argparse.Namespace, message: str) -> None:
    """Write ``--json`` with every scene an error entry: stopped before any scene ran.

    An earlier run's report must not stay in place to be read as this one's. Never over a
    file the command reads: the check that refuses that may not have run yet.
    """
    # Not from the scenes' package: a stop during its import (a yaml half imported) broke that.
    from ..suffixes import SCENE_SUFFIX

    record = getattr(args, "record", None)
    sidecar = [f"{record}{LOG_SIDECAR_SUFFIX}"] if record else []
    if not args.json or same_as_any(args.json, [*_inputs(args), *sidecar]):
        return  # (nor over the sidecar --record writes: a recording's)
    from ..file_kinds import read_only_kind

    if read_only_kind(Path(args.json).name) is not None:
        return  # named like a file the tool reads (another scene): never written over
    # No scene to tell (a command line argparse refused): one entry naming none.
    unrun = [_error_entry(Path(path).name.removesuffix(SCENE_SUFFIX), path, message)
             for path in args.scenes or [""]]
    write_json("--json", args.json, unrun[0] if len(unrun) == 1 else unrun)


def _run(args: argparse.Namespace, started: list[bool]) -> int:
    with command_imports():  # paused collector (`rts_scenario.startup`)
        from ..canbus.mapping import CanMapping
        from ..check import DETECTION_COLUMNS, tolerances_below_bus_steps
        from ..errors import BusError, ScenarioError
        from ..pipeline import RunOptions, run_scene
        from ..plots import safe_stem
        from ..preflight import Preflight
        from ..report import bench_failures, not_checked_note
        from ..scenario import SCENE_SUFFIX, load_scenario, parametrizations, run_label
        from ..scenario.model import simulated_radar_parameters
        from ..schedule import ScheduleError
        from ..schedule.build import calibration_note, if_distance_note

    # Every combination of a scene's parametrize block is one run, as in the pytest plugin;
    # a file whose block cannot be expanded is reported in its turn, like one that does not load.
    expanded: list[tuple[str, list[tuple[str, dict[str, Any]]] | Exception]] = []
    for path in args.scenes:
        try:
            expanded.append((path, parametrizations(path)))
        except Exception as exc:
            show_traceback(args)
            expanded.append((path, exc))

    # Everything the options name is checked before the first scene runs, not after it.
    # An option at fault stops the command before any scene runs: a --json report of an
    # earlier run must not stay in place to be read as this one's.
    logs: dict[str, str] = {}  # variant -> the file its bus is recorded to
    try:
        check_output("--output", args.output, run=True)
        check_can_interface("--can-interface", args.can_interface, args.can_channel)
        check_radar_channel(args.radar_channel)
        bus_mapping = CanMapping.builtin()
        if args.mapping:
            bus_mapping = named_file("--mapping", CanMapping.from_file, args.mapping)
            check_fd_mapping(args.can_fd, args.mapping, bus_mapping)
        check_distinct_paths(
            [("--json", args.json), ("--detections", args.detections), ("--record", args.record),
             ("--record's sidecar", f"{args.record}.rts.json" if args.record else None),
             ("--plot", args.plot)],
            [*(("SCENE", scene) for scene in args.scenes), ("--mapping", args.mapping)])
        if args.json or args.detections or args.record or args.plot:
            check_distinct_paths(
                [("--json", args.json), ("--detections", args.detections),
                 ("--record", args.record),
                 ("--record's sidecar", f"{args.record}.rts.json" if args.record else None),
                 ("--plot", args.plot)],
                read_by_scenes((path, overrides) for path, combos in expanded
                               if not isinstance(combos, Exception)
                               for _, overrides in combos))
        if args.json:
            check_writable_file("--json", args.json)
        if args.detections:
            check_writable_file("--detections", args.detections, in_place=True)
        if args.record:
            from ..recheck import LOG_SUFFIXES

            if len(args.scenes) > 1:
                raise RtsError(f"--record: records the bus of one scene, got {len(args.scenes)} "
                               f"scenes")
            suffix = Path(args.record).suffix.lower()
            if suffix not in LOG_SUFFIXES:
                raise RtsError(f"--record {args.record}: unknown log format {suffix!r}; valid: "
                               f"{', '.join(LOG_SUFFIXES)}")
            if suffix == ".mf4":
                try:
                    import asammdf  # noqa: F401 - python-can writes MF4 through it
                except ImportError:
                    raise RtsError("--record: .mf4 logs need asammdf (pip install "
                                   "'rts-scenario[mf4]')") from None
            combos = expanded[0][1]
            logs = variant_logs(args.record, [] if isinstance(combos, Exception)
                                else [ident for ident, _ in combos])
            # Each variant's log and sidecar, against the other outputs (the sidecar of one
            # named by --json was replaced by the report).
            check_distinct_paths(
                [("--json", args.json), ("--detections", args.detections), ("--plot", args.plot),
                 *((f"--record's log {log}", log) for log in logs.values()),
                 *((f"--record's sidecar of {log}", f"{log}{LOG_SIDECAR_SUFFIX}")
                   for log in logs.values())])
            for log in logs.values() or [args.record]:
                # The log is written as the bus goes, its sidecar whole, through a draft.
                check_writable_file("--record", log, in_place=True)
                sidecar = f"{log}{LOG_SIDECAR_SUFFIX}"
                with writing("--record", sidecar):
                    check_draft(sidecar)
        if args.plot:
            from ..plots import require_matplotlib

            require_matplotlib()
            check_writable_folder("--plot", args.plot)
            for option, path in (("--json", args.json), ("--detections", args.detections),
                                 ("--record", args.record)):
                # The plots are SCENE-KIND.png files in the folder: a .png there may be one.
                if path and Path(path).suffix.lower() == ".png" and \
                        same_as_any(Path(path).resolve().parent, [args.plot]):
                    raise RtsError(f"{option} {path}: a .png in the --plot folder {args.plot}, "
                                   f"where a plot may replace it or it a plot; give {option} "
                                   f"another name or folder")
        # Last: the interface opens once (and closes) only when every other option is good.
        check_can_opens("--can-interface", args.can_interface, args.can_channel, "--can-channel",
                        fd=args.can_fd)
    except RtsError as exc:
        if not str(exc).startswith("--json"):
            _write_not_run(args, f"not run: {exc}")
        raise
    if args.output == "simulated-radar" and args.can_interface != "virtual":
        # A bench script that forgot --output: no RTS plays, the built-in radar measures and
        # puts its detections on the bench's bus, and the verdict is its.
        print(f"warning: --can-interface {args.can_interface} without --output: the built-in "
              f"simulated radar measures (no RTS plays the scene) and sends its detections on "
              f"that bus; the verdicts are the simulated radar's; on a bench, give --output "
              f"udp://HOST:PORT", file=sys.stderr)
    # Until this run's report replaces it, --json says no verdict: a run stopped, killed or
    # failing before its report leaves no earlier run's report to be read as its own.
    if takes_placeholder(args.json):
        _write_not_run(args, "no verdict: the command stopped before it wrote its report (it "
                             "was interrupted, killed or failed); or it is still running")
    for log in logs.values() or ([args.record] if args.record else []):
        # Nor an earlier run's bus log and sidecar, which a check would take for this run's.
        for old in (Path(log), Path(f"{log}{LOG_SIDECAR_SUFFIX}")):
            real = Path(os.path.realpath(old))  # through a link, the file it names
            with writing("--record", old):
                if real.is_file():
                    real.unlink()
    entries: list[dict[str, Any]] = []
    bench_of_run: dict[int, list[str]] = {}  # a failed entry's bench failures, by index
    stems: set[str] = set()
    bad_input = runtime_error = False
    detections = None
    draft: Draft | None = None
    if args.detections:
        with writing("--detections", args.detections):
            # A draft beside it until the last scene ends (`atomic.Draft`).
            draft = Draft(args.detections, newline="")
        # Written through the draft, which keeps a write's error (a full disk) for the end
        # instead of failing the scene whose detections it was writing.
        detections = cast(TextIO, draft)
        detections.write(",".join(DETECTION_COLUMNS) + "\n")

    def failed(scene: str, path: str, exc: BaseException, variant: str = "",
               parameters: dict[str, Any] | None = None) -> None:
        message = located(path, exc)
        if not isinstance(exc, RtsError):
            message = (f"{path}: {type(exc).__name__}: {one_line(exc)} (a runtime error; "
                       f"--debug shows where)")
        if variant:
            message += f" [{variant}]"
        print(f"error: {message}", file=sys.stderr)
        entries.append(_error_entry(scene, path, message, variant, parameters))

    # The run under way when Ctrl-C came: (scene name, or file name until it loaded, path,
    # variant, overrides, log); its entry once its verdict is known (its log then complete).
    current: tuple[str, str, str, dict[str, Any], str | None] | None = None
    finished: dict[str, Any] | None = None
    interrupted = False
    # Runs begun (a file that does not expand is one), and the entries before the last began:
    # each run gets exactly one entry, whenever the stop comes.
    begun, run_start = 0, 0
    started[0] = True  # from here on the loop keeps what finished (`--json` included)
    try:
        for path, combos in expanded:
            file_name = Path(path).name.removesuffix(SCENE_SUFFIX)
            if isinstance(combos, Exception):
                begun, run_start = begun + 1, len(entries)
                current = (file_name, path, "", {}, None)
                finished = None
                failed(file_name, path, combos)
                # A file that does not load is bad input; anything else is a runtime error.
                bad_input = bad_input or isinstance(combos, RtsError)
                runtime_error = runtime_error or not isinstance(combos, RtsError)
                continue
            for variant, overrides in combos:
                label = f"{path}[{variant}]" if variant else path
                begun, run_start = begun + 1, len(entries)
                current = (file_name, path, variant, overrides, logs.get(variant, args.record))
                finished = None
                start = time.perf_counter()
                try:
                    scene = load_scenario(path, overrides)
                except Exception as exc:
                    show_traceback(args)
                    failed(file_name, path, exc, variant, overrides)
                    bad_input = bad_input or isinstance(exc, RtsError)
                    runtime_error = runtime_error or not isinstance(exc, RtsError)
                    continue
                # Loaded: an interrupted run's entry names the scene, not its file.
                current = (scene.name, *current[1:])
                for line in tolerances_below_bus_steps(scene.expectations,
                                                       bus_mapping.steps(args.can_fd),
                                                       bus_mapping.name):
                    print(f"warning: {label}: {line}", file=sys.stderr)
                calibrated = calibration_note(scene.rig)
                if calibrated is not None and args.output == "simulated-radar":
                    print(f"warning: {label}: {calibrated}", file=sys.stderr)
                uncalibrated = if_distance_note(scene.rig, scene.radar)
                if uncalibrated is not None:  # on a bench and the simulated radar alike
                    print(f"warning: {label}: {uncalibrated}", file=sys.stderr)
                unused = simulated_radar_parameters(scene.parameters)
                if unused and args.output != "simulated-radar":
                    # A variant over the built-in radar's options plays the same on a bench:
                    # its label would claim a result for a setting the radar never had.
                    print(f"note: {label}: {', '.join(unused)} set the built-in simulated "
                          f"radar; on the bench ({args.output}) the radar measures as it is "
                          f"set, so this variant runs as the others do")
                try:
                    loaded = {"load_s": time.perf_counter() - start}

                    def warn(pre: Preflight, label: str = label) -> None:
                        # Before anything plays: what the bench or the radar will not do as
                        # specified.
                        for line in pre.unexpected():
                            print(f"warning: {label}: {line}", file=sys.stderr)

                    log = logs.get(variant, args.record)
                    options = RunOptions(output=args.output, can_interface=args.can_interface,
                                         can_channel=args.can_channel, can_fd=args.can_fd,
                                         radar_channel=args.radar_channel,
                                         mapping=args.mapping, method=args.method,
                                         plot=bool(args.plot), bus_log=log)
                    result = run_scene(scene, options,
                                       progress=Progress(run_label(Path(path).name, variant)),
                                       detections_out=detections, on_preflight=warn, timing=loaded)
                    report = result.report
                    finished = {"file": path, "status": "pass" if report.passed else "fail",
                                "marks": list(scene.marks), **report.to_dict()}
                    print(report.table())
                    marked = marks_note(scene.marks, report.passed,
                                        bench_failures(report.reason_codes, report.playback))
                    if marked is not None:
                        print(f"note: {scene.label} is marked {marked[0]}")
                    if log and result.sidecar_error is not None:
                        # The verdict above stands; what re-checks the log lacks is said.
                        print(f"error: --record {log}: {result.sidecar_error}; the verdict "
                              f"above stands, but a check of {log} has no sidecar and aligns "
                              f"it by its detections alone", file=sys.stderr)
                        runtime_error = True
                    elif log:
                        print(f"wrote {log} and {log}.rts.json")
                    print("timing: " + ", ".join(
                        f"{k.removesuffix('_s')} {v * 1e3:.0f} ms"
                        + (f" ({report.solver_plan})" if k == "plan_s" else "")
                        for k, v in report.timing.items()))
                    if args.plot:
                        from ..plots import write_plots

                        stem = _unique(safe_stem(scene.label), stems)
                        with writing("--plot", args.plot):
                            written_plots = write_plots(result, args.plot, stem)
                        for written in written_plots:
                            print(f"wrote {written}")
                except Exception as exc:
                    show_traceback(args)
                    failed(scene.name, path, exc, variant, overrides)
                    # The scene loaded but its schedule cannot be built (e.g. the rig's update
                    # rate): still the scene's fault, not the run's; so is a CAN interface or
                    # channel the arguments name that cannot be opened.
                    if isinstance(exc, ScenarioError | ScheduleError | BusError):
                        bad_input = True
                    else:
                        runtime_error = True
                    continue
                finally:
                    print()
                assert finished is not None  # set where the run ended in a report
                entries.append(finished)
                current, finished = None, None
                if not report.passed:  # for the summary's marks note, not the --json
                    bench_of_run[len(entries) - 1] = bench_failures(report.reason_codes,
                                                                    report.playback)
    except KeyboardInterrupt:
        # What finished is kept and reported; nothing cut short is left looking complete.
        interrupts.handled()
        interrupted = True
        if current is None or len(entries) > run_start:
            # Between runs, or the run under way had its entry already (its error said).
            print("error: interrupted", file=sys.stderr)
        elif finished is not None:
            # Stopped after its verdict (the log and sidecar written): the verdict stands.
            entries.append(finished)
            print("error: interrupted", file=sys.stderr)
        else:
            name, path, variant, overrides, log = current
            failed(name, path, RtsError("interrupted (Ctrl-C or a stop signal) while running: "
                                        "no verdict"), variant, overrides)
            if log:
                print(f"note: {log} is cut short and has no sidecar: a check of it aligns it "
                      f"by its timestamps and fails on the cycles it lacks", file=sys.stderr)
        # The runs the stop kept from starting: each an entry, so none is missing from the
        # summary and the report (one entry per run, in order, whatever became of it).
        planned = [(Path(path).name.removesuffix(SCENE_SUFFIX), path, variant, overrides)
                   for path, combos in expanded
                   for variant, overrides in ([("", {})] if isinstance(combos, Exception)
                                              else combos)]
        entries += [_error_entry(*run[:2], "not run: interrupted (Ctrl-C or SIGTERM) before "
                                           "it ran", *run[2:])
                    for run in planned[begun:]]
    try:
        if draft is not None and not _finish_detections(draft, args.detections, interrupted):
            runtime_error = True
    except KeyboardInterrupt:
        # The report below is still written; the rows are named as not whole, if they can be.
        interrupts.handled()
        interrupted = True
        print("error: interrupted", file=sys.stderr)
        assert draft is not None
        with contextlib.suppress(OSError):
            print(f"wrote {draft.cut_short()} (cut short: the run was interrupted)")
    if len(entries) > 1:
        for i, entry in enumerate(entries):
            name = run_label(entry["scene"], entry["variant"])
            line = f"{entry['status'].upper()} {name} ({entry['file']})"
            if entry["status"] == "pass":
                targets = entry.get("targets") or []
                line += not_checked_note(sum(not t["checked"] for t in targets), len(targets))
            marked = marks_note(entry.get("marks", ()), entry["status"] == "pass",
                                bench_of_run.get(i, ()))
            if marked is not None:
                line += f" - marked {marked[1]}"
            print(line + (f": {entry['error']}" if entry["status"] == "error" else ""))
    if args.json:
        payload = entries[0] if len(entries) == 1 else entries
        write_json("--json", args.json, payload)
        print(f"wrote {args.json}")
    if runtime_error:
        return EXIT_RUNTIME_ERROR
    if bad_input:
        return EXIT_BAD_INPUT
    if interrupted:  # even before the first scene started: never a pass
        return EXIT_FAIL
    return EXIT_OK if all(e["status"] == "pass" for e in entries) else EXIT_FAIL


def _finish_detections(draft: Draft, path: str, interrupted: bool) -> bool:
    """Name the ``--detections`` draft ``path``, or ``path.partial`` where it is not whole.

    Returns False, having said why on standard error, where it could not be written whole (a
    full disk): the run's verdicts stand, the rows written are in ``path.partial``.
    """
    failure = None if draft.error is None else RtsError(
        f"--detections {path}: cannot write: {draft.error.strerror or draft.error}")
    if failure is None and not interrupted:
        try:
            with writing("--detections", path):
                print(f"wrote {draft.keep()}")
            return True
        except RtsError as exc:
            failure = exc
    try:
        with writing("--detections", path):
            partial = draft.cut_short()
    except RtsError as exc:
        draft.discard()
        print(f"error: {failure or exc}" + (f"; {exc}" if failure else ""), file=sys.stderr)
        return False
    if failure is None:
        print(f"wrote {partial} (cut short: the run was interrupted)")
        return True
    print(f"error: {failure}; the verdicts stand; the rows written are in {partial} (cut "
          f"short)", file=sys.stderr)
    return False


def marks_note(marks: Sequence[str], passed: bool, bench: Sequence[str] = ()
               ) -> tuple[str, str] | None:
    """Say how pytest and ``sweep`` judge a run that ``run`` judged by its check alone.

    ``run`` runs a scene as written, whatever its marks: a ``skip`` mark does not keep it from
    playing, an ``xfail`` mark does not turn its verdict or exit code. Where the marks would
    change what pytest and ``sweep`` report (`rts_scenario.sweep.marked_status`), returns
    the note's text after ``is marked`` and the summary line's after ``marked``; else None.
    ``bench``: the run's bench failures (`rts_scenario.report.bench_failures`), which an
    ``xfail`` mark does not cover.
    """
    from ..sweep import SKIP_MARKS, marked_status

    skip = next((mark for mark in marks if mark in SKIP_MARKS), None)
    if skip is not None:
        return (f"{skip}: pytest and rts-scenario sweep skip it; run ran it as written",
                f"{skip}: SKIPPED in pytest and sweep")
    if "xfail" not in marks:
        return None
    status = marked_status(marks, passed, bench=bench)
    if status == "fail" and not passed:
        return (f"xfail: pytest and rts-scenario sweep fail it all the same: the mark expects "
                f"the radar's check to fail, not the bench ({', '.join(bench)})",
                "xfail: FAIL in pytest and sweep (the bench failed it)")
    what = ("its failed check as XFAIL (a known failure, which fails nothing)" if not passed
            else "its passed check as XPASS (which fails nothing, unless the project sets "
                 "xfail_strict)")
    return (f"xfail: pytest and rts-scenario sweep report {what}; run judges the check as "
            f"written", f"xfail: {status.upper()} in pytest and sweep")


def variant_logs(log: str, variants: list[str]) -> dict[str, str]:
    """Name the bus log of each variant of a parametrized scene: ``LOG`` -> ``STEM[ID].SUFFIX``.

    ``ID`` is the variant's id made safe for a file name (`rts_scenario.plots.safe_stem`), with
    ``-2``, ``-3``, ... when two variants' ids become the same; empty for a scene without
    ``parametrize`` (its log is ``LOG`` itself).
    """
    from ..plots import safe_stem

    if variants in ([], [""]):
        return {}
    path = Path(log)
    taken: set[str] = set()
    return {variant: str(path.with_name(f"{path.stem}[{_unique(safe_stem(variant), taken)}]"
                                        f"{path.suffix}"))
            for variant in variants}


def _unique(stem: str, taken: set[str]) -> str:
    """``stem``, or ``stem-2``, ``stem-3``, ... if a scene of this run already used it."""
    candidate, n = stem, 1
    while candidate in taken:
        n += 1
        candidate = f"{stem}-{n}"
    taken.add(candidate)
    return candidate


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``run`` subcommand."""
    parser = subparsers.add_parser(
        "run", help="run scenes end to end and check the radar", parents=parents,
        description="Load each scene, build its schedule, play it (by default on the built-in "
                    "simulated radar), read the detections over CAN and check them. Every "
                    "combination of a scene's parametrize block is its own run, named as pytest "
                    "names it (SCENE[ID]). A scene runs as written, whatever its marks (skip, "
                    "xfail: pytest and sweep apply them), with a note saying what they would "
                    "report. Every run happens even if another errs. Exit 0 if "
                    "every run passes, 1 if one fails, 2 on bad input (arguments, a scene that "
                    "does not load), 3 on a runtime error.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="*.scenario.yaml files")
    parser.add_argument("--output", default="simulated-radar",
                        help="simulated-radar (default), udp://HOST:PORT or an installed RTS "
                             "output (a schedule file: rts-scenario schedule)")
    parser.add_argument("--can-interface", default="virtual",
                        help="python-can interface (default virtual)")
    parser.add_argument("--can-channel", default=None, help="CAN channel (default: private)")
    parser.add_argument("--can-fd", action="store_true", help="CAN FD detection messages")
    parser.add_argument("--radar-channel", default=None, metavar="CH",
                        help="on an interface listening on several channels, read only the "
                             "radar's (Message.channel as python-can gives it, e.g. 1 of a "
                             "Vector interface given 0,1); the log's check reads the same one")
    parser.add_argument("--mapping", default=None,
                        help="*.mapping.yaml for a third-party radar's DBC")
    parser.add_argument("--method", default="exact", choices=METHODS,
                        help="weight solver (default exact; estimator: aimed so that the scene's "
                             "radar.estimator reads the set angle)")
    parser.add_argument("--json", metavar="REPORT", help="write the report as JSON")
    parser.add_argument("--plot", metavar="DIR", help="write PNG plots (needs matplotlib)")
    parser.add_argument("--record", metavar="LOG",
                        help="record the detection bus (.blf, .asc, .csv, .log, .trc, .mf4) "
                             "and LOG.rts.json for `rts-scenario check SCENE --log LOG`; a "
                             "parametrized scene's variants to STEM[ID].SUFFIX each")
    parser.add_argument("--detections", metavar="CSV",
                        help="write every detection, with the target it was assigned to, as CSV "
                             "(columns in docs/report.md)")
    parser.set_defaults(handler=_do_run, on_usage_error=_usage_error)
