"""What the subcommands share: exit codes, the progress bar, checks of what options name."""

from __future__ import annotations

import argparse
import errno
import ipaddress
import math
import os
import stat
import sys
import traceback
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

from ..atomic import check_draft, write_atomic
from ..errors import RtsError, one_line
from ..suffixes import LOG_SIDECAR_SUFFIX

# Weight solver methods a command line can choose (``--method``).
# The schedule's methods (`solver.estimator_aware.SCHEDULE_METHODS`; a test keeps them equal).
METHODS = ("exact", "paper", "estimator")

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_BAD_INPUT = 2
EXIT_RUNTIME_ERROR = 3
# pytest's exit code when no test ran (none collected, or all deselected).
EXIT_NO_RUNS = 5


class _ReaderGone:
    """Standard output or error that outlives its reader (``rts-scenario run ... | head``).

    Standard error too (``2>&1 | head``). Once the reader has gone, what is still written goes
    to the null device: the command runs to its end, writes its files and exits with its
    verdict, instead of failing every later scene on a broken pipe. So it goes for output that
    cannot be written (``> /dev/full``, a lost device), which is kept in ``lost``: nobody saw
    what was printed, and the command exits with a runtime error (`rts_scenario.cli.main`),
    never with its verdict.
    """

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self.reader_gone = False
        self.lost: OSError | None = None
        # A duplicate of the stream's file descriptor while it points at the null device for
        # output that could not be written (`restore` puts it back).
        self._saved: int | None = None

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._to_null()
        except OSError as exc:
            self._lose(exc)
        return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._to_null()
        except OSError as exc:
            self._lose(exc)

    def restore(self) -> None:
        """Flush; give the stream its own file back if output could not be written to it.

        A reader that has gone stays gone (the null device), but a full or lost device is
        tried again by the next command in this process (`rts_scenario.cli.main` called
        twice), which then reports its own lost output.
        """
        self.flush()
        if self._saved is not None:
            os.dup2(self._saved, self._stream.fileno())
            os.close(self._saved)
            self._saved = None

    def _lose(self, exc: OSError) -> None:
        self.lost = self.lost or exc
        if self._saved is None:
            self._saved = os.dup(self._stream.fileno())
        self._to_null()

    def _to_null(self) -> None:
        # The stream's file descriptor now points at the null device, so its buffer (and, for a
        # reader gone, the interpreter's last flush at exit) drains there.
        self.reader_gone = True
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, self._stream.fileno())
        finally:
            os.close(null)
        self._stream.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def guarded_output(stream: TextIO) -> _ReaderGone | None:
    """Return ``stream`` wrapped in `_ReaderGone` when it is a file (not a capture), else None.

    For standard output and standard error alike.
    """
    try:
        stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None
    return _ReaderGone(stream)


def stdout_reader_gone() -> bool:
    """Whether standard output's reader has gone (`guarded_output`): nothing printed is read."""
    return bool(getattr(sys.stdout, "reader_gone", False))


class Progress:
    """A one-line progress bar on stderr, only when it is a terminal.

    ``unit`` names what is counted; fewer than ``minimum`` of them show nothing (a short run).
    """

    def __init__(self, label: str, unit: str = "frames", minimum: int = 200) -> None:
        self.label, self.unit, self.minimum = label, unit, minimum
        self.active = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        """Show ``done`` of ``total``; fewer than ``minimum`` in all show nothing."""
        if not self.active or total < self.minimum:
            return
        width = 30
        filled = int(width * done / total)
        line = (f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {done}/{total} "
                f"{self.unit}")
        sys.stderr.write(line)
        if done >= total:
            sys.stderr.write("\r" + " " * len(line) + "\r")
        sys.stderr.flush()


@contextmanager
def writing(option: str, path: str | Path) -> Iterator[None]:
    """Turn an `OSError` while writing what ``option`` names into an `RtsError` naming both."""
    try:
        yield
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise RtsError(f"{option} {path}: cannot write: {reason}") from exc


