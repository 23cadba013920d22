"""Command line: ``rts-scenario SUBCOMMAND ...``, one module per subcommand.

Each subcommand module has ``add_parser(subparsers)`` and a ``_do_<name>(args)`` handler that
imports the library only when it runs, so ``rts-scenario --help`` stays fast.

Exit codes: 0 success, 1 a check failed, 2 bad input (arguments or files), 3 runtime error.
Errors print one ``error: ...`` line; ``--debug`` adds the traceback before it (the exit code
stays the same). SIGTERM stops a command as Ctrl-C does.
"""

from __future__ import annotations

import argparse
import atexit
import functools
import os
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType
from typing import Any, NoReturn, TextIO, cast

from .. import interrupts
from .._version import __version__
from ..errors import RtsError
from ..settings import check_environment
from . import (
    bench,
    calibrate,
    check,
    emulate,
    import_,
    list_outputs,
    list_scenes,
    listen,
    run,
    schedule,
    survey,
    sweep,
    validate,
)
from .common import (
    EXIT_BAD_INPUT,
    EXIT_FAIL,
    EXIT_OK,
    EXIT_RUNTIME_ERROR,
    check_writable_file,
    guarded_output,
    one_line,
    other_files,
    replace_unwritten_report,
    same_as_any,
    show_traceback,
)

# In the order `--help` lists them.
_SUBCOMMANDS = (bench, validate, run, sweep, check, schedule, calibrate, survey, emulate,
                import_, list_scenes, list_outputs, listen)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser, subcommands = _parser(_Parser)
    for sub in subcommands:
        for action in sub._actions:
            if action.nargs != 0 and action.type in (None, str) and action.choices is None:
                action.type = _not_empty
            if type(action) is argparse._StoreAction and action.option_strings:
                action.__class__ = _StoreOnce
    return parser


