"""``rts-scenario list-outputs``: the outputs a schedule can go to."""

from __future__ import annotations

import argparse
from typing import Any

from .common import EXIT_OK


def _do_list_outputs(args: argparse.Namespace) -> int:
    from ..outputs import available_outputs

    for name in available_outputs():
        print(name)
    return EXIT_OK


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``list-outputs`` subcommand."""
    parser = subparsers.add_parser("list-outputs", help="list the available outputs",
                                   parents=parents)
    parser.set_defaults(handler=_do_list_outputs)