# The ``--json`` reports this process wrote (`write_json`), by path as given.
_written_reports: set[str] = set()


def write_json(option: str, path: str | Path, data: Any) -> None:
    """Write ``data`` as strict JSON to the file ``option`` names, replacing it whole.

    A reader (a CI system polling the report) never sees half a file, and a write that fails
    leaves the file as it was, not cut short.
    """
    import json

    text = json.dumps(data, indent=2, allow_nan=False) + "\n"
    with writing(option, path):
        write_atomic(path, text)
    if option == "--json":
        report_written(path)


def report_written(path: str | Path) -> None:
    """Note that this process wrote its ``--json`` report ``path`` (`replace_unwritten_report`)."""
    _written_reports.add(str(path))


@contextmanager
def replacing_after_stop(path: str | Path) -> Iterator[None]:
    """Write a report after a stop: a failure is one line (or, for RtsError, the exit code).

    A stop may leave a module half imported or a write half done; the stop is the command's
    outcome, so nothing here raises but a second stop.
    """
    try:
        yield
    except (RtsError, KeyboardInterrupt):
        pass  # the exit code says it
    except Exception as exc:  # whatever the stop left half-done
        print(f"error: --json {path}: not replaced after the stop: {type(exc).__name__}: "
              f"{one_line(exc)}", file=sys.stderr)


def replace_unwritten_report(args: argparse.Namespace) -> None:
    """After a stop, write ``--json`` if the command wrote none: no verdict, interrupted.

    An earlier run's report left in place would be read as this one's. `run` and `sweep` write
    their own (the scenes not run, the runs that finished); for the others this is their
    report: ``{"command": ..., "passed": false, "interrupted": true, "error": ...}``. Never
    over a file the command line names for another option (the command's own check of that
    may not have run yet).
    """
    path = getattr(args, "json", None)
    if not path or str(path) in _written_reports or args.command in ("run", "sweep"):
        return
    if same_as_any(path, other_files(args)):
        return
    with replacing_after_stop(path):
        write_json("--json", path, {"command": args.command, "passed": False,
                                    "interrupted": True,
                                    "error": "interrupted (Ctrl-C or SIGTERM) before the "
                                             "command wrote its report: no verdict"})


def other_files(args: argparse.Namespace) -> list[str]:
    """Return every text the command line gives an argument other than ``--json``.

    A report written without the command's own checks (after a stop, on a usage error) is
    never written over a file the command line names for another purpose.
    """
    named: list[Any] = []
    for key, value in vars(args).items():
        if key != "json":
            named += value if isinstance(value, list) else [value]
    record = getattr(args, "record", None)
    if isinstance(record, str):  # and the sidecar `--record` writes beside its log
        named.append(f"{record}{LOG_SIDECAR_SUFFIX}")
    return [value for value in named if isinstance(value, str)]


