"""pytest plugin: every ``*.scenario.yaml`` is a test; ``rts_run`` runs scenes from Python.

Installed with rts-scenario (entry point ``pytest11``). One item per scene and per combination
of its ``parametrize`` block; a failing scene shows its report and its worst frames; metrics
go to the JUnit XML as properties; a scene's ``marks`` become pytest marks. Each test uses a
private virtual CAN channel, so ``pytest -n auto`` (pytest-xdist) gives the same verdicts.

The library (numpy, scipy, python-can, cantools) is imported only when a scene file is collected
or ``rts_run`` is used: every pytest start-up in an environment with rts-scenario installed loads
this plugin, most of them for tests that have nothing to do with scenes.
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import uuid
import warnings
from collections.abc import Callable, Generator, Iterator, Sequence
from fnmatch import fnmatch
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from rts_scenario.scene_files import DEFAULT_PATTERN, PATTERN_OPTION, check_pattern

if TYPE_CHECKING:
    from rts_scenario.pipeline import RunOptions, RunResult
    from rts_scenario.report import Report

def pytest_addoption(parser: pytest.Parser) -> None:
    """Options mirroring ``rts-scenario run``."""
    group = parser.getgroup("rts-scenario", "scene files as tests")
    group.addoption("--rts-output", default="simulated-radar",
                    help="where schedules go: simulated-radar (default), udp://HOST:PORT "
                         "or an installed RTS output")
    group.addoption("--rts-can-interface", default="virtual",
                    help="python-can interface for detections (default virtual)")
    group.addoption("--rts-can-channel", default=None,
                    help="CAN channel (default: a private one per test)")
    group.addoption("--rts-can-fd", action="store_true", help="CAN FD detection messages")
    group.addoption("--rts-mapping", default=None, help="*.mapping.yaml of a third-party radar")
    group.addoption("--rts-radar-channel", default=None, metavar="CH",
                    help="on an interface listening on several channels, read only the radar's "
                         "(Message.channel as python-can gives it); without it, a run hearing "
                         "the radar's identifiers on several channels fails")
    group.addoption("--rts-method", default="exact", choices=["exact", "paper", "estimator"],
                    help="weight solver (default exact)")
    parser.addini(PATTERN_OPTION, "glob of the scene files to collect (a file holding a scene "
                                  "under another name fails)", default=DEFAULT_PATTERN)


# The options that take one value (``--rts-can-fd`` is a switch).
_ONE_VALUE = ("--rts-output", "--rts-can-interface", "--rts-can-channel", "--rts-mapping",
              "--rts-radar-channel", "--rts-method")


def _refuse_repeats(args: Sequence[str | os.PathLike[str]]) -> None:
    """Refuse an ``--rts-*`` option given twice on the command line, as ``run`` does.

    argparse keeps the last: ``--rts-mapping A --rts-mapping B`` judged every scene by B
    without a word. One from ``addopts`` (or ``PYTEST_ADDOPTS``) that the command line gives
    again is pytest's way to override it, and stays so: ``args`` are the command line's alone.
    """
    given: dict[str, str] = {}
    words = _expanded([os.fspath(a) for a in args])
    for i, word in enumerate(words):
        name, equals, value = word.partition("=")
        if word == "--":
            break
        if name not in _ONE_VALUE:
            continue
        if not equals:
            value = words[i + 1] if i + 1 < len(words) else ""
        if name in given:
            raise pytest.UsageError(f"{name}: given twice ({given[name]!r}, then {value!r}); "
                                    f"give it once")
        given[name] = value


def _expanded(args: list[str], depth: int = 0) -> list[str]:
    """``args`` with each ``@FILE`` replaced by the arguments in it, as pytest reads them.

    pytest's parser (argparse's ``fromfile_prefix_chars``) takes each line of the file as one
    argument, an empty one too, and reads ``@FILE`` arguments in it in turn. A file that
    cannot be read is left as it is (pytest says so itself); files nested past 100 deep (a
    file naming itself) are left too.
    """
    out: list[str] = []
    for word in args:
        if word.startswith("@") and depth < 100:
            try:
                lines = Path(word[1:]).read_text().splitlines()
            except (OSError, UnicodeDecodeError):
                out.append(word)
                continue
            out += _expanded(lines, depth + 1)
        else:
            out.append(word)
    return out


def pytest_configure(config: pytest.Config) -> None:
    """Register the marks shipped scenes use; refuse bad ``--rts-*`` options once, up front."""
    for line in ("slow: a long scene", "hardware: needs a real RTS and radar",
                 "hard: a hard numerical or physical case"):
        config.addinivalue_line("markers", line)
    from rts_scenario.errors import RtsError
    from rts_scenario.settings import check_environment

    try:
        check_environment()
        check_pattern(config.getini(PATTERN_OPTION), config.inipath)
    except RtsError as exc:
        raise pytest.UsageError(str(exc)) from None
    _refuse_repeats(config.invocation_params.args)
    for option in ("--rts-output", "--rts-can-interface", "--rts-can-channel", "--rts-mapping"):
        # An unset shell variable (``--rts-mapping=$MAPPING``) is not the option left out, as
        # for ``rts-scenario run``.
        if config.getoption(option) == "":
            raise pytest.UsageError(f"{option}: an empty value; give one, or leave the option "
                                    f"out")
    spec = config.getoption("--rts-output")
    mapping_path = config.getoption("--rts-mapping")
    can_fd = config.getoption("--rts-can-fd")
    interface = config.getoption("--rts-can-interface")
    radar_channel = config.getoption("--rts-radar-channel")
    # The defaults need no check (nor the library's import).
    if (spec != "simulated-radar" or mapping_path or can_fd or interface != "virtual"
            or radar_channel is not None):
        from rts_scenario.canbus.mapping import CanMapping
        from rts_scenario.cli.common import (
            check_can_interface,
            check_can_opens,
            check_fd_mapping,
            check_output,
            check_radar_channel,
            named_file,
        )

        try:
            check_output("--rts-output", spec, run=True)
            check_radar_channel(radar_channel)
            check_can_interface("--rts-can-interface", interface,
                                config.getoption("--rts-can-channel"),
                                channel_option="--rts-can-channel")
            if mapping_path:
                mapping = named_file("--rts-mapping", CanMapping.from_file, mapping_path)
                check_fd_mapping(can_fd, mapping_path, mapping)
            # Once here, not once per scene: an interface this machine cannot open.
            check_can_opens("--rts-can-interface", interface,
                            config.getoption("--rts-can-channel"), "--rts-can-channel",
                            fd=can_fd)
        except RtsError as exc:
            raise pytest.UsageError(str(exc).replace("--can-fd", "--rts-can-fd").replace(
                "--radar-channel", "--rts-radar-channel")) from None
        _refuse_workers_sharing_a_bench(config, spec, interface)
    if config.pluginmanager.hasplugin("html") and config.getoption("htmlpath", None):
        config.pluginmanager.register(HtmlReport(), "rts-scenario-html")


def _refuse_workers_sharing_a_bench(config: pytest.Config, spec: str, interface: str) -> None:
    """Refuse xdist workers driving one bench at once: each run would judge another's radar.

    The simulated radar on a private virtual channel is each test's own; an RTS output other
    than it, or a CAN interface other processes hear, is one bench (one RTS, one radar, one
    bus), which runs one scene at a time.
    """
    workers = 0
    if getattr(config.option, "dist", "no") != "no":
        # xdist's gateway specs: ``-n 2`` gives two, ``--tx 2*popen`` one for two workers.
        for tx in getattr(config.option, "tx", None) or ():
            count, star, _ = str(tx).partition("*")
            workers += int(count) if star and count.strip().isdigit() else 1
    workers = max(workers, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0))
    if workers <= 1:
        return
    shared = [(option, value) for option, value, own in (
        ("--rts-output", spec, "simulated-radar"),
        ("--rts-can-interface", interface, "virtual")) if value != own]
    if shared:
        option, value = shared[0]
        raise pytest.UsageError(
            f"{option} {value} with {workers} xdist workers: that is one bench (one RTS, one "
            f"radar, one bus), and workers running scenes on it at once would mix their frames "
            f"and detections, each judging another's; run the scenes one at a time (-n 0)")


def pytest_collect_file(parent: pytest.Collector,
                        file_path: Path) -> ScenarioFile | MisnamedScene | None:
    """Collect scene files matching the ``rts_scenario_pattern`` ini option.

    A YAML file that holds a scene (its ``rts_scenario`` key) under another name
    (``cut_in.scenario.yml``, ``cut_in.yaml``, or ``cut_in.scenario.yaml`` where the project's
    pattern is another) is one failing item: the scene it holds would otherwise never run, and
    the session would not say so (`rts_scenario.scene_files.scene_file_kind`, the sweep's rule
    too).
    """
    from rts_scenario.scene_files import scene_file_kind

    kind = scene_file_kind(file_path, parent.config.getini(PATTERN_OPTION))
    if kind == "scene":
        return ScenarioFile.from_parent(parent, path=file_path)
    if kind == "misnamed":
        return MisnamedScene.from_parent(parent, path=file_path)
    return None


@pytest.hookimpl(wrapper=True)
def pytest_make_collect_report(collector: pytest.Collector
                               ) -> Generator[None, pytest.CollectReport, pytest.CollectReport]:
    """Add a failing item for each scene file in a folder that is a link to nothing.

    pytest walks past such a link (neither a file nor a folder): the scene it named would
    never run, and the session would not say so.
    """
    report = yield
    if isinstance(collector, pytest.Directory) and report.passed:
        pattern = collector.config.getini(PATTERN_OPTION)
        try:
            entries = sorted(os.scandir(collector.path), key=lambda e: e.name)
        except OSError:
            return report
        for entry in entries:
            if (fnmatch(entry.name, pattern) and entry.is_symlink()
                    and not os.path.exists(entry.path)):
                report.result.append(DanglingScene.from_parent(collector,
                                                               path=Path(entry.path)))
    return report


@contextlib.contextmanager
def frozen_heap(active: bool = True) -> Iterator[None]:
    """Run the body with the session's objects frozen, as a command plays a scene (``active``).

    A test session's heap grows with its tests: a full collection of it (hundreds of
    milliseconds late in a long session) holds every thread, the sender pacing frames to an
    RTS among them, whose frames then go out late. Collected first (no garbage of earlier
    tests is kept), then frozen (`gc.freeze`), so no collection scans it while the body runs;
    unfrozen after it. Left alone where the session froze objects itself. The plugin freezes
    for scenes played to an RTS: the built-in simulated radar keeps no wall-clock time.
    """
    if not active or gc.get_freeze_count():
        yield
        return
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _options(config: pytest.Config, **overrides: Any) -> RunOptions:
    from rts_scenario.pipeline import RunOptions

    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    values = {
        "output": config.getoption("--rts-output"),
        "can_interface": config.getoption("--rts-can-interface"),
        "can_channel": config.getoption("--rts-can-channel")
        or f"rts-scenario-{worker}-{uuid.uuid4().hex[:8]}",
        "can_fd": config.getoption("--rts-can-fd"),
        "mapping": config.getoption("--rts-mapping"),
        "radar_channel": config.getoption("--rts-radar-channel"),
        "option_prefix": "rts-",  # reasons name the plugin's options
        "method": config.getoption("--rts-method"),
    }
    values.update(overrides)
    return RunOptions(**values)


class ScenarioFile(pytest.File):
    """A scene file: one item per parametrized combination."""

    def collect(self) -> Iterator[ScenarioItem]:
        """Validate the scene: one item per combination, loaded here.

        A combination that does not load is still an item, which fails with the one-line
        error naming file, line and key (as ``rts-scenario run`` reports it, the other
        combinations and scenes still run); a file whose ``parametrize`` block cannot be
        expanded is one such item. So is a combination whose loading raised anything else (a
        bug, not bad input), which fails with that exception and its traceback. A collection
        error would stop the whole session.
        """
        from rts_scenario.errors import RtsError, located
        from rts_scenario.scenario import SCENE_SUFFIX, load_scenario, parametrizations, run_label

        path = str(self.path)
        # A run that does not load is named after its file, as rts-scenario run names it.
        file_name = self.path.name.removesuffix(SCENE_SUFFIX)
        known = {line.split(":", 1)[0].split("(", 1)[0].strip()
                 for line in self.config.getini("markers")}

        def register(marks: tuple[str, ...]) -> tuple[str, ...]:
            # A scene's own marks are registered, so --strict-markers accepts them.
            for mark in set(marks) - known:
                self.config.addinivalue_line("markers", f"{mark}: a mark of scene files")
                known.add(mark)
            return marks

        try:
            combos = parametrizations(self.path)
        except RtsError as exc:
            # With the marks the file writes, to be selected by (`-m slow` selects a slow scene
            # whose parametrize block is broken), but not skipped by: which combinations a skip
            # was meant for is what the broken block would have said.
            from rts_scenario.sweep import SKIP_MARKS

            marks = tuple(m for m in _written_marks(self.path, {}) if m not in SKIP_MARKS)
            yield ScenarioItem.from_parent(self, name=file_name, overrides={},
                                           marks=register(marks), error=located(path, exc))
            return
        except Exception as exc:
            yield ScenarioItem.from_parent(self, name=file_name, overrides={},
                                           marks=register(_written_marks(self.path, {})),
                                           crash=exc)
            return

        for ident, overrides in combos:
            try:
                scene = load_scenario(self.path, overrides)
            except RtsError as exc:
                message = located(path, exc) + (f" [{ident}]" if ident else "")
                yield ScenarioItem.from_parent(
                    self, name=run_label(file_name, ident), overrides=overrides,
                    marks=register(_written_marks(self.path, overrides)), error=message)
                continue
            except Exception as exc:
                yield ScenarioItem.from_parent(
                    self, name=run_label(file_name, ident), overrides=overrides,
                    marks=register(_written_marks(self.path, overrides)), crash=exc)
                continue
            yield ScenarioItem.from_parent(self, name=scene.label, overrides=overrides,
                                           marks=register(scene.marks))


class MisnamedScene(pytest.File):
    """A file holding a scene under a name the plugin does not collect: one failing item."""

    def collect(self) -> Iterator[ScenarioItem]:
        """Yield the item that says so and how to name the file."""
        from rts_scenario.scene_files import misnamed_scene

        yield ScenarioItem.from_parent(
            self, name=self.path.name, overrides={}, marks=(),
            error=misnamed_scene(str(self.path), self.config.getini(PATTERN_OPTION)))


class DanglingScene(pytest.File):
    """A scene file that is a link to nothing: one failing item."""

    def collect(self) -> Iterator[ScenarioItem]:
        """Yield the item that says where the link leads."""
        from rts_scenario.scenario import SCENE_SUFFIX

        yield ScenarioItem.from_parent(
            self, name=self.path.name.removesuffix(SCENE_SUFFIX), overrides={}, marks=(),
            error=f"{self.path}: cannot read file: a link to {os.readlink(self.path)}, which "
                  f"does not exist")


def _written_marks(path: Path, overrides: dict[str, Any]) -> tuple[str, ...]:
    """Return the marks a scene file gives itself, read from its text (or its combination).

    For a combination that does not load: ``-m`` selects it, and ``skip`` skips it, as the
    scene says (`rts_scenario.scenario.written_marks`).
    """
    from rts_scenario.located_yaml import load_yaml
    from rts_scenario.scenario import written_marks

    try:
        data = load_yaml(path).data
    except Exception:  # the item's error says what is wrong with the file
        return ()
    return written_marks(data, overrides)


class BenchSettingWarning(UserWarning):
    """A combination over the built-in simulated radar's options, played to an RTS."""


