"""Optional compiled kernels: the exact method per target in machine code (numba).

numba is the ``fast`` extra (``pip install "rts-scenario[fast]"``, also in ``dev``). Without it
every method runs its numpy code, which stays the reference: same weights to rounding, same
reasons (tests/test_solver_kernel.py). The kernel module is imported, and numba with it, only
when a solver first asks for it, so ``import rts_scenario`` stays cheap. Its machine code is
cached on disk by numba (``cache=True``: ``__pycache__`` beside the source, else numba's user
cache directory, else ``$NUMBA_CACHE_DIR``); where none of those can be written, the kernels are
compiled into a temporary directory for the process instead, so a read-only install never fails.

Set ``RTS_SCENARIO_JIT=off`` to run the numpy code even where numba is installed.
"""

from __future__ import annotations

import importlib
import os
import sys
import tempfile
import threading
from types import ModuleType
from typing import Any

# Environment variable that turns the compiled kernels off ("off", "0", "no" or "false").
JIT_ENV = "RTS_SCENARIO_JIT"
_KERNEL_MODULE = f"{__package__}._exact_kernel"
_LOCK = threading.Lock()
_loaded: list[ModuleType | None] = []


def enabled() -> bool:
    """Whether the compiled kernels may be used (``$RTS_SCENARIO_JIT`` is not off)."""
    return os.environ.get(JIT_ENV, "").strip().lower() not in ("off", "0", "no", "false")


def exact_kernel() -> ModuleType | None:
    """Return the exact method's compiled kernel module, or ``None`` (no numba, or off)."""
    if not enabled():
        return None
    if not _loaded:
        with _LOCK:
            if not _loaded:
                _loaded.append(_load())
    return _loaded[0]


def _load() -> ModuleType | None:
    try:
        import numba
    except ImportError:  # not installed, or a numba that does not support this numpy
        return None
    try:
        return importlib.import_module(_KERNEL_MODULE)
    except RuntimeError:
        # numba raises this when it finds no writable place for its cache: compile into a
        # directory of our own (no reuse across processes, but no failure).
        sys.modules.pop(_KERNEL_MODULE, None)
    try:
        config: Any = numba.config
        config.CACHE_DIR = tempfile.mkdtemp(prefix="rts-scenario-numba-")
        return importlib.import_module(_KERNEL_MODULE)
    except (RuntimeError, OSError):
        sys.modules.pop(_KERNEL_MODULE, None)
        return None


__all__ = ["JIT_ENV", "enabled", "exact_kernel"]