def check_writable_file(option: str, path: str | Path, kind: str | None = None, *,
                        in_place: bool = False) -> None:
    """Fail now, before a long run, if the file ``option`` names could not be written later.

    The probe opens the file for appending (and removes it again if it did not exist), so
    read-only file systems and missing permissions are found whoever runs it. A file replaced
    whole (all but those written ``in_place``, as they come) is written to a draft beside it:
    one is made and removed too, or a folder that takes no new file would lose the result after
    the run. An output is never named like a file the tool reads (a scene, rig, DBC, ...),
    unless it is one: ``kind``, the suffix of what ``option`` writes (e.g. ``".rig.yaml"``).
    """
    target = Path(path)
    if str(path) == "":
        raise RtsError(f"{option}: needs a file path, got an empty one")
    if str(path) == "-":  # read as standard output, not a file named "-" in the current folder
        raise RtsError(f"{option} -: a file path, not standard output (which carries the text "
                       f"report); to name a file '-', write ./-")
    from ..file_kinds import read_only_kind

    named = read_only_kind(target.name)
    if named is not None and named[0] != kind:
        # An output named like one of the files the tool reads would replace a scene, a rig or
        # a radar's DBC that another run needs.
        raise RtsError(f"{option} {path}: named like {named[1]} ({named[0]}), which "
                       f"{option} would overwrite; give the output another name")
    # A path the system refuses to look at (a name too long) is named as not writable.
    with writing(option, path):
        if target.is_dir():
            raise RtsError(f"{option} {path}: cannot write: is a folder; give a file path")
        if str(path).endswith(("/", os.sep)):
            # pathlib drops the slash: "out.json/" would be written as the file out.json.
            raise RtsError(f"{option} {path}: names a folder (it ends in a slash); give a file "
                           f"path")
        parent = target.parent
        if not parent.is_dir():
            what = "is not a folder" if parent.exists() else "does not exist"
            raise RtsError(f"{option} {path}: cannot write: folder {parent} {what}")
        if target.is_symlink() and not target.exists():
            # A dangling link: the file it names is what gets written. Probe that one, and
            # leave the link in place.
            target = Path(os.path.realpath(target))
            if not target.parent.is_dir():
                raise RtsError(f"{option} {path}: cannot write: it links to {target}, whose "
                               f"folder does not exist")
        existed = target.exists()
        if existed and stat.S_ISFIFO(target.stat().st_mode):
            # A named pipe opened for writing waits for a reader: the probe would hang the
            # command before it starts. Permission is what can be checked (the writer waits
            # for the reader at the end, as a pipe does).
            if not os.access(target, os.W_OK):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
            return
        with open(target, "ab"):
            pass
        if not existed:
            target.unlink()
        if not in_place:
            check_draft(target)


def show_traceback(args: argparse.Namespace) -> None:
    """With ``--debug``, print the traceback of the exception being handled (and nothing else).

    The error line and the exit code stay those of a run without ``--debug``.
    """
    if getattr(args, "debug", False):
        traceback.print_exc()


def _same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file: the same path once resolved, or one file on disk."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links
    except OSError:
        return False


Paths = Iterable[tuple[str, str | Path | None]]


def is_standard_stream(path: str | Path) -> bool:
    """Whether ``path`` is this process's standard output or error.

    ``/dev/stdout``, and the file a shell redirected it to: what is written there goes to the
    stream's reader.
    """
    try:
        found = os.stat(path)
    except OSError:
        return False
    for fd in (1, 2):
        try:
            if os.path.samestat(found, os.fstat(fd)):
                return True
        except OSError:
            continue
    return False


def takes_placeholder(path: str | Path | None) -> bool:
    """Whether a report at ``path`` gets a placeholder until it is written.

    A regular file, or none yet; not a pipe, a device or the command's own output, which get
    the report alone.
    """
    if not path or is_standard_stream(path):
        return False
    return not os.path.exists(path) or os.path.isfile(path)


def same_as_any(path: str | Path, others: Iterable[str | Path | None]) -> bool:
    """Whether ``path`` names the same file as one of ``others`` (links followed)."""
    return any(other is not None and _same_file(path, other) for other in others)


def check_distinct_paths(outputs: Paths, inputs: Paths = ()) -> None:
    """Refuse, before anything is written, an output that would overwrite an input or output.

    ``outputs`` and ``inputs`` are ``(option, path)`` pairs (``None`` paths are skipped); the
    option names the argument in the message (``--json``, ``SCENE``, ...).
    """
    written = [(option, path) for option, path in outputs if path]
    read = [(option, path) for option, path in inputs if path]
    for i, (option, path) in enumerate(written):
        for source, source_path in read:
            if _same_file(path, source_path):
                raise RtsError(f"{option} {path}: the same file as {source} {source_path}, "
                               f"which this command reads; writing it would destroy the input; "
                               f"give {option} another file")
        for other, other_path in written[:i]:
            if _same_file(path, other_path):
                raise RtsError(f"{other} {other_path} and {option} {path}: the same file; one "
                               f"would overwrite the other; give each option its own file")