class TargetsNotCheckedWarning(UserWarning):
    """A scene passed with targets no radar cycle judged (under limits it expects all along)."""


class RunFailed(Exception):
    """A scene ran and failed (`ScenarioFailed`, `BenchFailed`)."""

    def __init__(self, result: RunResult) -> None:
        super().__init__(result.report.scene)
        self.result = result


class ScenarioFailed(RunFailed):
    """A scene ran and its check failed: what a scene's ``xfail`` mark expects."""


class BenchFailed(RunFailed):
    """A scene marked ``xfail`` ran and the bench failed it: not the failure the mark expects.

    The RTS did not play the schedule or the radar's messages were not seen
    (`rts_scenario.report.BENCH_FAILURE_CODES`): the radar was not checked.
    """


class ScenarioItem(pytest.Item):
    """One run of a scene."""

    def __init__(self, *, overrides: dict[str, Any], marks: tuple[str, ...],
                 error: str | None = None, crash: Exception | None = None,
                 **kwargs: Any) -> None:
        from rts_scenario.sweep import SKIP_MARKS

        super().__init__(**kwargs)
        self.overrides = overrides
        self.error = error  # the scene did not load: the item fails with this message
        self.crash = crash  # loading it raised (a bug): the item fails with this exception
        for mark in marks:
            if mark == "xfail":
                # A known failure of the radar's check; a scene that does not load or run is
                # no such failure, and fails.
                self.add_marker(pytest.mark.xfail(raises=ScenarioFailed,
                                                  reason="the scene's marks: xfail"))
            elif mark in SKIP_MARKS:
                # Said as sweep says it: without a reason, pytest's report (and the JUnit XML's
                # <skipped>) would say "unconditional skip", or nothing for skipif.
                reason = f"the scene's marks: {mark}"
                self.add_marker(pytest.mark.skip(reason=reason) if mark == "skip"
                                else pytest.mark.skipif(True, reason=reason))
            else:
                self.add_marker(mark)

    def runtest(self) -> None:
        """Run the scene end to end and check it."""
        from rts_scenario.errors import RtsError
        from rts_scenario.pipeline import run_scene
        from rts_scenario.scenario import load_scenario
        from rts_scenario.scenario.model import simulated_radar_parameters

        if self.error is not None:
            raise RtsError(self.error)
        if self.crash is not None:
            raise self.crash

        # The HTML report's plots need what the run plays and measures: gather it only for it.
        plot = self.config.pluginmanager.hasplugin("rts-scenario-html")
        scene = load_scenario(self.path, self.overrides)
        options = _options(self.config, plot=plot)
        unused = simulated_radar_parameters(scene.parameters)
        if unused and options.output != "simulated-radar":
            # As `rts-scenario run` notes it: the item's verdict is not one of that setting.
            # A note, shown in the warnings summary whatever the project's warning filters:
            # under `-W error` (or `filterwarnings = error`) it stopped the scene unplayed.
            with warnings.catch_warnings():
                warnings.simplefilter("always", BenchSettingWarning)
                warnings.warn(BenchSettingWarning(
                    f"{self.name}: {', '.join(unused)} set the built-in simulated radar; on "
                    f"the bench ({options.output}) the radar measures as it is set, so this "
                    f"combination runs as the others do"), stacklevel=1)
        with frozen_heap(options.output != "simulated-radar"):
            result = run_scene(scene, options)
        report = result.report
        self.user_properties.extend(_metrics(report))
        unchecked = report.not_checked_targets
        if report.passed and unchecked:
            # PASSED alone would hide them (`rts-scenario run` says so beside the pass). Under
            # the project's warning filters: `-W error::...TargetsNotCheckedWarning` fails such
            # a pass, `ignore` silences it.
            warnings.warn(TargetsNotCheckedWarning(
                f"{self.name}: passed with {len(unchecked)} of {len(report.targets)} "
                f"targets not checked (under limits the scene expects all along): "
                f"{', '.join(unchecked[:5])}{', ...' if len(unchecked) > 5 else ''}"),
                stacklevel=1)
        if not report.passed:
            from rts_scenario.report import bench_failures

            if bench_failures(report.reason_codes, report.playback) \
                    and self.get_closest_marker("xfail"):
                raise BenchFailed(result)
            raise ScenarioFailed(result)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: Any = None) -> str | Any:
        """Show the report and worst frames of a failed check; one clean line for bad input."""
        from rts_scenario.errors import RtsError, located

        if isinstance(excinfo.value, ScenarioFailed):
            return _render(excinfo.value.result)
        if isinstance(excinfo.value, BenchFailed):
            from rts_scenario.report import bench_failures
            from rts_scenario.sweep import bench_not_expected

            report = excinfo.value.result.report
            bench = bench_failures(report.reason_codes, report.playback)
            return f"{bench_not_expected(bench)}\n\n{_render(excinfo.value.result)}"
        if isinstance(excinfo.value, RtsError):
            if self.error is not None:  # the load error, located already
                return f"error: {self.error}"
            return f"error: {located(str(self.path), excinfo.value)}"
        return super().repr_failure(excinfo, style=style)

    def reportinfo(self) -> tuple[Path, int, str]:
        """Where the test comes from."""
        return self.path, 0, f"scenario: {self.name}"


