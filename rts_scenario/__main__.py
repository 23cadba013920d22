"""``python -m rts_scenario``: the ``rts-scenario`` command."""

import sys

from .cli import main

sys.exit(main())
