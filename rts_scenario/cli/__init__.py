"""Command line: ``rts-scenario SUBCOMMAND ...``, one module per subcommand.

Each subcommand module has ``add_parser(subparsers)`` and a ``_do_<name>(args)`` handler that
imports the library only when it runs, so ``rts-scenario --help`` stays fast.

Exit codes: 0 success, 1 a check failed, 2 bad input. Errors print ``error: ...`` without a
traceback unless ``--debug`` is given.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ..errors import RtsError
from . import bench, calibrate, list_outputs, run, schedule, validate
from .common import EXIT_BAD_INPUT, EXIT_FAIL, EXIT_OK

# In the order `--help` lists them.
_SUBCOMMANDS = (bench, validate, run, schedule, calibrate, list_outputs)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="rts-scenario",
        description="Replay traffic scenes on a radar target simulator with 2-D angle of arrival.",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in _SUBCOMMANDS:
        module.add_parser(subparsers)
    return parser


__all__ = ["EXIT_BAD_INPUT", "EXIT_FAIL", "EXIT_OK", "build_parser", "main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.handler(args)
        return code
    except RtsError as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_FAIL


if __name__ == "__main__":
    sys.exit(main())