# The JUnit XML property listing why a test failed or was skipped (`_outcome_codes`).
REASONS_PROPERTY = "reasons"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """Give a scene that failed or was skipped its ``reasons`` property (JUnit XML).

    A scene whose check failed has it from its report (`ScenarioItem.runtest`); one that was
    skipped, did not load or erred while it ran gets it here.
    """
    report = yield
    if (isinstance(item, ScenarioItem) and report.when in ("setup", "call")
            and (report.failed or report.skipped)
            and all(name != REASONS_PROPERTY for name, _ in item.user_properties)):
        item.user_properties.append((REASONS_PROPERTY, _outcome_codes(item, call)))
    return report


def _outcome_codes(item: ScenarioItem, call: pytest.CallInfo[None]) -> str:
    """Return the reason code of a scene that did not run to a verdict.

    The mark that skipped it (``skip``, ``skipif``; ``skipped`` for a skip of another's
    making); ``bad_input`` where it did not load or its schedule or CAN interface could not be
    had (as ``rts-scenario run`` exits 2); ``xpass_strict`` where its check passed under an
    ``xfail`` mark and ``xfail_strict``; else ``runtime`` (exit 3).
    """
    from rts_scenario.errors import BusError, ScenarioError
    from rts_scenario.schedule import ScheduleError
    from rts_scenario.sweep import SKIP_MARKS

    error = call.excinfo.value if call.excinfo is not None else None
    if call.excinfo is None and call.when == "call":
        # It ran and raised nothing, yet failed: an xfail scene whose check passed, with
        # xfail_strict (pytest's "[XPASS(strict)]").
        return "xpass_strict"
    if call.excinfo is not None and call.excinfo.errisinstance(pytest.skip.Exception):
        return next((mark.name for mark in item.iter_markers() if mark.name in SKIP_MARKS),
                    "skipped")
    if item.error is not None or isinstance(error, ScenarioError | ScheduleError | BusError):
        return "bad_input"
    return "runtime"


