"""python-can's MF4 logs (asammdf) loaded where a MF4 log is used, not at start-up.

python-can loads asammdf when it is first imported, wherever asammdf is installed (the
``mf4`` extra), and asammdf loads pandas and sympy: about 0.7 s of every command's start-up,
for a log format few runs use. The ``rts-scenario`` command defers it (`defer`): python-can's
MF4 module is loaded as if asammdf were not installed, and loaded again with it (`ready`)
before a MF4 log is written or read. Elsewhere (the library, the pytest plugin) nothing
changes: a process that imports python-can itself gets its MF4 support as python-can loads it.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

# python-can's module that imports asammdf.
MODULE = "can.io.mf4"


class _WithoutAsammdf(importlib.abc.Loader):
    """Load a module with asammdf hidden: its ``import asammdf`` fails as if not installed."""

    def __init__(self, loader: importlib.abc.Loader) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        hidden = "asammdf" not in sys.modules
        if hidden:
            sys.modules["asammdf"] = None  # type: ignore[assignment]  # "import halted"
        try:
            self._loader.exec_module(module)
        finally:
            if hidden and sys.modules.get("asammdf", ...) is None:
                del sys.modules["asammdf"]


class _Deferring(importlib.abc.MetaPathFinder):
    """Find `MODULE` (once) with a loader that hides asammdf from it."""

    def find_spec(self, name: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if name != MODULE:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        spec.loader = _WithoutAsammdf(spec.loader)
        return spec


def defer() -> None:
    """Load python-can's MF4 module without asammdf when python-can is first imported.

    Does nothing where python-can is imported already (its MF4 support is as it loaded it).
    """
    if MODULE not in sys.modules and not any(isinstance(f, _Deferring) for f in sys.meta_path):
        sys.meta_path.insert(0, _Deferring())


def ready(path: str | Path) -> None:
    """Make python-can's MF4 reader and writer work before ``path`` (a ``.mf4`` log) is used.

    Where `defer` kept asammdf out, python-can's MF4 module is loaded again, now with it (if
    it is installed; if not, python-can says so when the log is opened). Its reader and writer
    classes, which python-can's `can.Logger` and `can.LogReader` hold, look asammdf up in
    the module when they run, so they find it.
    """
    if Path(path).suffix.lower() != ".mf4":
        return
    module = sys.modules.get(MODULE)
    if module is not None and getattr(module, "asammdf", None) is None \
            and importlib.util.find_spec("asammdf") is not None:
        importlib.reload(module)


__all__ = ["MODULE", "defer", "ready"]
