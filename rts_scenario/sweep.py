"""Sweeps: every parametrized combination of many scenes, run in parallel, and their summary.

A sweep is a list of `SweepTask` (one scene file and one combination of its ``parametrize``
block). `run_task` runs one of them end to end on the simulated radar and returns a plain,
JSON-ready entry; it depends only on the scene file and its overrides (every random effect is
seeded from the scene), so it gives the same verdict in this process, in a process pool or on
a Dask worker. `run_sweep` runs a whole list in one of those three places and never loses a
result: a run that raises, or a worker that dies, becomes an entry with status ``error`` and a
one-line message. A scene's ``marks`` judge its runs as the pytest plugin does (`judged`), and
`select_tasks` picks runs by a mark expression as ``pytest -m`` does. The project's pytest
settings that change which scenes run and how they are judged (``norecursedirs``,
``xfail_strict``, ``rts_scenario_pattern``) are read from the config file pytest would read
(`pytest_settings`); which files are scenes is the plugin's rule
(`rts_scenario.scene_files.scene_file_kind`).
`summarize` counts the verdicts overall and per parameter value and picks the worst runs.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from fnmatch import fnmatch
from pathlib import Path
from typing import Any, NamedTuple

from .errors import RtsError
from .scene_files import (
    DEFAULT_PATTERN,
    PATTERN_OPTION,
    check_pattern,
    misnamed_scene,
    scene_file_kind,
)

# Runs the summary lists as the worst ones (failed and erred runs first).
WORST_RUNS = 10
# ``--scheduler`` value that starts a Dask cluster on this machine.
LOCAL_SCHEDULER = "local"
# How long to try reaching a Dask scheduler before giving up.
CONNECT_TIMEOUT_S = 10.0
# pytest's default ``norecursedirs``: the folders a folder's sweep does not walk into, unless
# the project's pytest settings name others. ``__pycache__`` and virtual environments are left
# out whatever they say, as pytest leaves them out (`_left_out`).
NORECURSE_PATTERNS = ("*.egg", ".*", "_darcs", "build", "CVS", "dist", "node_modules", "venv",
                      "{arch}")
# The files pytest reads its settings from (`_pytest.config.findpaths`), looked for in the
# folders of the paths given and above them.
PYTEST_CONFIG_NAMES = ("pytest.toml", ".pytest.toml", "pytest.ini", ".pytest.ini",
                       "pyproject.toml", "tox.ini", "setup.cfg")
# The settings that make an xpass fail, in the order pytest's xfail marks read them: the first
# that is set decides (``strict_xfail``, called ``xfail_strict`` before pytest 9, then pytest
# 9's ``strict``); a name this pytest does not know is skipped.
XFAIL_STRICT_OPTIONS = ("strict_xfail", "xfail_strict", "strict")
# Marks that skip a run (``skipif`` without a condition skips, as in pytest).
SKIP_MARKS = ("skip", "skipif")
# Statuses of runs whose check was judged, and the summary's count of each.
COUNTS = {"pass": "passed", "fail": "failed", "error": "errors", "xfail": "xfailed",
          "xpass": "xpassed", "skipped": "skipped"}

Entry = dict[str, Any]


class NoRunSelected(RtsError):
    """A mark expression selects none of the runs (pytest's exit code 5: no tests ran)."""


@dataclass(frozen=True)
class PytestSettings:
    """The project's pytest settings that change which scenes a sweep runs and their verdicts.

    ``inifile`` is the config file pytest reads them from and ``rootdir`` pytest's rootdir
    (both None where no config file is found: pytest's defaults apply). ``xfail_strict``: an
    xpassed run fails (pytest's ``XPASS(strict)``). ``norecursedirs``: the patterns of the
    folders a folder's sweep does not walk into (`folder_files`). ``rts_scenario_pattern``:
    the names of the scene files (`scene_file_kind`).
    """

    inifile: Path | None = None
    rootdir: Path | None = None
    xfail_strict: bool = False
    norecursedirs: tuple[str, ...] = NORECURSE_PATTERNS
    rts_scenario_pattern: str = DEFAULT_PATTERN

    def as_json(self) -> dict[str, Any]:
        """Return the settings as the sweep's JSON gives them (paths as text)."""
        return {"inifile": None if self.inifile is None else str(self.inifile),
                "rootdir": None if self.rootdir is None else str(self.rootdir),
                "xfail_strict": self.xfail_strict, "norecursedirs": list(self.norecursedirs),
                PATTERN_OPTION: self.rts_scenario_pattern}


def pytest_settings(paths: Iterable[str | Path]) -> PytestSettings:
    """Read the pytest settings ``pytest PATHS`` would run with, from the same config file.

    pytest finds it (`pytest.Config`): the first ``pytest.ini``, ``pyproject.toml`` with a
    ``[tool.pytest.ini_options]`` table, ``tox.ini`` with ``[pytest]``, ``setup.cfg`` with
    ``[tool:pytest]`` (...) from the common folder of ``paths`` upwards. Only the file is read:
    neither ``addopts``, ``PYTEST_ADDOPTS`` nor the ``conftest.py`` files. The plugin's
    ``rts_scenario_pattern`` is read with the plugin loaded, also where pytest loads no plugin
    on its own. Where none of
    `PYTEST_CONFIG_NAMES` is in those folders, or pytest is not installed, pytest's defaults
    apply, without importing pytest (which takes a while).

    Raises
    ------
    RtsError
        pytest cannot read the config file (pytest would stop on it too).
    """
    given = [Path(os.path.abspath(p)) for p in paths]
    if not any((folder / name).is_file() for path in given for folder in (path, *path.parents)
               for name in PYTEST_CONFIG_NAMES):
        return PytestSettings()
    try:
        import pytest
    except ImportError:
        return PytestSettings()
    # No capture, no assertion rewriting and no conftest: nothing this process keeps.
    args = ["--capture=no", "--assert=plain", "--noconftest", *map(str, given)]
    try:
        config = pytest.Config.fromdictargs({}, args)
        try:
            pattern = str(config.getini(PATTERN_OPTION))
        except ValueError:
            # Plugins not loaded on their own (PYTEST_DISABLE_PLUGIN_AUTOLOAD): the plugin's
            # setting is read with the plugin named, as a session that runs scenes names it.
            config = pytest.Config.fromdictargs({}, ["-p", "pytest_rts_scenario", *args])
            pattern = str(config.getini(PATTERN_OPTION))
    except (Exception, pytest.fail.Exception) as exc:
        from .errors import one_line

        raise RtsError(f"cannot read pytest's settings: {one_line(exc)}") from None
    strict = False
    for name in XFAIL_STRICT_OPTIONS:
        try:
            value = config.getini(name)
        except ValueError:
            continue
        if value is not None:
            strict = bool(value)
            break
    check_pattern(pattern, config.inipath)
    return PytestSettings(config.inipath, config.rootpath, strict,
                          tuple(config.getini("norecursedirs")), pattern)


@dataclass(frozen=True)
class SweepTask:
    """One run of a sweep: a scene file and one combination of its ``parametrize`` block.

    ``error`` is set when the file could not even be expanded into combinations (missing,
    not a scene, invalid ``parametrize``); the task then runs nothing and reports it.
    ``error_type`` says which exit code the error gives (``runtime`` when listing the
    combinations raised something else than bad input). ``path``, when set, is where the run
    reads ``file`` (its absolute path, for a worker whose current folder is another); the
    entry and its messages still name ``file``. ``marks`` are the scene's marks for this
    combination (`rts_scenario.scenario.written_marks`), which judge its run (`judged`).
    ``given_path`` marks the error of a path given that is no scene to run (not there, or a
    folder holding none): no mark expression selects it away (`select_tasks`).
    ``xfail_strict``: the project's pytest setting (`PytestSettings`), with which an ``xfail``
    mark fails the run whose check passes. ``misnamed``: the file holds a scene under a name
    the project's ``rts_scenario_pattern`` does not give a scene (`scene_file_kind`); its run
    is named after the whole file name, as the plugin names its item.
    """

    index: int
    file: str
    ident: str = ""
    parameters: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    path: str | None = None
    error_type: str = "bad_input"
    marks: tuple[str, ...] = ()
    given_path: bool = False
    xfail_strict: bool = False
    misnamed: bool = False

    @property
    def skipped(self) -> bool:
        """Whether its marks skip it (it then runs nothing, as pytest skips its item)."""
        return any(mark in SKIP_MARKS for mark in self.marks)


def collect_tasks(paths: Iterable[str | Path], notes: list[str] | None = None,
                  settings: PytestSettings | None = None) -> list[SweepTask]:
    """Expand folders (every scene file in them, recursively, sorted) and parametrize blocks.

    ``settings``: the project's pytest settings (by default read for ``paths``:
    `pytest_settings`). A folder's sweep does not walk into the folders pytest leaves out
    (`folder_files`); a file or folder given is always swept. A scene file reached twice
    (given twice, given and inside a folder given, or through a linked folder) runs once, so
    that its variants count once in the pass rates; ``notes`` (if given) receives a line for
    each repeat and each linked folder not walked because it holds itself.

    A folder's scene files are those the project's ``rts_scenario_pattern`` names (by default
    ``*.scenario.yaml``). A path that is neither a scene file nor a folder holding one, or a
    scene whose ``parametrize`` block is invalid, becomes one task carrying its error; so does
    a file in a folder that holds a scene under another name (`scene_file_kind`), or a scene
    file there that is a link to nothing: either would otherwise never run without the sweep
    saying so. Each task carries its combination's marks, as the pytest
    plugin gives them to its item (none for a file whose combinations cannot be listed as
    bad input).
    """
    from .located_yaml import load_yaml
    from .scenario import parametrizations, written_marks

    paths = list(paths)
    if settings is None:
        settings = pytest_settings(paths)
    pattern = settings.rts_scenario_pattern
    tasks: list[SweepTask] = []
    seen: dict[Path, str] = {}  # each scene file (resolved) and the name it first came as
    for given in paths:
        path = Path(given)
        misnamed: set[Path] = set()
        dangling: set[Path] = set()
        walked: set[Path] = set()  # the scene files (resolved) this folder gave
        if path.is_dir():
            found, left_out, loops = folder_files(path, settings.norecursedirs)
            if notes is not None:
                notes += [f"{loop}: {_loop_words(loop)}, a folder that holds it: not walked "
                          f"again" for loop in loops]
            kinds = {p: scene_file_kind(p, pattern) for p in found}
            scenes = [p for p, kind in kinds.items() if kind == "scene"]
            misnamed = {p for p, kind in kinds.items() if kind == "misnamed"}
            dangling = {p for p in scenes if p.is_symlink() and not p.exists()}
            files = sorted([*(p for p in scenes if p.is_file()), *misnamed, *dangling],
                           key=str)
            if not files:
                tasks.append(SweepTask(len(tasks), str(given),
                                       error=f"{given}: no {pattern} files in this folder"
                                             + _left_out_note(path, left_out),
                                       given_path=True))
        elif path.is_file():
            files = [path]
        else:
            tasks.append(SweepTask(len(tasks), str(given),
                                   error=f"{given}: no such file or folder", given_path=True))
            continue
        for file in files:
            name = str(given) if file is path else str(file)
            key = file.resolve()
            if key in seen:
                if notes is not None:
                    notes.append(f"{name}: the same file as {seen[key]} (through a link): run "
                                 f"once" if key in walked else
                                 f"{name}: given again (as {seen[key]} first): run once")
                continue
            seen[key] = name
            if file is not path:
                walked.add(key)
            if file in dangling:
                tasks.append(SweepTask(len(tasks), name, error=dangling_link(file)))
                continue
            if file in misnamed:
                tasks.append(SweepTask(len(tasks), name, error=misnamed_scene(name, pattern),
                                       misnamed=True))
                continue

            def marks_of(overrides: dict[str, Any], file: Path = file) -> tuple[str, ...]:
                try:
                    data = load_yaml(file).data
                except Exception:  # the run that loads it says what is wrong
                    return ()
                return written_marks(data, overrides)

            try:
                combos = parametrizations(file)
            except Exception as exc:  # the file's one run reports it; the others still run
                bad = isinstance(exc, RtsError)
                tasks.append(SweepTask(len(tasks), name, error=_message(name, exc),
                                       error_type="bad_input" if bad else "runtime",
                                       # To be selected by, not skipped by (as the plugin).
                                       marks=tuple(m for m in marks_of({})
                                                   if not bad or m not in SKIP_MARKS),
                                       xfail_strict=settings.xfail_strict))
                continue
            written = marks_of({})
            tasks += [SweepTask(len(tasks) + i, name, ident, overrides,
                                marks=marks_of(overrides) if any(
                                    k.split(".", 1)[0] == "marks" for k in overrides)
                                else written, xfail_strict=settings.xfail_strict)
                      for i, (ident, overrides) in enumerate(combos)]
    return tasks


class FolderFiles(NamedTuple):
    """What a folder's sweep finds in it (`folder_files`)."""

    files: list[Path]
    left_out: list[Path]  # the folders it does not walk into, as pytest does not
    loops: list[Path]  # the linked folders it does not walk: each holds the link itself


def _loop_words(loop: Path) -> str:
    """Say what a folder the walk does not enter again is: a link, or one reached through one.

    ``sweep sub``, where ``sub/back`` links to ``..``, walks ``sub/back`` (the parent) and
    meets ``sub/back/sub``: no link itself, but ``sub`` again.
    """
    try:
        if loop.is_symlink():
            return f"a link to {os.readlink(loop)}"
    except OSError:
        pass
    return f"{loop.resolve()} again (through a link above it)"


def folder_files(folder: Path, norecursedirs: Sequence[str] = NORECURSE_PATTERNS
                 ) -> FolderFiles:
    """Every file under ``folder``, and the folders in it a sweep leaves out, as pytest does.

    Left out (not walked into): a folder matching one of the ``norecursedirs`` patterns (the
    project's pytest setting; by default pytest's: hidden ones, ``build``, ``dist``,
    ``node_modules``, ``venv``, ``*.egg``, ...), ``__pycache__`` and a virtual environment (a
    folder holding ``pyvenv.cfg`` or ``conda-meta/history``). A pattern is matched against
    the folder's name, or against its path when it holds a ``/`` (``scenarios/drafts``), as
    pytest matches it. ``folder`` itself is walked whatever its name. Linked folders are
    followed, as pytest follows them, but never into a folder the walk is already in (a link
    to an enclosing folder, which pytest follows until the system refuses): such links are
    ``loops``.
    """
    files: list[Path] = []
    left_out: list[Path] = []
    loops: list[Path] = []
    # Each folder to walk and the real paths of the folders it is in (itself among them).
    stack = [(folder, frozenset({folder.resolve()}))]
    while stack:
        here, within = stack.pop()
        try:
            entries = sorted(os.scandir(here), key=lambda entry: entry.name)
        except OSError:  # unreadable: what pytest could not collect either
            continue
        inner: list[tuple[Path, frozenset[Path]]] = []
        for entry in entries:
            path = here / entry.name
            try:
                is_folder = entry.is_dir()  # through a link, as pytest's walk
            except OSError:
                is_folder = False
            if not is_folder:
                files.append(path)
            elif _left_out(path, norecursedirs):
                left_out.append(path)
            elif (real := path.resolve()) in within:
                loops.append(path)
            else:
                inner.append((path, within | {real}))
        stack += reversed(inner)
    return FolderFiles(files, left_out, loops)


def _left_out(folder: Path, norecursedirs: Sequence[str]) -> bool:
    if folder.name == "__pycache__" or any(_matches(pattern, folder)
                                           for pattern in norecursedirs):
        return True
    try:
        return ((folder / "pyvenv.cfg").is_file()
                or (folder / "conda-meta" / "history").is_file())
    except OSError:
        return False


def _matches(pattern: str, folder: Path) -> bool:
    """Whether a ``norecursedirs`` pattern matches ``folder``, as pytest matches it."""
    pattern = pattern.replace("/", os.sep)
    if os.sep not in pattern:
        return fnmatch(folder.name, pattern)
    # A pattern with a separator matches the whole path; unless absolute, at any depth.
    if not os.path.isabs(pattern):
        pattern = f"*{os.sep}{pattern}"
    return fnmatch(os.path.abspath(folder), pattern)


def _left_out_note(folder: Path, left_out: list[Path]) -> str:
    """Name the folders left out, where that is why a folder has no scene to sweep."""
    if not left_out:
        return ""
    shown = [str(p.relative_to(folder)) for p in left_out[:5]]
    more = f" and {len(left_out) - 5} more" if len(left_out) > 5 else ""
    return (f" ({len(left_out)} folder{'s' if len(left_out) != 1 else ''} in it left out, as "
            f"pytest leaves them out: {', '.join(shown)}{more}; name one to sweep it)")


def dangling_link(path: Path) -> str:
    """Say that ``path`` is a link to nothing (a scene linked from a folder that is not there)."""
    return f"{path}: cannot read file: a link to {os.readlink(path)}, which does not exist"


def run_task(task: SweepTask, method: str = "exact") -> Entry:
    """Run one task end to end on the simulated radar; never raises.

    Returns the entry ``{"scene", "file", "id", "parameters", "marks", "passed", "status",
    ...}``: ``status`` is ``pass``, ``fail`` or ``error``, judged by the scene's marks as the
    pytest plugin judges its item: ``skipped`` (a ``skip`` or ``skipif`` mark; nothing runs),
    and with an ``xfail`` mark ``xfail`` for a failed check or ``xpass`` for a passed one (a
    run that errs stays an error), or ``fail`` for a passed one where the task's
    ``xfail_strict`` is set (pytest's ``XPASS(strict)``). ``passed`` says whether the check
    passed. A failed run (``fail``, ``xfail``) adds ``reason``, a skipped one too; an erred one
    ``reason`` (its one-line message), ``error_type`` (``bad_input``: the scene does not load
    or its schedule cannot be built; ``runtime``: anything else) and the quantities of
    `QUANTITY_KEYS`, each None. Finished runs add ``detection_rate``, ``false_detections``,
    ``targets`` and ``targets_not_checked`` (those no radar cycle judged), ``errors`` (rms
    and max per quantity), ``max_error_ratio`` and ``max_error_quantity`` (the
    largest max error over its tolerance), ``solver_plan`` (where its solver plan came from:
    ``built``, ``memory`` or ``disk``) and ``seconds``.
    """
    from .errors import ScenarioError
    from .pipeline import RunOptions, run_scene
    from .scenario import load_scenario
    from .schedule import ScheduleError

    start = time.perf_counter()
    entry = _task_entry(task)
    source = task.path if task.path is not None else task.file
    if task.skipped:  # before its error, as pytest skips an item before running it
        if task.error is None:
            try:  # named as the pytest plugin names its item: by its scene, if it loads
                entry["scene"] = load_scenario(source, task.parameters).name
            except Exception:  # as in pytest, skipped all the same, named after its file
                pass
        mark = next(m for m in task.marks if m in SKIP_MARKS)
        return {**entry, "passed": False, "status": "skipped",
                "reason": f"the scene's marks: {mark}"}
    if task.error is not None:
        return error_entry(entry, task.error, task.error_type)

    def message(exc: BaseException) -> str:
        # Named as given, also where the run read it by its absolute path.
        text = _message(source, exc)
        return text if source == task.file else text.replace(source, task.file)

    try:
        scene = load_scenario(source, task.parameters)
    except Exception as exc:
        return error_entry(entry, message(exc),
                           "bad_input" if isinstance(exc, RtsError) else "runtime")
    entry["scene"] = scene.name
    try:
        report = run_scene(scene, RunOptions(method=method)).report
    except Exception as exc:
        # As in `rts-scenario run`: a schedule the scene asks for and the bench cannot build is
        # the scene's fault; anything else is a runtime error.
        bad = isinstance(exc, ScenarioError | ScheduleError)
        return error_entry(entry, message(exc), "bad_input" if bad else "runtime")
    from .check import QUANTITIES
    from .report import bench_failures, strict

    bench = bench_failures(report.reason_codes, report.playback)
    status = marked_status(task.marks, report.passed, task.xfail_strict, bench)
    entry.update(passed=report.passed, status=status)
    if not report.passed:
        entry["reason"] = "; ".join(report.reasons)
        if status == "fail" and "xfail" in task.marks:
            entry["reason"] += "; " + bench_not_expected(bench)
    elif status == "fail":  # an xpass under xfail_strict, worded as pytest's report of it
        entry["reason"] = "[XPASS(strict)] the scene's marks: xfail"
    ratio, worst = -1.0, None
    for quantity, tolerance_key in QUANTITIES:
        stats = report.errors[quantity]
        tolerance = scene.expectations.tolerances.get(tolerance_key)
        if stats.count and tolerance and stats.max / tolerance > ratio:
            ratio, worst = stats.max / tolerance, quantity
    entry.update(strict({
        "detection_rate": report.detection_rate,
        "false_detections": report.false_detections,
        "targets_not_checked": len(report.not_checked_targets),
        "targets": len(report.targets),
        "errors": {q: {"rms": s.rms, "max": s.max} for q, s in report.errors.items()
                   if s.count},
        "max_error_ratio": ratio if worst else None,
        "max_error_quantity": worst,
    }))
    entry["solver_plan"] = report.solver_plan
    entry["seconds"] = round(time.perf_counter() - start, 3)
    return entry


def marked_status(marks: Sequence[str], passed: bool, xfail_strict: bool = False,
                  bench: Sequence[str] = ()) -> str:
    """Return the status of a finished run whose check ``passed`` or not, by its scene's marks.

    As the pytest plugin's item: ``pass`` or ``fail``; with an ``xfail`` mark (a known failure
    of the check) ``xfail``, or ``xpass`` for a passed check, ``fail`` where ``xfail_strict``
    is set. A failed run the ``bench`` failed (its codes from `rts_scenario.report.
    bench_failures`: the RTS did not play it, the radar's messages were not seen) is ``fail``
    whatever its marks. A skip mark skips a run before it runs (`SweepTask.skipped`): not
    judged here.
    """
    if "xfail" not in marks or (not passed and bench):
        return "pass" if passed else "fail"
    if not passed:
        return "xfail"
    return "fail" if xfail_strict else "xpass"


def bench_not_expected(bench: Sequence[str]) -> str:
    """Why a failed run of a scene marked ``xfail`` fails all the same (as the plugin says).

    ``bench``: the bench failures (`rts_scenario.report.bench_failures`).
    """
    return (f"the scene's xfail mark expects the radar's check to fail, not the bench: "
            f"{', '.join(bench)}")


def _task_entry(task: SweepTask) -> Entry:
    """Return the part of a task's entry known before it runs (named after its file)."""
    scene = Path(task.file).name if task.misnamed else _file_scene(task.file)
    return {"scene": scene, "file": task.file, "id": task.ident,
            "parameters": dict(task.parameters), "marks": list(task.marks)}


def _file_scene(file: str) -> str:
    """Name a run whose scene did not report its name: its file's name without the suffix."""
    from .scenario import SCENE_SUFFIX

    return Path(file).name.removesuffix(SCENE_SUFFIX)


# What a finished run measured (`run_task`): an erred run has each of them, as null.
QUANTITY_KEYS = ("detection_rate", "false_detections", "targets_not_checked", "targets",
                 "errors", "max_error_ratio", "max_error_quantity")


def error_entry(entry: Entry, message: str, error_type: str) -> Entry:
    """Complete ``entry`` as a run that erred with ``message`` (one line).

    Every quantity a finished run gives (`QUANTITY_KEYS`) is None: the run measured nothing,
    and a number there, one it had before it erred or a default, would read as a result.
    """
    return {**entry, **dict.fromkeys(QUANTITY_KEYS), "passed": False, "status": "error",
            "reason": message, "error_type": error_type}


def _message(path: str, exc: BaseException) -> str:
    from .errors import located, one_line

    if isinstance(exc, RtsError):
        return located(path, exc)
    return f"{path}: {type(exc).__name__}: {one_line(exc)} (a runtime error)"


def warm_plans(tasks: Sequence[SweepTask], method: str = "exact") -> int:
    """Build (or load) the solver plan of every distinct rig and radar the tasks use, once.

    The plans land in this process's memory cache, which worker processes forked afterwards
    inherit, and in the disk cache (``$RTS_SCENARIO_CACHE_DIR``), which any other worker on
    this machine reads in milliseconds: no two workers build the same plan. A scene that
    fails here is left to its run, which reports it. Returns the number of distinct plans.
    """
    from .scenario import load_scenario
    from .schedule.build import FE_RESPONSES, solver_inputs
    from .solver import plan_key, solver_plan
    from .solver.estimator_aware import plan_method

    seen: set[str] = set()
    for task in tasks:
        if task.error is not None:
            continue
        try:
            scene = load_scenario(task.file, task.parameters)
            array, model = solver_inputs(scene.radar, FE_RESPONSES[0])
            key = plan_key(scene.rig, array, plan_method(method), model)
            if key not in seen:
                seen.add(key)
                solver_plan(scene.rig, array, plan_method(method), model)
        except Exception:  # the task's own run reports what is wrong
            continue
    return len(seen)


def run_sweep(tasks: Sequence[SweepTask], *, method: str = "exact", workers: int = 1,
              scheduler: str | None = None,
              on_result: Callable[[Entry], None] | None = None) -> list[Entry]:
    """Run every task; return their entries in task order.

    ``workers == 1`` without ``scheduler`` runs in this process, one task after the other;
    ``workers > 1`` in a pool of that many processes; ``scheduler`` on a Dask cluster: its
    address, or ``"local"`` for a `distributed.LocalCluster` of ``workers`` processes on this
    machine. ``on_result(entry)`` is called as each run finishes (in completion order).
    """
    done: dict[int, Entry] = {}

    def finish(task: SweepTask, entry: Entry) -> None:
        done[task.index] = entry
        if on_result is not None:
            on_result(entry)

    # Skipped and erred tasks run nothing: reported here, at once.
    runnable = [t for t in tasks if t.error is None and not t.skipped]
    for task in tasks:
        if task.error is not None or task.skipped:
            finish(task, run_task(task, method))
    # A pool for one run would only cost its start.
    workers = max(1, min(workers, len(runnable)))
    local = scheduler is None or scheduler == LOCAL_SCHEDULER
    if runnable and local and (workers > 1 or scheduler is not None):
        warm_plans(runnable, method)
    if scheduler is not None:
        if runnable:
            _run_dask(runnable, method, scheduler, workers, finish)
    elif workers == 1:
        for task in runnable:
            finish(task, run_task(task, method))
    else:
        _run_pool(runnable, method, workers, finish)
    return [done[t.index] for t in tasks]


def _run_pool(tasks: Sequence[SweepTask], method: str, workers: int,
              finish: Callable[[SweepTask, Entry], None]) -> None:
    # Forked workers start at once and inherit the plans `warm_plans` built; where fork does not
    # exist, the platform's default start method (the plans come from the disk cache then).
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else None)
    with ProcessPoolExecutor(max_workers=workers, mp_context=context,
                             initializer=_init_worker) as pool:
        futures = {pool.submit(run_task, task, method): task for task in tasks}
        try:
            _collect(futures, as_completed(futures), finish)
        except BaseException:  # Ctrl-C, SIGTERM: do not wait for the runs not started yet,
            # nor for those under way: SIGTERM reaches this process alone (Ctrl-C reaches the
            # workers too), and leaving the pool waits for its workers' runs to end.
            # (The pool's own map of them: it has no public handle on them before Python 3.14.)
            workers_running = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for process in workers_running:
                process.terminate()
            raise