def _metrics(report: Report) -> list[tuple[str, object]]:
    # No detection rate where nothing was checkable (an empty bench): "null", as in the JSON.
    rate = report.detection_rate
    out: list[tuple[str, object]] = [("passed", report.passed),
                                     ("detection_rate",
                                      round(rate, 4) if math.isfinite(rate) else "null"),
                                     ("false_detections", report.false_detections),
                                     ("targets_not_checked", len(report.not_checked_targets))]
    for name, stats in report.errors.items():
        if stats.count:
            out += [(f"{name}_rms", round(stats.rms, 5)), (f"{name}_max", round(stats.max, 5))]
    if not report.passed:
        # What failed it, by name (docs/report.md, reason codes), comma-separated.
        out.append((REASONS_PROPERTY, ",".join(report.reason_codes)))
    return out


def _render(result: RunResult) -> str:
    """Render the report table and the worst frames (misses first, then largest errors)."""
    report = result.report
    lines = [report.verdict_line, "", report.table(verdict=False), ""]
    if not report.worst_frames:
        return "\n".join([*lines, "worst frames: none (no target-frame was judged)"])
    lines += ["worst frames (error / tolerance):",
              f"{'frame':>6} {'t_s':>7} {'target':<18} {'range':>8} {'vel':>8} {'az':>8} "
              f"{'el':>8}"]
    tolerances = result.scene.expectations.tolerances
    for row in report.worst_frames:
        # Each error over its tolerance (as the frames are ranked): beyond +-1 is out of it.
        cells = ["missed" if row["missed"] else f"{row[key] / tolerances[key]:+.3f}"
                 for key in ("range_m", "radial_velocity_mps", "az_deg", "el_deg")]
        lines.append(f"{row['frame']:>6} {row['t_s']:>7.2f} {row['target']:<18} "
                     + " ".join(f"{c:>8}" for c in cells))
    return "\n".join(lines)


