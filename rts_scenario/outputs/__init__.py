"""Outputs for schedules, by name: built-ins plus plugins from an entry-point group.

A spec names the output and its target: ``file:PATH`` (``.npz`` or ``.csv``),
``udp://HOST:PORT``, ``simulated-radar`` (options: profile, rig, ...), or ``NAME[:ARGUMENT]``
for any registered output. Third-party RTS drivers
register an `Output` subclass in the ``rts_scenario.outputs`` entry-point group; it is imported
only when selected, so a missing driver fails only for the user who picks it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..errors import OutputError
from ..registry import Registry
from .base import Output

ENTRY_POINT_GROUP = "rts_scenario.outputs"

_REGISTRY = Registry(
    "output",
    {
        "file": "rts_scenario.outputs.file:FileOutput",
        "udp": "rts_scenario.outputs.udp:UdpOutput",
        "simulated-radar": "rts_scenario.outputs.radar:SimulatedRadarOutput",
    },
    entry_point_group=ENTRY_POINT_GROUP,
    error=OutputError,
)


def available_outputs() -> list[str]:
    """Names of every output: built-ins and installed plugins."""
    return _REGISTRY.names()


def output_class(name: str) -> type[Output]:
    """Return the `Output` subclass registered under ``name``."""
    cls = _REGISTRY.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Output)):
        raise OutputError(f"output {name!r} is not an rts_scenario Output subclass: {cls!r}")
    return cls


def split_spec(spec: str) -> tuple[str, str]:
    """Output name and argument of a spec: ``udp://HOST:PORT``, ``NAME:ARGUMENT`` or ``NAME``."""
    if spec.startswith("udp://"):
        return "udp", spec[len("udp://"):]
    name, _, argument = spec.partition(":")
    return name, argument


def open_output(spec: str, **options: Any) -> Output:
    """Create the output a spec names (see the module docstring); ``options`` go to it."""
    name, argument = split_spec(spec)
    factory: Callable[..., Output] = output_class(name)
    return factory(argument, **options) if argument else factory(**options)


__all__ = ["ENTRY_POINT_GROUP", "Output", "available_outputs", "open_output", "output_class",
           "split_spec"]