def _init_worker() -> None:
    """Keep each worker process to one BLAS thread: the processes already fill the CPUs.

    SIGTERM ends a worker again (the command's handler, forked with it, would turn it into an
    interrupt): an interrupted sweep stops its workers so (`_run_pool`), and the command stops
    on its own SIGTERM.
    """
    import signal

    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threadpool_limits(limits=1, user_api="blas")


def _run_dask(tasks: Sequence[SweepTask], method: str, scheduler: str, workers: int,
              finish: Callable[[SweepTask, Entry], None]) -> None:
    distributed = require_dask()
    cluster = None
    try:
        if scheduler == LOCAL_SCHEDULER:
            import logging

            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1,
                                               processes=True, dashboard_address=None,
                                               silence_logs=logging.ERROR)
            client = distributed.Client(cluster)
        else:
            try:
                client = distributed.Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
            except (OSError, TimeoutError, ValueError) as exc:
                from .errors import one_line

                raise RtsError(f"--scheduler {scheduler}: cannot connect: {one_line(exc)}"
                               ) from None
        # A worker's current folder is its own (another machine's, a worker started
        # elsewhere): it reads each scene by its absolute path, the same on a shared folder.
        shipped = [replace(task, path=os.path.abspath(task.file)) for task in tasks]
        with client:
            # Each run is deterministic, not pure in Dask's sense (it times itself).
            futures = dict(zip(client.map(run_task, shipped, method=method, pure=False), tasks,
                               strict=True))
            _collect(futures, distributed.as_completed(futures), finish)
    finally:
        if cluster is not None:
            cluster.close()


