"""``rts-scenario sweep``: every parametrized combination of many scenes, in parallel."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from .. import interrupts
from .common import (
    EXIT_FAIL,
    EXIT_NO_RUNS,
    METHODS,
    check_distinct_paths,
    check_writable_file,
    read_by_scenes,
    replacing_after_stop,
    same_as_any,
    takes_placeholder,
    write_json,
    writing,
)

if TYPE_CHECKING:
    from ..sweep import PytestSettings, SweepTask

# Without a terminal, a progress line each time another tenth of the runs is done.
PLAIN_PROGRESS_STEPS = 10


class SweepProgress:
    """Runs done so far: a bar on a terminal, a plain line per tenth of the runs otherwise."""

    def __init__(self, total: int, stream: IO[str] | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.total = total
        self.done = self.failed = self.errors = 0
        self.start = time.perf_counter()
        self.step = max(1, math.ceil(total / PLAIN_PROGRESS_STEPS))
        self.next_line = self.step

    def __call__(self, entry: dict[str, Any]) -> None:
        """Count one finished run and show the progress."""
        self.done += 1
        self.failed += entry["status"] == "fail"
        self.errors += entry["status"] == "error"
        elapsed = time.perf_counter() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        counts = (f"{self.done}/{self.total} runs, {self.failed} failed, {self.errors} errors, "
                  f"{rate:.2f} runs/s")
        if self.tty:
            width = 30
            filled = int(width * self.done / max(self.total, 1))
            line = f"sweep [{'#' * filled}{'.' * (width - filled)}] {counts}"
            end = "\r" + " " * len(line) + "\r" if self.done >= self.total else ""
            self.stream.write("\r" + line + end)
        elif self.done >= self.next_line or self.done >= self.total:
            self.stream.write(f"sweep: {counts}\n")
            while self.next_line <= self.done:
                self.next_line += self.step
        self.stream.flush()


def _variants(scene_files: list[Path]) -> list[tuple[Path, dict[str, Any]]]:
    """Each scene file with the values of each of its variants (none for one that errs)."""
    from ..scenario import parametrizations

    found: list[tuple[Path, dict[str, Any]]] = []
    for path in scene_files:
        try:
            found += [(path, overrides) for _, overrides in parametrizations(path)]
        except Exception:  # noqa: BLE001 - the sweep reports it as that run's error
            continue
    return found


def _outputs_checked(args: argparse.Namespace) -> PytestSettings:
    """Check ``--json`` and ``--plot`` against the sweep's inputs; return the pytest settings.

    Before anything is written: neither may be a scene file, or a file a scene reads in any
    variant, and both must be writable.
    """
    from fnmatch import fnmatch

    from ..errors import RtsError
    from ..file_kinds import holds_scene
    from ..sweep import folder_files, pytest_settings

    settings = pytest_settings(args.scenes)
    scene_files: list[Path] = []
    misnamed: list[Path] = []  # reported as erred runs: the user's files all the same
    for given in map(Path, args.scenes):  # a folder: the scene files it holds
        if not given.is_dir():
            scene_files.append(given)
            continue
        for found in folder_files(given, settings.norecursedirs).files:
            if fnmatch(found.name, settings.rts_scenario_pattern):
                scene_files.append(found)
            elif holds_scene(found):
                misnamed.append(found)
    check_distinct_paths([("--json", args.json), ("--plot", args.plot)],
                         [("SCENE", scene) for scene in [*scene_files, *misnamed]])
    if args.json or args.plot:
        # Nor a file the scenes read (their rig, radar profile, fragments), in any variant.
        check_distinct_paths([("--json", args.json), ("--plot", args.plot)],
                             read_by_scenes(_variants(scene_files)))
    if args.json:
        check_writable_file("--json", args.json)
    if args.plot:
        from ..plots import require_matplotlib

        require_matplotlib()
        if Path(args.plot).suffix.lower() != ".png":
            raise RtsError(f"--plot {args.plot}: must name a .png file")
        check_writable_file("--plot", args.plot)
    return settings


def _write_interrupted(args: argparse.Namespace, error: str | None = None, *,
                       planned: int = 0, deselected: int = 0) -> None:
    """Write ``--json`` with no run and ``"interrupted": true``: stopped before any run.

    ``error``: the sweep stopped on bad input instead (a command line argparse refused, a bad
    ``-m`` expression, ``--workers 0``, ``-m`` selecting no run, a scheduler it cannot reach):
    no run, not interrupted, and why, with the summary's ``planned`` and ``deselected`` runs.
    Not where ``--json`` itself is what is wrong (its check fails here again): the error line
    says it.
    """
    from ..errors import RtsError

    if not args.json:
        return
    with replacing_after_stop(args.json):
        try:
            from ..sweep import summarize

            # Again (the stop may have come before them), --json's alone: a bad --plot is no
            # reason to leave an earlier report in place.
            settings = _outputs_checked(argparse.Namespace(**{**vars(args), "plot": None}))
            summary, config = summarize([], deselected=deselected), settings.as_json()
        except (RtsError, KeyboardInterrupt):
            return  # the exit code says it
        except Exception:
            # A module the stop left half imported: the checks cannot run. Never over a scene
            # named, nor over a YAML file (a scene or a file scenes read, in a folder named).
            if same_as_any(args.json, args.scenes) or \
                    Path(args.json).suffix.lower() in (".yaml", ".yml"):
                return
            summary, config = {"runs": 0}, None
        if error is None:
            write_json("--json", args.json, {"runs": [], "summary": {**summary,
                                                                     "interrupted": True},
                                             "config": config})
        else:
            write_json("--json", args.json, {"runs": [], "summary": {**summary,
                                                                     "planned": planned},
                                             "config": config, "error": error})


def _usage_error(args: argparse.Namespace, message: str) -> None:
    """Write ``--json`` for a command line argparse refused (``message``): no run."""
    _write_interrupted(argparse.Namespace(**{**vars(args), "scenes": args.scenes or []}),
                       message)


def _prepare(args: argparse.Namespace
             ) -> tuple[int, PytestSettings, list[SweepTask], int] | int:
    """Check the arguments and the outputs, and collect the runs.

    Returns ``(workers, settings, tasks, deselected)``, or the exit code of a sweep that ends
    here (``-m`` selects no run).
    """
    from ..errors import RtsError
    from ..sweep import (
        LOCAL_SCHEDULER,
        NoRunSelected,
        collect_tasks,
        default_workers,
        mark_expression,
        require_dask,
        select_tasks,
    )

    workers = args.workers if args.workers is not None else default_workers()
    if workers < 1:
        raise RtsError(f"--workers: must be >= 1, got {workers}")
    if args.scheduler is not None:
        require_dask()
        if args.scheduler == "":
            raise RtsError(f"--scheduler: needs an address (tcp://HOST:PORT) or "
                           f"{LOCAL_SCHEDULER!r}, got an empty one")
    if args.marks is not None:
        mark_expression(args.marks)  # a bad expression stops the sweep before anything runs
    settings = _outputs_checked(args)
    notes: list[str] = []
    tasks = collect_tasks(args.scenes, notes, settings)
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    deselected = 0
    if args.marks is not None:
        try:
            tasks, deselected = select_tasks(tasks, args.marks)
        except NoRunSelected as exc:
            print(f"error: {exc}", file=sys.stderr)
            _write_interrupted(args, str(exc), deselected=len(tasks))
            return EXIT_NO_RUNS
    return workers, settings, tasks, deselected


def _do_sweep(args: argparse.Namespace) -> int:
    from ..errors import RtsError

    try:
        prepared = _prepare(args)
        from ..sweep import LOCAL_SCHEDULER, exit_code, run_sweep, summarize
    except KeyboardInterrupt:
        # Stopped before any run: an earlier sweep's --json must not stay to be read as this
        # one's (as `run` writes its "not run" entries).
        _write_interrupted(args)
        raise
    except RtsError as exc:  # bad input before any run: the same, saying why
        _write_interrupted(args, str(exc))
        raise
    if isinstance(prepared, int):
        return prepared
    workers, settings, tasks, deselected = prepared
    # As many workers as there are runs at most (`run_sweep`); one runs in this process.
    used = max(1, min(workers, len(tasks)))
    where = (f"Dask scheduler {args.scheduler}" if args.scheduler not in (None, LOCAL_SCHEDULER)
             else "this process" if used == 1 and args.scheduler is None
             else f"{used} worker{'s' if used > 1 else ''}"
             + (" (local Dask cluster)" if args.scheduler == LOCAL_SCHEDULER else ""))
    print(f"sweep: {len(tasks)} run{'s' if len(tasks) != 1 else ''} on {where}"
          + (f" ({deselected} deselected by -m {args.marks!r})" if deselected else ""),
          file=sys.stderr)
    if takes_placeholder(args.json):
        # Until the sweep's report replaces it: no run, interrupted, the runs planned. A sweep
        # killed outright, or stopped or failing after its runs, leaves no earlier report in
        # place (not into a pipe or a device, which get the report alone).
        write_json("--json", args.json, {
            "runs": [], "summary": {**summarize([], deselected=deselected), "interrupted": True,
                                    "planned": len(tasks)},
            "config": settings.as_json(),
            "error": "no verdict: the sweep stopped before it wrote its report (it was "
                     "interrupted, killed or failed); or it is still running"})
    start = time.perf_counter()
    progress = SweepProgress(len(tasks))
    finished: list[dict[str, Any]] = []

    def on_result(entry: dict[str, Any]) -> None:
        finished.append(entry)
        progress(entry)

    try:
        entries = run_sweep(tasks, method=args.method, workers=workers,
                            scheduler=args.scheduler, on_result=on_result)
    except KeyboardInterrupt:
        interrupts.handled()
        # Keep what finished: the runs done so far, in the sweep's order, printed and in the
        # JSON with their summary, as `run` keeps the scenes that ran.
        order = {(t.file, t.ident): t.index for t in tasks}
        done = sorted(finished, key=lambda e: order.get((e["file"], e["id"]), len(order)))
        if progress.tty:  # off the progress bar's line
            progress.stream.write("\n")
        _print_runs(done, {**summarize(done, deselected=deselected), "interrupted": True,
                           "planned": len(tasks)},
                    time.perf_counter() - start, args, settings, total=len(tasks))
        print("error: interrupted", file=sys.stderr)
        # Never a pass; a run that erred before keeps its exit code.
        return max(exit_code(done), EXIT_FAIL)
    except RtsError as exc:
        if not finished:  # bad input before any run (a scheduler it cannot reach)
            _write_interrupted(args, str(exc), planned=len(tasks), deselected=deselected)
        raise
    _print_runs(entries, {**summarize(entries, deselected=deselected), "planned": len(tasks)},
                time.perf_counter() - start, args, settings)
    if args.plot:
        from ..plots import write_sweep_plot

        with writing("--plot", args.plot):
            write_sweep_plot(entries, args.plot)
        print(f"wrote {args.plot}")
    return exit_code(entries)


def _print_runs(entries: list[dict[str, Any]], summary: dict[str, Any], seconds: float,
                args: argparse.Namespace, settings: PytestSettings,
                total: int | None = None) -> None:
    """Print the pytest settings, a line per run and the summary, and write ``--json``.

    ``total``: the runs the sweep had, when it was interrupted before all of them finished.
    """
    from ..report import not_checked_note
    from ..sweep import run_label

    print(_settings_text(settings))
    for entry in entries:
        line = f"{entry['status'].upper()} {run_label(entry)} ({entry['file']})"
        if entry["status"] == "pass":
            line += not_checked_note(entry.get("targets_not_checked") or 0,
                                     entry.get("targets") or 0)
        print(line + (f": {entry['reason']}" if "reason" in entry else ""))
    print()
    print(_summary_text(summary, seconds, total))
    if args.json:
        payload = {"runs": entries, "summary": summary, "config": settings.as_json()}
        write_json("--json", args.json, payload)
        print(f"wrote {args.json}" + (f" ({len(entries)} of {total} runs)"
                                      if total is not None else ""))


def _settings_text(settings: PytestSettings) -> str:
    """Say where the pytest settings the sweep took came from, and what they are.

    ``pytest settings: configfile pyproject.toml (rootdir /project): xfail_strict = false,
    norecursedirs = .* build, rts_scenario_pattern = *.scenario.yaml``; ``none found, pytest's
    defaults`` without a config file.
    """
    if settings.inifile is None:
        where = "none found, pytest's defaults"
    else:
        rootdir = settings.rootdir
        inifile = (settings.inifile.relative_to(rootdir) if rootdir is not None
                   and settings.inifile.is_relative_to(rootdir) else settings.inifile)
        where = f"configfile {inifile} (rootdir {rootdir})"
    return (f"pytest settings: {where}: xfail_strict = {str(settings.xfail_strict).lower()}, "
            f"norecursedirs = {' '.join(settings.norecursedirs)}, "
            f"rts_scenario_pattern = {settings.rts_scenario_pattern}")


def _rate_text(rate: float | None) -> str:
    """Render the pass rate for people; none where no run ran (every one skipped)."""
    return "no run ran, no pass rate" if rate is None else f"pass rate {rate:.1%}"


def _summary_text(summary: dict[str, Any], seconds: float, total: int | None = None) -> str:
    """Render the summary for people: totals, pass rate per parameter value, worst runs.

    ``total``: the sweep's runs, when it was interrupted (``summary`` counts those done).
    """
    from ..sweep import run_label

    runs = summary["runs"]
    count = f"{runs} runs" if total is None else f"{runs} of {total} runs (interrupted)"
    lines = [f"sweep: {count}, {summary['passed']} passed, {summary['failed']} failed, "
             f"{summary['errors']} errors{_marked_counts(summary)}; "
             f"{_rate_text(summary['pass_rate'])} ({seconds:.1f} s, "
             f"{runs / seconds if seconds > 0 else 0.0:.2f} runs/s)"]
    by_parameter = summary["by_parameter"]
    if by_parameter:
        # The key path's last part names a parameter, unless it is a list index or two
        # parameters share it.
        short = [key.rsplit(".", 1)[-1] for key in by_parameter]
        short = [key if name.isdigit() else name for key, name in zip(by_parameter, short,
                                                                        strict=True)]
        lines.append("pass rate by parameter:")
        for key, name in zip(by_parameter, short, strict=True):
            label = name if short.count(name) == 1 else key
            for value, counts in by_parameter[key].items():
                extra = (f"{counts['errors']} errors" if counts["errors"] else ""
                         ) + _marked_counts(counts)
                extra = f" ({extra.removeprefix(', ')})" if extra else ""
                ran = counts["runs"] - counts["skipped"]
                lines.append(f"  {label}={value}: {counts['passed']}/{ran}{extra}")
    worst = [w for w in summary["worst"] if w["status"] not in ("pass", "xpass")
             or w.get("max_error_ratio") is not None]
    if worst:
        lines.append("worst runs:")
    for w in worst:
        ratio = w.get("max_error_ratio")
        error = (f" largest error {w['max_error_quantity']} at {ratio:.0%} of tolerance"
                 if ratio is not None else "")
        reason = f": {w['reason']}" if "reason" in w else ""
        lines.append(f"  {w['status'].upper()} {run_label(w)} ({w['file']}){reason}"
                     + (f" -{error}" if error and reason else error))
    return "\n".join(lines)


def _marked_counts(counts: dict[str, Any]) -> str:
    """``, 2 xfailed, 1 skipped``: the runs a scene's marks judged, those there are."""
    return "".join(f", {counts[key]} {key}" for key in ("xfailed", "xpassed", "skipped",
                                                         "deselected") if counts.get(key))


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``sweep`` subcommand."""
    parser = subparsers.add_parser(
        "sweep", help="run every parametrized combination of scenes, in parallel",
        parents=parents,
        description="Run every combination of each scene's parametrize block (a scene without "
                    "one runs once; a folder means every *.scenario.yaml in it, recursively) on "
                    "the simulated radar, in parallel, and print the pass rate overall and per "
                    "parameter value and the worst runs. Every run is reported, even if others "
                    "err. A scene's marks judge its runs as the pytest plugin does (xfail, "
                    "skip), with the project's pytest settings (norecursedirs, xfail_strict, "
                    "from the config file pytest would read). Exit 0 if no run fails, 1 if one "
                    "fails, 2 on bad input, 3 on a runtime error, 5 if -m selects no run.",
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE",
                        help="*.scenario.yaml files or folders of them (a folder's sweep "
                             "leaves out the folders pytest leaves out: the project's "
                             "norecursedirs, by default hidden ones, build, dist, "
                             "node_modules, ...; virtual environments, __pycache__)")
    parser.add_argument("--json", metavar="OUT", help="write every run and the summary as JSON")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="worker processes (default: the number of CPUs); 1 runs in this "
                             "process, one run after the other; with --scheduler local, the "
                             "local Dask cluster's workers")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run on a Dask cluster: its scheduler's address (tcp://HOST:PORT), "
                             "or 'local' for a cluster of --workers processes on this machine "
                             "(needs pip install 'rts-scenario[sweep]')")
    parser.add_argument("--method", default="exact", choices=METHODS,
                        help="weight solver (default exact)")
    parser.add_argument("-m", "--marks", default=None, metavar="EXPR",
                        help="run only the runs whose scene's marks match this expression, as "
                             "pytest -m selects them ('slow and not hardware'; needs pytest)")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="plot pass/fail over the parameters (needs matplotlib)")
    parser.set_defaults(handler=_do_sweep, on_usage_error=_usage_error)
