"""Optional compiled kernels: the exact method per target in machine code (numba).

numba is the ``fast`` extra (``pip install "rts-scenario[fast]"``, also in ``dev``). Without it
every method runs its numpy code, which stays the reference: same weights to rounding, same
reasons (tests/test_solver_kernel.py). The kernel module is imported, and numba with it, only
when a solver first asks for it, so ``import rts_scenario`` stays cheap. Its machine code is
cached on disk by numba (``cache=True``: ``__pycache__`` beside the source, else numba's user
cache directory; ``$NUMBA_CACHE_DIR`` first when set). Compiling takes several seconds, once;
where no cache location can be written the numpy code runs instead (set ``NUMBA_CACHE_DIR`` to
a writable directory to get the kernel there), so a read-only install never fails.

Loading numba and the cached kernel takes about half a second, what the numpy code needs for
about a million targets, so by default (``RTS_SCENARIO_JIT=auto``) a process loads the kernel
only once it has solved `LOAD_AFTER_TARGETS` targets: a scene of a few thousand target-frames
never pays for it, a sweep over millions soon does. ``RTS_SCENARIO_JIT=on`` loads it at the
first solve, ``off`` never. Any other value is refused (`SettingError`) wherever it is read:
a typo would otherwise change when the kernel loads without a word.
"""

from __future__ import annotations

import importlib
import sys
import threading
from types import ModuleType

from ..settings import JIT_ENV, jit_mode

# With "auto", targets a process solves with the numpy code before it loads the kernel.
LOAD_AFTER_TARGETS = 1_000_000
_KERNEL_MODULE = f"{__package__}._exact_kernel"
_LOCK = threading.Lock()
_loaded: list[ModuleType | None] = []
_solved_targets = [0]


def mode() -> str:
    """``$RTS_SCENARIO_JIT`` as one of "auto", "on", "off" (`rts_scenario.settings.jit_mode`).

    Unset or empty is "auto"; 1/yes/true are "on", 0/no/false "off". Any other value raises
    `SettingError` naming the variable, the value and the allowed values.
    """
    return jit_mode()


def exact_kernel(n_targets: int | None = None) -> ModuleType | None:
    """Return the exact method's compiled kernel module for a solve, or ``None`` (numpy).

    ``n_targets``: the solve's size, counted towards `LOAD_AFTER_TARGETS` in "auto" mode
    (0: the kernel if it is loaded already); ``None`` asks for the kernel now (loading it
    unless turned off). ``None`` is returned
    where numba is missing, turned off, or has nowhere to cache the kernel.
    """
    chosen = mode()
    if chosen == "off":
        return None
    if not _loaded:
        if n_targets is not None and chosen == "auto":
            _solved_targets[0] += n_targets
            if _solved_targets[0] < LOAD_AFTER_TARGETS:
                return None
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


__all__ = ["JIT_ENV", "LOAD_AFTER_TARGETS", "exact_kernel", "mode"]
