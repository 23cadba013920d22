"""Objects by name: built-ins imported lazily, extended from an entry-point group.

The shape of python-can's interface registry: built-ins are ``"module:attr"`` strings and
plugins are entry points; `Registry.get` imports only the entry selected, so a missing optional
dependency fails only for the user who picks it, with a message naming it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from importlib import import_module
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from .errors import RtsError


class Registry:
    """Names of one kind of object (``"output"``, ``"angle estimator"``) and where they live.

    Parameters
    ----------
    kind : str
        What the names stand for; used in error messages (``unknown output 'x'; ...``).
    builtins : Mapping[str, str]
        Name to ``"module:attr"``; imported only by `get`. Built-ins win over plugins of the
        same name.
    entry_point_group : str, optional
        Entry-point group that installed packages extend the registry from.
    error : type of RtsError
        Raised for an unknown name or an entry that cannot be imported.
    plural : str, optional
        The kind in the plural (default: ``kind + "s"``).

    ``name in registry`` and iteration (over `names`) work as for a mapping of names.
    """

    def __init__(self, kind: str, builtins: Mapping[str, str], *,
                 entry_point_group: str | None = None,
                 error: type[RtsError] = RtsError, plural: str | None = None) -> None:
        for name, target in builtins.items():
            module, _, attr = target.partition(":")
            if not module or not attr:
                raise ValueError(f"built-in {kind} {name!r}: expected 'module:attr', "
                                 f"got {target!r}")
        self.kind = kind
        self.plural = plural or f"{kind}s"
        self.entry_point_group = entry_point_group
        self.error = error
        self._builtins = dict(builtins)

    def _plugins(self) -> dict[str, EntryPoint]:
        if self.entry_point_group is None:
            return {}
        return {ep.name: ep for ep in entry_points(group=self.entry_point_group)}

    def names(self) -> list[str]:
        """Every name: built-ins in their order, then installed plugins, sorted; imports nothing."""
        return [*self._builtins, *sorted(set(self._plugins()) - set(self._builtins))]

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and (name in self._builtins or name in self._plugins())

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def get(self, name: str) -> Any:
        """Import and return the object registered under ``name``.

        Raises
        ------
        RtsError
            Of the registry's ``error`` class: ``name`` is unknown (the message lists the valid
            names) or its entry cannot be imported (the message says why).
        """
        try:
            if name in self._builtins:
                module, attr = self._builtins[name].split(":")
                return getattr(import_module(module), attr)
            plugins = self._plugins()
            if name not in plugins:
                raise self.error(f"unknown {self.kind} {name!r}; valid {self.plural}: "
                                 f"{', '.join(self.names())}")
            return plugins[name].load()
        except (ImportError, AttributeError) as exc:
            raise self.error(f"{self.kind} {name!r} cannot be loaded: {exc}") from None