class HtmlReport:
    """With pytest-html and ``--html``: a failed scene's report carries its table and plots.

    Registered by `pytest_configure` only when pytest-html is installed and writes a report,
    so without it nothing changes (and no run gathers what plots draw).
    """

    @pytest.hookimpl(wrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item,
                                  call: pytest.CallInfo[None]
                                  ) -> Generator[None, pytest.TestReport, pytest.TestReport]:
        """Add the failed scene's table and plots to the report's ``extras``."""
        report = yield
        failure = call.excinfo.value if call.excinfo is not None else None
        if isinstance(failure, RunFailed):
            extras = [*getattr(report, "extras", []),
                      *_html_extras(failure.result)]
            report.extras = extras  # type: ignore[attr-defined]  # pytest-html reads it
        return report


def _html_extras(result: RunResult) -> list[dict[str, Any]]:
    """Return the report table (as the CLI prints it) and every plot of the run, base64 PNG."""
    import base64
    import html
    import importlib.util
    import tempfile

    from pytest_html import extras

    from rts_scenario.plots import write_plots

    out = [extras.html(f'<pre class="rts-scenario-report">{html.escape(_render(result))}'
                       f"</pre>")]
    if importlib.util.find_spec("matplotlib") is None:  # say so where the plots would be
        return [*out, extras.html("<p>No plots: they need matplotlib (pip install "
                                  "'rts-scenario[plot]').</p>")]
    with tempfile.TemporaryDirectory(prefix="rts-scenario-html-") as folder:
        try:
            written = write_plots(result, folder)
        except Exception as exc:  # a report that cannot draw must not break the test session
            return [*out, extras.html(f"<p>No plots: {html.escape(type(exc).__name__)}: "
                                      f"{html.escape(str(exc))}</p>")]
        for path in written:
            data = base64.b64encode(path.read_bytes()).decode("ascii")
            out.append(extras.png(data, name=path.stem))
    return out


@pytest.fixture
def rts_run(request: pytest.FixtureRequest) -> Callable[..., RunResult]:
    """Run a scene (path or loaded `Scenario`) end to end; keyword options as `RunOptions`.

    A relative path that does not exist from the current folder is taken relative to the
    calling test file's folder. A parametrized scene file is one of its variants, named by
    ``variant=`` (its id, as the plugin's items have it): its file as written is none of its
    runs, so without ``variant`` the call raises, listing them.
    """
    def run(scene: Any, variant: str | None = None, **options: Any) -> RunResult:
        from rts_scenario.pipeline import run_scene
        from rts_scenario.scenario import load_scenario, select_variant

        if isinstance(scene, str | Path):
            if not Path(scene).is_absolute():
                beside_test = request.path.parent / scene
                if not Path(scene).exists() and beside_test.exists():
                    scene = beside_test
            _, overrides = select_variant(scene, variant, option="variant=")
            scene = load_scenario(scene, overrides)
        elif variant is not None:
            raise TypeError("rts_run: variant= names a variant of a scene file; a loaded "
                            "Scenario is one already")
        run_options = _options(request.config, **options)
        with frozen_heap(run_options.output != "simulated-radar"):
            return run_scene(scene, run_options)

    return run
