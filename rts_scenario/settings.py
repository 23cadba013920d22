"""Settings read from the environment, checked in one place (no heavy imports).

The command line checks every one of them once before anything runs; library code reads
them where they apply (`rts_scenario.solver.compiled.mode`), and both refuse a value they do
not know with a `SettingError`.
"""

from __future__ import annotations

import os

from .errors import SettingError

# Environment variable choosing when to use the compiled kernels: "auto" (default), "on", "off".
JIT_ENV = "RTS_SCENARIO_JIT"
_JIT_MODES = {"": "auto", "auto": "auto", "on": "on", "1": "on", "yes": "on", "true": "on",
              "off": "off", "0": "off", "no": "off", "false": "off"}


def jit_mode() -> str:
    """``$RTS_SCENARIO_JIT`` as one of "auto", "on", "off" (case and spaces aside).

    Unset or empty is "auto"; 1/yes/true are "on", 0/no/false "off". Any other value raises
    `SettingError` naming the variable, the value and the allowed values.
    """
    raw = os.environ.get(JIT_ENV, "")
    chosen = _JIT_MODES.get(raw.strip().lower())
    if chosen is None:
        raise SettingError(f"{JIT_ENV}={raw!r}: unknown value; allowed: auto, on, off (also "
                           "1/0, yes/no, true/false; unset or empty is auto)")
    return chosen


def check_environment() -> None:
    """Raise `SettingError` for the first environment setting whose value is not known."""
    jit_mode()


__all__ = ["JIT_ENV", "check_environment", "jit_mode"]
