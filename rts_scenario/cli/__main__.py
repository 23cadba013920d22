"""``python -m rts_scenario.cli``: the ``rts-scenario`` command."""

import sys

from . import main

sys.exit(main())