def _collect(futures: dict[Any, SweepTask], completed: Iterable[Future[Entry]],
             finish: Callable[[SweepTask, Entry], None]) -> None:
    """Hand on each finished future's entry; a worker's failure becomes an erred entry."""
    from .errors import one_line

    for future in completed:
        task = futures[future]
        try:
            entry = future.result()
        except Exception as exc:  # the worker died or the task could not be shipped to it
            entry = error_entry(
                _task_entry(task),
                f"{task.file}: worker failed: {type(exc).__name__}: {one_line(exc)} "
                f"(a runtime error)", "runtime")
        finish(task, entry)


def require_dask() -> Any:
    """Return `distributed`, or raise the one-line error that says how to install it."""
    try:
        import distributed
    except ImportError:
        raise RtsError("--scheduler needs dask.distributed: pip install "
                       "'rts-scenario[sweep]'") from None
    return distributed


def default_workers() -> int:
    """Worker processes by default: the CPUs this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def run_label(entry: Entry) -> str:
    """``scene[id]`` (``scene`` when the scene has no parametrize block)."""
    return f"{entry['scene']}[{entry['id']}]" if entry.get("id") else str(entry["scene"])


def value_name(value: Any) -> str:
    """Name a parameter's value in the summary: equal numbers get one name.

    A number is named as a decimal number (``0``, ``0.0`` and ``-0.0`` are ``0.0``, ``12`` is
    ``12.0``), except an integer a float cannot hold exactly, which keeps its digits; a
    boolean is ``True`` or ``False``; anything else is its text.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, int):
        try:
            exact = float(value)
        except OverflowError:
            return str(value)
        if exact != value:
            return str(value)
        value = exact
    return repr(value + 0.0)  # -0.0 + 0.0 is 0.0


