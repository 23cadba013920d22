"""``python -m rts_scenario``: the ``rts-scenario`` command."""

from .cli import console

console()