def read_by_scenes(scenes: Iterable[tuple[str | Path, dict[str, Any]]]
                   ) -> list[tuple[str, Path]]:
    """Return ``(label, file)`` for each file the scenes read (`scene_files`), once.

    For `check_distinct_paths`; ``scenes`` are ``(path, overrides)`` of every run.
    """
    from ..scenario import scene_files

    found: dict[Path, None] = {}
    loaded: set[tuple[str, str]] = set()
    for path, overrides in scenes:
        # Only what a variant sets under these keys changes the files it reads: one load per
        # scene and distinct such values, not one per variant (thousands in a sweep-like run).
        refs = {k: v for k, v in overrides.items() if k.split(".")[0] in _FILE_KEYS}
        key = (os.path.realpath(path), repr(sorted(refs.items())))
        if key in loaded:
            continue
        loaded.add(key)
        # The variant's whole values: the file as written may hold placeholders for them.
        found.update(dict.fromkeys(scene_files(path, overrides)))
    return [("the scene's", path) for path in found]


# The scene keys whose values name files the scene reads (its rig, radar profile, fragments).
_FILE_KEYS = ("rig", "radar", "include")


def check_rig_out(option: str, path: str) -> None:
    """Reject a rig file to write whose name does not end in ``.rig.yaml``."""
    if not path.endswith(".rig.yaml") and not Path(path).is_dir():  # a folder: say so
        raise RtsError(f"{option} {path}: a rig file's name ends in .rig.yaml")
    check_writable_file(option, path, ".rig.yaml")


# Suffixes of files, not folders, a folder option refuses where no such folder exists.
_FILE_SUFFIXES = frozenset({".png", ".svg", ".pdf", ".jpg", ".jpeg", ".json", ".csv", ".txt",
                            ".html", ".blf", ".asc", ".mf4", ".yaml", ".yml"})


def check_writable_folder(option: str, path: str | Path) -> None:
    """Fail now if the folder ``option`` names could not be written.

    The folder is made when missing, in a folder that exists (a mistyped parent is not made
    as a tree of new folders, as no file output makes one); a name with a file's suffix
    (``plots/run.png``) is refused, not made into a folder of that name.
    """
    if str(path) == "":
        raise RtsError(f"{option}: needs a folder path, got an empty one")
    folder = Path(path)
    with writing(option, path):
        exists = folder.exists()
    if not exists and folder.suffix.lower() in _FILE_SUFFIXES:
        raise RtsError(f"{option} {path}: names a file ({folder.suffix}); {option} takes the "
                       f"folder its .png files go into (made if missing)")
    probe = folder if exists else folder.parent
    with writing(option, path):
        is_dir, there = probe.is_dir(), probe.exists()
    if not is_dir:
        if probe == folder:
            raise RtsError(f"{option} {path}: cannot write: not a folder")
        what = "is a file" if there else "does not exist"
        raise RtsError(f"{option} {path}: cannot write: folder {probe} {what}")
    with writing(option, path):
        if not os.access(probe, os.W_OK | os.X_OK):
            raise PermissionError(13, "Permission denied")
        check_draft(probe)  # the files written in it are replaced whole


def check_number(option: str, value: float, *, low: float | None = None,
                 high: float | None = None) -> None:
    """Reject NaN, infinities and values outside ``low..high`` naming the option."""
    allowed = ("a finite number" if low is None and high is None
               else f"within {low:g}..{high:g}" if low is not None and high is not None
               else f">= {low:g}" if low is not None else f"<= {high:g}")
    if not math.isfinite(value) or (low is not None and value < low) or (
            high is not None and value > high):
        raise RtsError(f"{option}: must be {allowed}, got {value}")