def summarize(entries: Sequence[Entry], worst: int = WORST_RUNS,
              deselected: int = 0) -> dict[str, Any]:
    """Count verdicts overall and per parameter value; pick the worst runs.

    The counts are ``runs`` (every entry) and, by status, ``passed``, ``failed``, ``errors``,
    ``xfailed``, ``xpassed`` and ``skipped``; ``pass_rate`` is ``passed`` over the runs that ran
    (skipped ones left out; None if none ran: no rate to give). ``deselected``: the runs a mark
    expression left out (`select_tasks`), which are not among ``entries``. ``by_parameter`` maps
    each parameter's key path to its values (named by :func:`value_name`, in the order they
    first appear) and each value to the same counts and its ``pass_rate``: equal numbers are one
    value (``0`` and ``0.0``). ``worst`` lists erred runs, then failed, xpassed and xfailed
    ones, then passing ones, each by their largest error over tolerance, at most ``worst`` runs
    (a pass with no error to rate is none of them, nor is a skipped run).
    """
    def counts_of(group: Iterable[Entry]) -> dict[str, Any]:
        counts = {"runs": 0, **dict.fromkeys(COUNTS.values(), 0)}
        for entry in group:
            counts["runs"] += 1
            counts[COUNTS[entry["status"]]] += 1
        ran = counts["runs"] - counts["skipped"]
        return {**counts, "pass_rate": counts["passed"] / ran if ran else None}

    groups: dict[str, dict[str, list[Entry]]] = {}
    for entry in entries:
        for key, value in entry["parameters"].items():
            groups.setdefault(key, {}).setdefault(value_name(value), []).append(entry)
    by_parameter = {key: {value: counts_of(group) for value, group in values.items()}
                    for key, values in groups.items()}
    order = {"error": 0, "fail": 1, "xpass": 2, "xfail": 3}

    def badness(entry: Entry) -> tuple[int, float]:
        ratio = entry.get("max_error_ratio")
        # A failed run with nothing to rate (nothing detected) leads its group.
        return order.get(entry["status"], 4), -(ratio if ratio is not None else math.inf)

    # A pass with nothing to rate is no close call: the worst runs leave it out.
    ranked = sorted((e for e in entries if e["status"] not in ("pass", "skipped")
                     or e.get("max_error_ratio") is not None), key=badness)[:worst]
    keys = ("scene", "file", "id", "status", "reason", "max_error_ratio", "max_error_quantity")
    return {**counts_of(entries), "deselected": deselected, "by_parameter": by_parameter,
            "worst": [{k: e[k] for k in keys if k in e} for e in ranked]}