def _parser(parser_class: type[argparse.ArgumentParser]
            ) -> tuple[argparse.ArgumentParser, list[argparse.ArgumentParser]]:
    """Build the parser of ``parser_class`` with every subcommand; return it and theirs."""
    parser = parser_class(
        prog="rts-scenario",
        description="Replay traffic scenes on a radar target simulator with 2-D angle of arrival.",
        epilog="Exit codes: 0 pass, 1 a check failed, 2 bad input (arguments or files), "
               "3 runtime error.",
    )
    parser.add_argument("--version", action="version", version=f"rts-scenario {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    # `--debug` also after the subcommand; SUPPRESS keeps the top-level value when absent there.
    debug = argparse.ArgumentParser(add_help=False)
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show tracebacks on errors")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in _SUBCOMMANDS:
        module.add_parser(subparsers, [debug])
    for sub in subparsers.choices.values():
        # No option looks like a number: every negative number is a value.
        sub._negative_number_matcher = _NEGATIVE_NUMBER  # type: ignore[assignment]
    return parser, list(subparsers.choices.values())


class _UsageError(SystemExit):
    """argparse's exit on a usage error (its usage and error printed, exit 2), with the error."""

    def __init__(self, code: str | int | None, message: str) -> None:
        super().__init__(code)
        self.message = message


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage error says what it was (`_UsageError`)."""

    def error(self, message: str) -> NoReturn:
        try:
            super().error(message)
        except SystemExit as exc:
            raise _UsageError(exc.code, message) from None


class _Unreadable(Exception):
    """A command line that even `_read_leniently` cannot read (no command, say)."""


class _LenientParser(argparse.ArgumentParser):
    """A parser that raises `_Unreadable` on what it still refuses, printing nothing."""

    def error(self, message: str) -> NoReturn:
        raise _Unreadable(message)


class _Ignored(argparse.Action):
    """``--help`` and ``--version`` read past, not acted on (`_read_leniently`)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        pass


def _read_leniently(argv: Sequence[str]) -> tuple[argparse.Namespace, list[str]] | None:
    """Read a command line that argparse refused as far as it goes: the command, its files.

    Every option of a subcommand takes any value or none, none is required, an unknown one is
    left over and one given twice keeps its last value, so that an error elsewhere on the line
    does not hide ``--json PATH`` or the scenes. An abbreviated option (``--js``) is read as
    argparse reads it; where that is ambiguous, as an unknown one, and a flag given a value
    (``--can-fd=1``) as the flag. None where even so the line cannot be read (no command, an
    unknown one); else the arguments and those left over.
    """
    for abbreviations in (True, False):
        parser, subcommands = _parser(_LenientParser)
        flags: set[str] = set()
        for each in (parser, *subcommands):
            each.allow_abbrev = abbreviations
            for action in each._actions:
                if action.nargs == 0:
                    flags.update(action.option_strings)
                if type(action) in (argparse._HelpAction, argparse._VersionAction):
                    action.__class__ = _Ignored
                elif each is not parser:
                    action.type, action.choices, action.required = None, None, False
                    if action.option_strings and action.nargs is None:
                        action.nargs = "?"
        if not abbreviations:
            argv = [arg.partition("=")[0] if arg.partition("=")[0] in flags else arg
                    for arg in argv]
        try:
            return parser.parse_known_args(argv)
        except _Unreadable:
            continue
    return None


def _report_usage_error(argv: Sequence[str], message: str) -> None:
    """Write the ``--json`` report of a command line that argparse refused: no verdict.

    An earlier run's report left in place would be read as this one's. For a command that
    writes one (``run``, ``sweep``: its ``on_usage_error``), with argparse's error; not where
    ``--json`` itself is what is wrong, nor over a file the command line names for another
    option or one that `check_writable_file` refuses (a scene's name): the usage error stands.
    """
    if message.startswith("argument --json:"):
        return
    read = _read_leniently(argv)
    if read is None:
        return
    args, left_over = read
    path = getattr(args, "json", None)
    if path and _replaceable_report(path):
        _report_stop(args, message, left_over)


def _report_stop(args: argparse.Namespace, message: str,
                 also_named: Sequence[str] = ()) -> None:
    """Write the ``--json`` report of a command stopped before it ran (its ``on_usage_error``).

    Not over a file the command line names for another option (or ``also_named``), nor one
    `check_writable_file` refuses: the checks that refuse those have not run yet.
    """
    report = getattr(args, "on_usage_error", None)
    path = getattr(args, "json", None)
    if report is None or not path or same_as_any(path, [*other_files(args), *also_named]):
        return
    try:
        check_writable_file("--json", path)
        report(args, message)
    except RtsError:
        pass  # the stop is the command's outcome, said above


def _replaceable_report(path: str) -> bool:
    """Whether ``path`` may take a refused command line's report: absent, or a report already.

    A line argparse refused may be read wrongly (``run --json scene.yaml`` without a scene puts
    the scene where ``--json`` goes): only an earlier report, or no file, is written over.
    """
    import json

    try:
        with open(path, "rb") as f:
            text = f.read(MAX_REPORT_BYTES + 1)
    except FileNotFoundError:
        return True
    except OSError:
        return False
    if len(text) > MAX_REPORT_BYTES:
        return False
    try:
        data = json.loads(text)
    except ValueError:
        return False
    # A report of `run` (an entry, or a list of them) or of `sweep`; not a scene written as
    # JSON, nor a recording's sidecar.
    entries = data if isinstance(data, list) else [data]
    return bool(entries) and all(isinstance(e, dict) and ("status" in e or "runs" in e)
                                 for e in entries)


# The largest file a refused command line's report replaces (`_replaceable_report`).
MAX_REPORT_BYTES = 64 << 20


class _StoreOnce(argparse._StoreAction):
    """An option that takes one value, refused when given twice.

    argparse keeps the last: ``--json a.json --json b.json`` wrote only ``b.json``, and the
    report the user asked for first was never written, without a word.
    """

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        given: dict[str, Any] = namespace.__dict__.setdefault("_rts_given", {})
        if self.dest in given:
            parser.error(f"argument {'/'.join(self.option_strings)}: given twice "
                         f"({given[self.dest]!r}, then {values!r}); give it once")
        given[self.dest] = values
        super().__call__(parser, namespace, values, option_string)


class _NegativeNumber:
    """What argparse takes for a negative number, a value rather than an option.

    argparse's own pattern (``-5``, ``-.5``) left out ``-inf``, ``-nan`` and ``-1e3``, so
    ``--time-offset-s -inf`` read as an option and failed with "expected one argument"
    instead of the option's own check. Here anything ``float()`` reads is a number.
    """

    @staticmethod
    def match(text: str) -> bool:
        if not text.startswith("-"):
            return False
        try:
            float(text)
        except ValueError:
            return False
        return True


_NEGATIVE_NUMBER = _NegativeNumber()


def _not_empty(value: str) -> str:
    """Refuse an empty argument: an unset shell variable is not an option left out.

    Taken as absent, ``--json ""`` wrote no report and ``sweep ""`` swept the current folder.
    """
    if not value:
        raise argparse.ArgumentTypeError("an empty value; give one, or leave the option out")
    return value


__all__ = ["EXIT_BAD_INPUT", "EXIT_FAIL", "EXIT_OK", "EXIT_RUNTIME_ERROR", "build_parser",
           "console", "main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        # Ctrl-C, or a SIGTERM while the command's handler was being put back: the command
        # itself handles both while it runs (`_handle`), this is the few instructions around it.
        try:
            print("error: interrupted", file=sys.stderr)
        except (OSError, KeyboardInterrupt):
            pass  # the exit code says it
        return EXIT_FAIL


def console() -> NoReturn:
    """Run the ``rts-scenario`` command: `main`, then exit with its code.

    Ctrl-C or SIGTERM after the command has printed all it prints, while the process exits,
    used to kill it by its signal without a word. While Python still waits for threads and
    runs its exit hooks (where a stuck thread would hang), either stops the command as one
    that ended then does (`_main`): ``error: interrupted`` and exit 1 (or the command's own
    2 or 3), what was printed and written standing. The exit hooks not run yet are skipped:
    the command has closed what it writes (its files, its pools) before `main` returns. The
    last hook ignores them: tearing the modules down (a few tenths of a second) runs with no
    signal handlers of Python's, and a signal would kill it, while the command has ended and
    nothing of its is left to stop. A SIGTERM between the command's handler put back and
    these is noted, and acted on once they are in place.
    """
    from ..mf4 import defer
    from ..startup import mark_command_process

    defer()  # python-can's MF4 support loads with a MF4 log, not at start-up (0.7 s)
    mark_command_process()  # its imports with the collector paused (`command_imports`)
    main_thread = threading.current_thread() is threading.main_thread()
    noted: list[int] = []
    if main_thread:
        atexit.register(_ignore_stops)  # registered first: run last
        # What `_main` puts back when the command ends.
        signal.signal(signal.SIGTERM, lambda signum, frame: noted.append(signum))
    code = EXIT_FAIL
    try:
        code = main()
        if main_thread:
            signal.signal(signal.SIGINT, functools.partial(_stopped_at_exit, code))
            signal.signal(signal.SIGTERM, functools.partial(_stopped_at_exit, code))
    except KeyboardInterrupt:  # in the instants after `main` returned, before the above
        _stopped_at_exit(code, signal.SIGINT, None)
    if noted:
        _stopped_at_exit(code, noted[0], None)
    sys.exit(code)


def _stopped_at_exit(code: int, signum: int, frame: object) -> NoReturn:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    try:
        print("error: interrupted", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass  # the exit code says it
    # Never 0; a bad input's or a runtime error's code stands.
    os._exit(code if code != EXIT_OK else EXIT_FAIL)


def _ignore_stops() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        _report_usage_error(sys.argv[1:] if argv is None else argv, exc.message)
        raise
    try:
        # Settings the environment gives are checked once, before anything runs.
        check_environment()
    except RtsError as exc:
        print(f"error: {one_line(exc)}", file=sys.stderr)
        _report_stop(args, one_line(exc))
        return EXIT_BAD_INPUT
    if sys.stdout is None:
        # Started with its standard output closed (``>&-``): Python drops what is printed to
        # it without a word, the verdict with it.
        if sys.stderr is not None:
            print("error: standard output is closed: what the command prints (its verdict "
                  "among it) would be lost; give it a file, or /dev/null to discard it",
                  file=sys.stderr)
        return EXIT_BAD_INPUT
    stdout, stderr = sys.stdout, sys.stderr
    out_guard, err_guard = guarded_output(stdout), guarded_output(stderr)
    if out_guard is not None:
        sys.stdout = cast(TextIO, out_guard)
    if err_guard is not None:
        sys.stderr = cast(TextIO, err_guard)
    sigterm = _SigtermAsInterrupt()
    interrupts.reset()
    try:
        sigterm.install()
        code = _handle(args)
    finally:
        sigterm.armed = False  # first: a plain store, no point for a signal to come in
        sigterm.uninstall()
        swallowed = interrupts.swallowed()
        interrupts.reset()  # the command has ended: nothing after it is stopped by its stops
        if out_guard is not None:
            out_guard.restore()
            sys.stdout = stdout
        if err_guard is not None:
            err_guard.restore()
            sys.stderr = stderr
    lost = [(name, getattr(guard, "lost", None))
            for name, guard in (("standard output", out_guard), ("standard error", err_guard))]
    if any(error is not None for _, error in lost):
        # What was printed (a verdict among it) went nowhere: never the verdict's exit code.
        for name, error in lost:
            if error is not None:
                try:
                    print(f"error: {name}: {one_line(error)}: what the command printed is lost",
                          file=sys.stderr)
                except OSError:
                    pass  # standard error itself is lost: the exit code is all that is left
        return EXIT_RUNTIME_ERROR
    if sigterm.late or swallowed:
        # Stopped as the command ended, or stopped while a library it called caught the
        # interrupt (it ran on to its end): what it printed stands, its exit code says stopped.
        print("error: interrupted", file=sys.stderr)
        return code if code not in (EXIT_OK, EXIT_FAIL) else EXIT_FAIL
    return code


class _SigtermAsInterrupt:
    """SIGTERM as Ctrl-C (`KeyboardInterrupt`) while a command runs.

    A CI job's timeout, ``kill`` or a container's stop sends SIGTERM: its default killed the
    command on the spot, leaving a report half written or not at all and no verdict. Handled as
    Ctrl-C, a command keeps what finished and exits with Ctrl-C's exit code. Once the command
    has ended (``armed`` false) a SIGTERM is only noted (``late``): raised while the handler is
    put back and the output restored, it would end in a traceback. Nothing is set outside the
    main thread, where no handler can be.
    """

    def __init__(self) -> None:
        self.armed = True
        self.late = False
        self.previous: Any = None  # the handler replaced, once installed
        self.previous_int: Any = None  # SIGINT's, where Python's own was replaced

    def __call__(self, signum: int, frame: object) -> None:
        if self.armed:
            interrupts.note()  # should a library swallow the interrupt
            raise KeyboardInterrupt
        self.late = True

    def install(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        found = signal.getsignal(signal.SIGTERM)
        # None: a handler set outside Python, which cannot be put back; the default is its
        # nearest.
        self.previous = signal.SIG_DFL if found is None else found
        signal.signal(signal.SIGTERM, self)
        # Ctrl-C as Python's own handler takes it (`KeyboardInterrupt`), noted as well. Where
        # something else handles SIGINT (a test, an embedding program), it is left to it.
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self.previous_int = signal.default_int_handler
            signal.signal(signal.SIGINT, self._interrupt)

    def _interrupt(self, signum: int, frame: FrameType | None) -> None:
        if self.armed:
            interrupts.note()
        signal.default_int_handler(signum, frame)

    def uninstall(self) -> None:
        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
            self.previous = None
        if self.previous_int is not None:
            signal.signal(signal.SIGINT, self.previous_int)
            self.previous_int = None


def _handle(args: argparse.Namespace) -> int:
    try:
        code: int = args.handler(args)
        return code
    except RtsError as exc:
        show_traceback(args)
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        interrupts.handled()
        replace_unwritten_report(args)
        print("error: interrupted", file=sys.stderr)
        return EXIT_FAIL
    except Exception as exc:
        show_traceback(args)
        hint = "" if args.debug else "; --debug shows the traceback"
        print(f"error: {type(exc).__name__}: {one_line(exc)} (a runtime error{hint})",
              file=sys.stderr)
        return EXIT_RUNTIME_ERROR


if __name__ == "__main__":
    sys.exit(main())