def check_output(option: str, spec: str, *, run: bool) -> None:
    """Check an output spec before anything runs: a known name and a usable argument.

    ``run`` says whether the output is opened by a run (which provides the rig and radar the
    simulated radar needs, and needs a radar that answers: no file) or on its own
    (``schedule``).
    """
    from ..outputs import available_outputs, split_spec

    name, argument = split_spec(spec)
    valid = available_outputs()
    usage = ("simulated-radar, udp://HOST:PORT" if run
             else "udp://HOST:PORT, file:PATH (.npz or .csv)")
    if name not in valid:
        raise RtsError(f"{option} {spec!r}: unknown output {name!r}; valid outputs: "
                       f"{', '.join(valid)} (as {usage})")
    if name == "simulated-radar" and not run:
        raise RtsError(f"{option} {spec}: the simulated radar needs a run (rts-scenario run); "
                       f"a schedule goes to {usage}")
    if name == "simulated-radar" and argument:
        raise RtsError(f"{option} {spec!r}: simulated-radar takes no argument")
    if name == "file" and run:
        # A file output only writes the schedule to disk: no radar ever sees it.
        raise RtsError(f"{option} {spec}: a file output only stores the schedule, on disk: "
                       f"no radar sees it and nothing can be measured "
                       f"or checked; valid here: {usage} (or an installed RTS output); "
                       f"rts-scenario schedule SCENE --output {spec} exports a schedule")
    if name == "file":
        if not argument:
            raise RtsError(f"{option} {spec!r}: file needs a path: file:PATH (.npz or .csv)")
        if argument.endswith(("/", os.sep)):
            raise RtsError(f"{option} {spec}: names a folder (it ends in a slash); give a file "
                           f"path: file:PATH (.npz or .csv)")
        if Path(argument).suffix not in (".npz", ".csv"):
            raise RtsError(f"{option} {spec}: unknown file format "
                           f"{Path(argument).suffix or '(none)'!r}; valid: .npz, .csv")
        check_writable_file(option, argument)
    if name == "udp":
        from ..outputs import open_output

        try:
            open_output(spec).close()  # parses HOST:PORT and opens (then closes) a socket
        except RtsError as exc:
            raise RtsError(f"{option} {one_line(exc)}") from None


def named_file(option: str, load: Any, path: str) -> Any:
    """``load(path)`` with the option named in its error (a file an option names)."""
    try:
        return load(path)
    except RtsError as exc:
        raise RtsError(f"{option} {one_line(exc)}") from None


def preset_or_file(what: str, name: str, presets: list[str], preset: Any, from_file: Any,
                   suffix: str) -> Any:
    """Load a preset by name or a file by path; an unknown name lists both choices."""
    if name in presets:
        return preset(name)
    if not Path(name).is_file():
        raise RtsError(f"{what} {name!r}: unknown preset and no such file; valid presets: "
                       f"{', '.join(presets)}, or a *{suffix} file")
    return named_file(what, from_file, name)


# python-can's own default group of its udp_multicast interface.
UDP_MULTICAST_EXAMPLE = "239.74.163.2"


def check_can_interface(option: str, interface: str, channel: str | None = None,
                        channel_option: str = "--can-channel") -> None:
    """Reject an unknown python-can interface, and a udp_multicast channel not a multicast group.

    python-can would fail on such a channel with a name lookup error, and a private channel
    name would be heard by no other process. ``channel_option`` names the channel's option.
    """
    from can.interfaces import VALID_INTERFACES

    if interface not in VALID_INTERFACES:
        raise RtsError(f"{option} {interface!r}: unknown python-can interface; valid: "
                       f"{', '.join(sorted(VALID_INTERFACES))}")
    if interface != "udp_multicast":
        return
    need = (f"a multicast group address both processes join (e.g. {UDP_MULTICAST_EXAMPLE}, "
            f"python-can's default; IPv4 224.0.0.0/4 or IPv6 ff00::/8)")
    if channel is None:
        raise RtsError(f"{option} udp_multicast needs {channel_option}: {need}")
    try:
        multicast = ipaddress.ip_address(channel).is_multicast
    except ValueError:
        multicast = False
    if not multicast:
        raise RtsError(f"{channel_option} {channel!r}: udp_multicast needs {need}")