def exit_code(entries: Sequence[Entry]) -> int:
    """Return the command line's exit code: 3 runtime error, 2 bad input, 1 a failure, else 0.

    As pytest's for the same scenes: an xfailed, xpassed or skipped run fails nothing.
    """
    types = {e.get("error_type") for e in entries if e["status"] == "error"}
    if "runtime" in types:
        return 3
    if types:
        return 2
    return 1 if any(e["status"] == "fail" for e in entries) else 0


def mark_expression(text: str) -> Callable[[Sequence[str]], bool]:
    """Compile a ``pytest -m`` mark expression; return whether a run's marks match it.

    pytest's own parser reads it (``slow and not hardware``, ``(a or b) and not c``), so it
    selects what ``pytest -m`` selects from the same scenes. A scene's marks carry no
    arguments: ``name(key=value)`` matches none.

    Raises
    ------
    RtsError
        pytest is not installed, or ``text`` is no mark expression (the message says where).
    """
    try:
        from _pytest.mark.expression import Expression
    except ImportError:
        raise RtsError("-m/--marks needs pytest (its mark expressions): pip install "
                       "pytest") from None
    try:
        expression = Expression.compile(text)
    except SyntaxError as exc:
        raise RtsError(f"-m/--marks {text!r}: not a mark expression: at column {exc.offset}: "
                       f"{exc.msg}") from None

    def matches(marks: Sequence[str]) -> bool:
        def has(name: str, /, **arguments: str | int | bool | None) -> bool:
            return name in marks and not arguments

        return expression.evaluate(has)

    return matches


