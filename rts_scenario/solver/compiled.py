"""Optional compiled kernels: the exact method per target in machine code (numba).

numba is the ``fast`` extra (``pip install "rts-scenario[fast]"``, also in ``dev``). Without it
every method runs its numpy code, which stays the reference: same weights to rounding, same
reasons (tests/test_solver_kernel.py). The kernel module is imported, and numba with it, only
when a solver first asks for it, so ``import rts_scenario`` stays cheap. Its machine code is
cached on disk by numba (``cache=True``: ``__pycache__`` beside the source, else numba's user
cache directory; ``$NUMBA_CACHE_DIR`` first when set). Compiling takes several seconds, once;
where no cache location can be written the numpy code runs instead (set ``NUMBA_CACHE_DIR`` to
a writable directory to get the kernel there), so a read-only install never fails.

Set ``RTS_SCENARIO_JIT=off`` to run the numpy code even where numba is installed.
"""

from __future__ import annotations

import importlib
import os
import sys
import threading
from types import ModuleType

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
        import numba  # noqa: F401
    except ImportError:  # not installed, or a numba that does not support this numpy
        return None
    try:
        return importlib.import_module(_KERNEL_MODULE)
    except RuntimeError:
        # numba raises this when no cache location is writable. Compiling in every process
        # (seconds) would cost more than the kernel saves on most runs: use the numpy code.
        sys.modules.pop(_KERNEL_MODULE, None)
        return None


__all__ = ["JIT_ENV", "enabled", "exact_kernel"]