def check_can_opens(option: str, interface: str, channel: str | None, channel_option: str,
                    *, fd: bool = False) -> None:
    """Open the CAN interface a run will use once, and close it: one error before any run.

    A run opens it per scene (per variant of a parametrized one), so an interface this machine
    cannot open failed each of them in turn. Opening it and closing it again sends nothing;
    the ``virtual`` interface is left alone (a run's own bus, heard by no one else).
    """
    if interface == "virtual":
        return
    from ..canbus import open_bus
    from ..errors import BusError

    # Without a channel a run uses a private channel name (`Pipeline`): so does the check.
    name = channel if channel is not None else f"rts-scenario-{os.getpid():x}-detections"
    given = (f"{channel_option} {channel}" if channel is not None
             else f"(no {channel_option}: a private channel name)")
    try:
        bus = open_bus(interface, name, fd=fd)
    except BusError as exc:
        raise BusError(f"{option} {interface} {given}: {one_line(exc)}") from None
    bus.shutdown()


def check_readable_file(option: str, path: str) -> None:
    """Reject a path that is not a readable file."""
    if not Path(path).is_file():
        what = "is a folder" if Path(path).is_dir() else "file not found"
        raise RtsError(f"{option} {path}: {what}")


def add_bench_arguments(parser: argparse.ArgumentParser, radar_default: str) -> None:
    """Add the arguments of a command that drives a bench without a scene.

    Rig, radar, output, CAN (and the radar's DBC: ``--mapping``), and the simulated radar's
    fidelity and noise.
    """
    parser.add_argument("rig", metavar="RIG", help="rig preset or *.rig.yaml")
    parser.add_argument("--radar", default=radar_default,
                        help=f"radar profile (default {radar_default})")
    parser.add_argument("--output", default="simulated-radar",
                        help="simulated-radar (default) or udp://HOST:PORT")
    parser.add_argument("--can-interface", default="virtual")
    parser.add_argument("--can-channel", default=None)
    parser.add_argument("--can-fd", action="store_true", help="CAN FD detection messages")
    add_radar_channel_argument(parser, "a measurement")
    parser.add_argument("--mapping", default=None,
                        help="*.mapping.yaml for a third-party radar's DBC (the simulated "
                             "radar speaks it, the measurement reads it)")
    # None: not given (the simulated radar's analytic; refused with a real radar's output).
    parser.add_argument("--fidelity", default=None, choices=["analytic", "adc"],
                        help="the simulated radar's (default analytic)")
    parser.add_argument("--noise", action="store_true", help="thermal noise (simulated)")
    parser.add_argument("--estimator", default="bartlett",
                        help="the radar's angle estimator (the simulated radar's, and the one "
                             "the model reads with): bartlett (default), ti or an installed one")


def add_radar_channel_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """Add ``--radar-channel CH``: ``what`` reads only the radar's channel."""
    parser.add_argument("--radar-channel", default=None, metavar="CH",
                        help="on an interface listening on several channels, read only the "
                             "radar's (Message.channel as python-can gives it, e.g. 1 of a "
                             f"Vector interface given 0,1); without it, {what} hearing the "
                             "radar's identifiers on several channels fails")


def host_clock_lines(steps: list[dict[str, Any]]) -> list[str]:
    """Say each step of the host's clock during a command's measurements (`Pipeline.play`)."""
    return [f"host clock: the wall clock stepped {step['size_s'] * 1e3:+.1f} ms at "
            f"{step['at_s']:.3f} s after measurement {step['measurement']}'s start (within "
            f"{step['within_s'] * 1e3:.0f} ms before); corrected: {step['corrected']}"
            for step in steps]