def select_tasks(tasks: Sequence[SweepTask], text: str) -> tuple[list[SweepTask], int]:
    """Keep the tasks whose marks match the ``pytest -m`` expression ``text``.

    A path given that is no scene to run (``given_path``) is kept whatever ``text`` says: it
    is bad input, as pytest stops on a path that is not there, ``-m`` or not. Returns the kept
    tasks (renumbered in order) and how many were left out.

    Raises
    ------
    NoRunSelected
        ``text`` selects none of the tasks: a sweep of nothing would pass.
    RtsError
        ``text`` is no mark expression.
    """
    matches = mark_expression(text)
    kept = [replace(task, index=i) for i, task in enumerate(
        t for t in tasks if t.given_path or matches(t.marks))]
    if tasks and not kept:
        marks = sorted({mark for task in tasks for mark in task.marks})
        raise NoRunSelected(f"-m/--marks {text!r}: selects none of the {len(tasks)} run"
                       f"{'s' if len(tasks) != 1 else ''} (their marks: "
                       f"{', '.join(marks) or 'none'})")
    return kept, len(tasks) - len(kept)


__all__ = ["LOCAL_SCHEDULER", "NORECURSE_PATTERNS", "PYTEST_CONFIG_NAMES", "WORST_RUNS",
           "FolderFiles", "NoRunSelected", "PytestSettings", "SweepTask", "bench_not_expected",
           "collect_tasks", "default_workers", "error_entry", "exit_code", "folder_files",
           "mark_expression", "marked_status", "pytest_settings", "require_dask", "run_label",
           "run_sweep", "run_task", "select_tasks", "summarize", "warm_plans"]