def check_radar_channel(channel: str | None) -> None:
    """Reject an empty ``--radar-channel`` (bad input)."""
    if channel is not None and not channel.strip():
        raise RtsError(f"--radar-channel {channel!r}: empty; give the channel the radar's "
                       f"messages come on, as python-can gives it (Message.channel)")


def bench_of(args: argparse.Namespace, command: str = "a measurement",
             needs: tuple[str, ...] = ()) -> tuple[Any, Any]:
    """Check the bench arguments (`add_bench_arguments`); return ``(rig, radar profile)``.

    ``needs``: the quantities (`rts_scenario.canbus.mapping.QUANTITIES`) ``command`` reads of
    each detection; a ``--mapping`` whose detections do not carry one of them is refused.
    """
    from ..radar.angle import estimator_names, estimator_problem
    from ..radar.profile import RadarProfile
    from ..radar.profile import preset_names as radar_presets
    from ..rig import Rig
    from ..rig import preset_names as rig_presets

    if args.estimator not in estimator_names():
        raise RtsError(f"--estimator: unknown estimator {args.estimator!r}; valid: "
                       f"{', '.join(estimator_names())}")
    check_output("--output", args.output, run=True)
    if args.output != "simulated-radar" and (args.fidelity is not None or args.noise):
        # They would be taken and change nothing: the radar under test measures.
        which = "--fidelity" if args.fidelity is not None else "--noise"
        raise RtsError(f"{which}: an option of the built-in simulated radar; with --output "
                       f"{args.output} the radar on the bench measures (to rehearse, give it "
                       f"to `rts-scenario emulate`)")
    if args.fidelity is None:
        args.fidelity = "analytic"
    check_can_interface("--can-interface", args.can_interface, args.can_channel)
    check_radar_channel(args.radar_channel)
    if args.mapping is not None:
        from ..canbus.mapping import CanMapping

        mapping = named_file("--mapping", CanMapping.from_file, args.mapping)
        check_fd_mapping(args.can_fd, args.mapping, mapping)
        lacking = [q for q in needs if q not in mapping.quantities]
        if lacking:
            raise RtsError(f"--mapping {args.mapping}: the mapping {mapping.name!r} carries no "
                           f"{', '.join(lacking)}, which {command} measures (of each detection "
                           f"it needs: {', '.join(needs)})")
    rig = preset_or_file("RIG", args.rig, rig_presets(), Rig.preset, Rig.from_file,
                         ".rig.yaml")
    radar = preset_or_file("--radar", args.radar, radar_presets(), RadarProfile.preset,
                           RadarProfile.from_file, ".radar.yaml")
    if (problem := estimator_problem(args.estimator, radar.array)) is not None:
        raise RtsError(f"--estimator {args.estimator}: {problem}")
    return rig, radar


def check_bench_paths(args: argparse.Namespace, outputs: Paths) -> None:
    """`check_distinct_paths` for a bench command: its outputs against the files it reads.

    The rig and radar files, and the ``--mapping``.
    """
    check_distinct_paths(outputs, [("RIG", args.rig if Path(args.rig).is_file() else None),
                                   ("--radar", args.radar if Path(args.radar).is_file()
                                    else None),
                                   ("--mapping", args.mapping)])


def mapping_record(path: str | None) -> str | None:
    """Return the mapping a JSON records: its absolute path (as a run's sidecar), or None."""
    return str(Path(path).resolve()) if path else None


def check_fd_mapping(can_fd: bool, path: str | None, mapping: Any) -> None:
    """Refuse ``--can-fd`` with a mapping that has no CAN FD message (it would go unused)."""
    if can_fd and mapping is not None and mapping.fd_message is None:
        raise RtsError(f"--can-fd: the mapping {path} has no fd_message (the radar's CAN FD "
                       f"detection message) for --can-fd to use; add fd_message to the mapping "
                       f"or leave out --can-fd")
