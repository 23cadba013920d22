"""Import OpenSCENARIO 1.x files as scene files: a documented subset without a road network.

The storyboard is played forward in time the way a simulator would, but only as far as the
scene format needs it: every entity moves along a straight line (its Init heading) with a
piecewise-linear speed over time plus lateral shifts (the format's quintic lane changes).
Events start in time order; a condition on a distance is solved on the motion already known up
to that time, which no later event can change. The ego is written as the scene's ego (the radar
carrier), every other entity as a target in world coordinates, so the kinematics computes the
tracks relative to the moving radar.

Nothing is dropped silently: every element and attribute the import does not read is an error
naming it and its line, and every approximation is a note in the output's header. The subset
and its mapping are documented in ``docs/import.md``.
"""

from __future__ import annotations

import ast
import copy
import math
import operator
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.optimize import brentq

from .errors import RtsError, ScenarioError
from .scenario.loader import (
    FRAME_SLACK,
    LANE_CHANGE_PEAK,
    MAX_ACCELERATION_MPS2,
    lane_change_seconds,
)
from .scenario.trajectory import LaneChange, Trajectory, TrajectorySet, TravelLaw
from .scenario.trajectory import Path as TrajectoryPath

MAX_FILE_BYTES = 16 * 1024 * 1024
# The deepest nesting of elements libxml's parser takes without its huge-tree option.
MAX_XML_DEPTH = 256
# An XML Schema double (Python's float() also reads "1_0" and other digits than 0-9).
_DOUBLE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
XSI_NAMESPACE = "http://www.w3.org/2001/XMLSchema-instance"
DEFAULT_FRAME_RATE_HZ = 20.0
DEFAULT_LANE_WIDTH_M = 3.5
# A step transition is played as a linear ramp centred on its start time (positions after it
# are exact, speeds differ only inside it): at the scene format's greatest acceleration, and at
# least this long.
STEP_S = 1e-3
# Cubic and sinusoidal speed transitions become linear pieces within this speed error.
SPEED_TOLERANCE_MPS = 2e-3
MAX_SHAPE_PIECES = 200
# Conditions on distances are searched on this time grid, then solved to XTOL_S.
SEARCH_STEP_S = 0.01
SEARCH_HORIZON_S = 3600.0
XTOL_S = 1e-9
# Radar mount when the ego has no bounding box: the shipped scenes' front-bumper radar.
DEFAULT_MOUNT_X_M = 3.7
MOUNT_HEIGHT_M = 0.5
# The scene format's lane change is a quintic ramp: its peak slope and jerk for a unit offset
# over a unit time (its peak acceleration: `scenario.loader.LANE_CHANGE_PEAK`).
QUINTIC_PEAK_SLOPE = 15.0 / 8.0
QUINTIC_PEAK_JERK = 60.0

# Transition shapes over u in [0, 1]: value, peak slope, peak |second derivative|.
_SHAPES: dict[str, tuple[Callable[[float], float], float, float]] = {
    "linear": (lambda u: u, 1.0, 0.0),
    "cubic": (lambda u: u * u * (3.0 - 2.0 * u), 1.5, 6.0),
    "sinusoidal": (lambda u: 0.5 - 0.5 * math.cos(math.pi * u), math.pi / 2, math.pi**2 / 2),
}
SHAPES = ("step", *_SHAPES)
DIMENSIONS = ("time", "rate", "distance")

VEHICLE_KINDS = {"car": "car", "van": "car", "truck": "truck", "trailer": "truck",
                 "semitrailer": "truck", "bus": "truck", "train": "truck", "tram": "truck",
                 "motorbike": "motorcycle", "bicycle": "bicycle"}
PEDESTRIAN_KINDS = {"pedestrian": "pedestrian", "wheelchair": "pedestrian", "animal": "other"}
# Categories whose RCS model is not their kind's (docs/import.md): an animal is of kind
# "other", with the pedestrian's model, not the 10 dBsm constant of other objects.
RCS_MODEL_OF_CATEGORY = {"animal": "pedestrian"}
MISC_KINDS = {**dict.fromkeys(("barrier", "guardRail", "railing", "soundBarrier", "wall"),
                              "barrier"),
              **dict.fromkeys(("gantry", "pole", "streetLamp", "trafficSign"), "sign"),
              **dict.fromkeys(("none", "obstacle", "building", "crosswalk", "parkingSpace",
                               "patch", "roadMark", "trafficIsland", "tree", "vegetation",
                               "wind"), "other")}

# RCS models by kind, taken from the shipped scenes (named after each); see docs/import.md.
RCS_MODELS: dict[str, dict[str, Any]] = {
    # gantry_stopped_car: a car's aspect table
    "car": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [12, 18, 10, 18]},
    # highway_following: a truck's aspect table
    "truck": {"aspect_deg": [0, 45, 90, 135, 180, 225, 270, 315],
              "rcs_dbsm": [20, 15, 25, 15, 22, 15, 25, 15]},
    # motorcycle: a weak, fluctuating two-wheeler (also used for bicycles: no bicycle model ships)
    "motorcycle": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [0, 5, 1, 5],
                   "fluctuation": "swerling3"},
    "bicycle": {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [0, 5, 1, 5],
                "fluctuation": "swerling3"},
    # pedestrian_crossing
    "pedestrian": {"rcs_dbsm": -8.0, "fluctuation": "swerling1"},
    # gantry_stopped_car's sign, also for barriers
    "sign": {"rcs_dbsm": 18.0},
    "barrier": {"rcs_dbsm": 18.0},
    # the shipped scenes' usual constant
    "other": {"rcs_dbsm": 10.0},
}
# Target height above its reference point without a bounding box (as in the shipped scenes).
DEFAULT_HEIGHT_M = {"car": 0.6, "truck": 1.2, "motorcycle": 0.8, "bicycle": 0.8,
                    "pedestrian": 1.0}

SUPPORTED_ACTIONS = ("TeleportAction (Init only)", "SpeedAction", "LaneChangeAction",
                     "LaneOffsetAction", "LateralDistanceAction")
SUPPORTED_CONDITIONS = ("SimulationTimeCondition", "RelativeDistanceCondition",
                        "StoryboardElementStateCondition")
SUPPORTED_POSITIONS = ("WorldPosition", "RelativeWorldPosition", "RelativeObjectPosition")
_RULES = {"greaterThan": operator.gt, "greaterOrEqual": operator.ge, "lessThan": operator.lt,
          "lessOrEqual": operator.le, "equalTo": operator.eq, "notEqualTo": operator.ne}


# ----------------------------------------------------------------------------------- elements

class _El:
    """An XML element after parameter substitution that remembers what the import read."""

    def __init__(self, file: str, raw: Any, parent: _El | None) -> None:
        self.file = file
        self.tag = raw.tag.rsplit("}", 1)[-1]
        self.line: int | None = raw.sourceline
        self.parent = parent
        self.attrs: dict[str, str] = {}
        for key, value in raw.attrib.items():
            if key.startswith("{"):  # another namespace: only the schema's hints are known
                uri, local = key[1:].split("}", 1)
                if uri == XSI_NAMESPACE:
                    continue
                prefix = next((p for p, u in (raw.nsmap or {}).items() if u == uri and p), None)
                key = f"{prefix}:{local}" if prefix else key
            self.attrs[key] = value
        # OpenSCENARIO gives every value as an attribute: text in an element is not read.
        self.content = " ".join(filter(None, [(raw.text or "").strip(),
                                              *((c.tail or "").strip() for c in raw)]))
        self.children = [_El(file, c, self) for c in raw if isinstance(c.tag, str)]
        self.used = False
        self.skipped = False
        self.read: set[str] = set()
        self.known: set[str] = set()  # attributes the import looks for, for the messages
        self.asked: set[str] = set()  # children the import looks for, for the messages

    def error(self, message: str) -> ScenarioError:
        return ScenarioError(message, file=self.file, line=self.line)

    def text(self, name: str, default: str | None = None) -> str:
        self.read.add(name)
        self.known.add(name)
        value = self.attrs.get(name, default)
        if value is None:
            raise self.error(f"<{self.tag}> needs the attribute {name}")
        return value

    def has(self, name: str) -> bool:
        self.known.add(name)
        return name in self.attrs

    def number(self, name: str, default: float | None = None) -> float:
        raw = self.text(name, None if default is None else repr(default))
        text = raw.strip()
        if not _DOUBLE.fullmatch(text):
            if text.lstrip("+-").lower() in ("inf", "infinity", "nan"):
                raise self.error(f"<{self.tag} {name}=\"{raw}\">: must be a finite number")
            raise self.error(f"<{self.tag} {name}=\"{raw}\">: must be a number")
        value = float(text)
        if not math.isfinite(value):  # beyond a double's range
            raise self.error(f"<{self.tag} {name}=\"{raw}\">: must be a finite number")
        return value

    def boolean(self, name: str, default: bool) -> bool:
        raw = self.text(name, "true" if default else "false")
        if raw not in ("true", "false", "1", "0"):
            raise self.error(f"<{self.tag} {name}=\"{raw}\">: must be true or false")
        return raw in ("true", "1")

    def choice(self, name: str, allowed: tuple[str, ...], default: str | None = None) -> str:
        value = self.text(name, default)
        if value not in allowed:
            raise self.error(f"<{self.tag} {name}=\"{value}\"> is not supported by import; "
                             f"supported: {', '.join(allowed)} (at {self.path()})")
        return value

    def kids(self, *names: str) -> list[_El]:
        self.asked.update(names)
        out = [c for c in self.children if c.tag in names]
        for c in out:
            c.used = True
        return out

    def child(self, name: str, required: bool = True) -> _El | None:
        found = self.kids(name)
        if len(found) > 1:
            raise found[1].error(f"<{self.tag}> has more than one <{name}>")
        if not found and required:
            raise self.error(f"<{self.tag}> needs a <{name}> element")
        return found[0] if found else None

    def need(self, name: str) -> _El:
        found = self.child(name)
        assert found is not None
        return found

    def pick(self, what: str, supported: tuple[str, ...], listed: tuple[str, ...] = ()) -> _El:
        """Return the element's one child, which must be among ``supported``."""
        if len(self.children) != 1:
            raise self.error(f"<{self.tag}> needs exactly one child element, got "
                             f"{len(self.children)}")
        c = self.children[0]
        self.asked.update(supported)
        if c.tag not in supported:
            raise c.error(f"<{c.tag}> is not supported by import; supported {what}: "
                          f"{', '.join(listed or supported)} (at {c.path()})")
        c.used = True
        return c

    def skip(self) -> None:
        """Mark the whole subtree as read: it does not change the scene."""
        self.used = self.skipped = True
        self.read |= set(self.attrs)
        for c in self.children:
            c.skip()

    def empty(self, why: str = "") -> None:
        """Refuse children: a declaration the import cannot use must stay empty (``why``)."""
        self.used = True
        if self.children:
            c = self.children[0]
            raise c.error(f"<{c.tag}> in <{self.tag}> is not supported by import"
                          f"{'; ' + why if why else ''} (at {c.path()})")

    def path(self) -> str:
        """Return the element's tags from below the root, e.g. ``Storyboard/Init/Actions``."""
        parts, el = [], self
        while el.parent is not None:
            parts.append(el.tag)
            el = el.parent
        return "/".join(reversed(parts)) or self.tag

    def walk(self) -> list[_El]:
        out = [self]
        for c in self.children:
            out += c.walk()
        return out


def _check_all_read(root: _El) -> None:
    for el in root.walk():
        if not el.used:
            assert el.parent is not None  # the root is always read
            supported = ", ".join(sorted(el.parent.asked)) or "nothing"
            raise el.error(f"<{el.tag}> in <{el.parent.tag}> is not supported by import; "
                           f"supported in <{el.parent.tag}>: {supported} (at {el.path()})")
        unread = [a for a in el.attrs if a not in el.read]
        if unread:
            supported = ", ".join(sorted(el.known)) or "none"
            raise el.error(f"<{el.tag} {unread[0]}=\"{el.attrs[unread[0]]}\">: attribute "
                           f"{unread[0]} is not supported by import; supported: {supported} "
                           f"(at {el.path()})")
        if el.content and not el.skipped:
            raise el.error(f"<{el.tag}> contains text ({el.content[:40]!r}): OpenSCENARIO "
                           f"gives values as attributes, text is not read by import (at "
                           f"{el.path()})")


# --------------------------------------------------------------------------------- parameters

@dataclass
class Parameter:
    """A declared parameter: its type, the value used and where that value came from."""

    name: str
    type: str
    value: str
    source: str  # "declared" or "--param"
    line: int | None = None  # of the declaration


_PARAM_REF = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_BINARY: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
    ast.Div: operator.truediv, ast.Mod: operator.mod}
_COMPARE: dict[type, Callable[[Any, Any], Any]] = {
    ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
    ast.Eq: operator.eq, ast.NotEq: operator.ne}
_FUNCTIONS: dict[str, Callable[..., Any]] = {
    "round": round, "floor": math.floor, "ceil": math.ceil, "sqrt": math.sqrt, "pow": math.pow}


def _number(text: str) -> float | int | bool:
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        return float(text)


def _evaluate(expression: str, params: dict[str, Parameter]) -> str:
    """Evaluate an OpenSCENARIO 1.1 expression (``${...}``): arithmetic, comparisons, logic."""
    def value(node: ast.AST) -> Any:
        if isinstance(node, ast.Expression):
            return value(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in ("true", "false"):
                return node.id == "true"
            if node.id not in params:
                raise ValueError(f"unknown parameter ${node.id}")
            try:
                return _number(params[node.id].value)
            except ValueError:
                raise ValueError(f"${node.id} = {params[node.id].value!r} is not a number") \
                    from None
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return _BINARY[type(node.op)](value(node.left), value(node.right))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd | ast.Not):
            operand = value(node.operand)
            return (-operand if isinstance(node.op, ast.USub) else
                    operand if isinstance(node.op, ast.UAdd) else not operand)
        if isinstance(node, ast.BoolOp):
            values = [bool(value(v)) for v in node.values]
            return all(values) if isinstance(node.op, ast.And) else any(values)
        if (isinstance(node, ast.Compare) and len(node.ops) == 1
                and type(node.ops[0]) in _COMPARE):
            return _COMPARE[type(node.ops[0])](value(node.left), value(node.comparators[0]))
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in _FUNCTIONS and not node.keywords):
            return _FUNCTIONS[node.func.id](*(value(a) for a in node.args))
        raise ValueError("only numbers, $parameters, + - * / %, comparisons, and/or/not and "
                         f"{', '.join(_FUNCTIONS)}() are supported")

    try:
        result = value(ast.parse(_PARAM_REF.sub(r"\1", expression).strip(), mode="eval"))
    except SyntaxError:
        raise ValueError("not a valid expression") from None
    except (RecursionError, MemoryError):  # MemoryError: CPython's parser, deeper still
        raise ValueError("expression nested too deeply") from None
    except (ZeroDivisionError, OverflowError, TypeError, ValueError) as exc:
        raise ValueError(str(exc) or type(exc).__name__) from None
    if isinstance(result, bool):
        return "true" if result else "false"
    return repr(result) if isinstance(result, float) else str(result)


def _substitute(raw_root: Any, file: str, params: dict[str, Parameter]) -> None:
    """Replace ``$name`` and ``${expression}`` attribute values in place."""
    for raw in raw_root.iter():
        if not isinstance(raw.tag, str):
            continue
        for key, text in raw.attrib.items():
            if not text.startswith("$"):
                continue
            where = f"<{raw.tag.rsplit('}', 1)[-1]} {key}=\"{text}\">"
            if text.startswith("${") and text.endswith("}"):
                try:
                    raw.attrib[key] = _evaluate(text[2:-1], params)
                except ValueError as exc:
                    raise ScenarioError(f"{where}: {exc}", file=file,
                                        line=raw.sourceline) from None
                continue
            name = text[1:]
            if name not in params:
                declared = ", ".join(params) or "none"
                raise ScenarioError(f"{where}: unknown parameter ${name}; declared: "
                                    f"{declared}", file=file, line=raw.sourceline)
            raw.attrib[key] = params[name].value


_PARAMETER_TYPES = ("double", "integer", "unsignedInt", "unsignedShort", "string", "boolean",
                    "dateTime")


# OpenSCENARIO's integer types and their ranges (XML Schema's int, unsignedInt, unsignedShort).
_INTEGER_RANGES = {"integer": (-(2**31), 2**31 - 1), "unsignedInt": (0, 2**32 - 1),
                   "unsignedShort": (0, 2**16 - 1)}


def _check_type(name: str, kind: str, value: str) -> str | None:
    """Return why ``value`` is not a ``kind``, or None."""
    try:
        if kind == "double":
            float(value)
        elif kind in _INTEGER_RANGES:
            number = int(value)
            low, high = _INTEGER_RANGES[kind]
            if not low <= number <= high:
                return f"{name} is an {kind} ({low} to {high}), got {value!r}"
        elif kind == "boolean" and value not in ("true", "false"):
            return f"{name} is a boolean (true or false), got {value!r}"
    except ValueError:
        return f"{name} is a{'n' if kind[0] in 'aeiou' else ''} {kind}, got {value!r}"
    return None


def _resolve(value: str, params: dict[str, Parameter], where: str, file: str,
             line: int | None, lines: dict[str, int] | None = None, own: str = "") -> str:
    """Resolve a declaration's value: ``$name`` or ``${expression}`` over earlier ones.

    ``lines``: every declaration's line, to say so of a name declared after this one (or of
    ``own``, the declaration's name).
    """
    before = f"declared before it: {', '.join(params) or 'none'}"

    def not_yet(name: str) -> ScenarioError | None:
        """Return the error for ``name`` declared here or after, None if it is not declared."""
        if not lines or name not in lines:
            return None
        if name == own:
            return ScenarioError(f"{where}: ${name} names the declaration itself; a "
                                 f"declaration can use only the parameters declared before it; "
                                 f"{before}", file=file, line=line)
        return ScenarioError(f"{where}: ${name} is declared after it (line {lines[name]}); a "
                             f"declaration can use only the parameters declared before it; "
                             f"{before}", file=file, line=line)

    if value.startswith("${") and value.endswith("}"):
        try:
            return _evaluate(value[2:-1], params)
        except ValueError as exc:
            unknown = re.fullmatch(r"unknown parameter \$(\w+)", str(exc))
            error = not_yet(unknown.group(1)) if unknown else None
            raise (error or ScenarioError(f"{where}: {exc}", file=file, line=line)) from None
    if value.startswith("$"):
        if value[1:] not in params:
            raise not_yet(value[1:]) or ScenarioError(
                f"{where}: unknown parameter {value}; {before}", file=file, line=line)
        return params[value[1:]].value
    return value


_NUMERIC_TYPES = ("double", "integer", "unsignedInt", "unsignedShort")


def _constraints(raw: Any, kind: str, params: dict[str, Parameter],
                 file: str) -> list[list[tuple[str, str]]]:
    """Read a declaration's value constraint groups (OR-ed; their constraints AND-ed)."""
    from lxml import etree

    groups = []
    for group in raw:
        if not isinstance(group.tag, str) or etree.QName(group).localname != "ConstraintGroup":
            continue  # anything else is reported by the element sweep
        constraints = []
        for c in group:
            if not isinstance(c.tag, str) or etree.QName(c).localname != "ValueConstraint":
                continue
            rule, value = c.get("rule"), c.get("value")
            if rule is None or value is None:
                raise ScenarioError("<ValueConstraint> needs rule and value", file=file,
                                    line=c.sourceline)
            allowed = tuple(_RULES) if kind in _NUMERIC_TYPES else ("equalTo", "notEqualTo")
            if rule not in allowed:
                raise ScenarioError(f"<ValueConstraint rule=\"{rule}\"> is not supported by "
                                    f"import; supported: {', '.join(allowed)}"
                                    + ("" if kind in _NUMERIC_TYPES else
                                       f" (for a {kind} parameter)"),
                                    file=file, line=c.sourceline)
            where = f"<ValueConstraint value=\"{value}\">"
            value = _resolve(value, params, where, file, c.sourceline)
            if kind in _NUMERIC_TYPES:
                try:
                    float(value)
                except ValueError:
                    raise ScenarioError(f"{where}: must be a number (the parameter is a "
                                        f"{kind})", file=file, line=c.sourceline) from None
            constraints.append((rule, value))
        if not constraints:
            raise ScenarioError("<ConstraintGroup> needs at least one <ValueConstraint>",
                                file=file, line=group.sourceline)
        groups.append(constraints)
    return groups


def _allowed(value: str, kind: str, groups: list[list[tuple[str, str]]]) -> bool:
    if not groups:
        return True
    if kind in _NUMERIC_TYPES:
        return any(all(_RULES[rule](float(value), float(bound)) for rule, bound in group)
                   for group in groups)
    return any(all(_RULES[rule](value, bound) for rule, bound in group) for group in groups)


def _describe(groups: list[list[tuple[str, str]]]) -> str:
    return " or ".join("(" + " and ".join(f"{rule} {bound}" for rule, bound in group) + ")"
                       for group in groups)


# Why a <ParameterDeclarations> elsewhere than at the root must be empty.
_ROOT_PARAMETERS_ONLY = ("parameters are declared in the <ParameterDeclarations> at the root of "
                         "the file (<OpenSCENARIO>), which import supports")


def _parameters(raw_root: Any, file: str, overrides: dict[str, str]) -> dict[str, Parameter]:
    """Read the root's parameter declarations and apply the overrides."""
    from lxml import etree

    params: dict[str, Parameter] = {}
    # An override is in place from its declaration on: a later value naming it takes it.
    given = {name.removeprefix("$"): (name, value) for name, value in overrides.items()}
    declarations = [d for d in raw_root if isinstance(d.tag, str)
                    and etree.QName(d).localname == "ParameterDeclarations"]
    if len(declarations) > 1:  # as for every element allowed once (OpenSCENARIO allows one)
        raise ScenarioError("<OpenSCENARIO> has more than one <ParameterDeclarations>",
                            file=file, line=declarations[1].sourceline)
    # Every declaration's line: one may use only those before it.
    lines = {raw.get("name"): raw.sourceline for block in declarations for raw in block
             if isinstance(raw.tag, str) and raw.get("name")}
    for block in declarations:
        for raw in block:
            if not isinstance(raw.tag, str):
                continue
            if etree.QName(raw).localname != "ParameterDeclaration":
                continue  # reported as unsupported by the element sweep
            name = raw.get("name")
            kind = raw.get("parameterType", raw.get("type"))
            value = raw.get("value")
            if not name or kind is None or value is None:
                raise ScenarioError("<ParameterDeclaration> needs name, parameterType and value",
                                    file=file, line=raw.sourceline)
            if name in params:
                raise ScenarioError(f"<ParameterDeclaration name=\"{name}\">: declared twice "
                                    f"(first at line {params[name].line})", file=file,
                                    line=raw.sourceline)
            if kind not in _PARAMETER_TYPES:
                raise ScenarioError(f"<ParameterDeclaration parameterType=\"{kind}\">: "
                                    f"unknown type; valid: {', '.join(_PARAMETER_TYPES)}",
                                    file=file, line=raw.sourceline)
            where = f"<ParameterDeclaration name=\"{name}\">"
            value = _resolve(value, params, where, file, raw.sourceline, lines, name)
            problem = _check_type(name, kind, value)
            if problem:
                raise ScenarioError(f"<ParameterDeclaration>: {problem}", file=file,
                                    line=raw.sourceline)
            groups = _constraints(raw, kind, params, file)
            if not _allowed(value, kind, groups):
                raise ScenarioError(f"{where}: value {value} is outside the values allowed: "
                                    f"{_describe(groups)}", file=file, line=raw.sourceline)
            params[name] = Parameter(name, kind, value, "declared", raw.sourceline)
            if name in given:
                option, override = given[name]
                problem = _check_type(name, kind, override)
                if problem:
                    raise RtsError(f"--param {option}={override}: {problem}")
                if not _allowed(override, kind, groups):
                    raise RtsError(f"--param {option}={override}: outside the values "
                                   f"{file}:{raw.sourceline} allows for {name}: "
                                   f"{_describe(groups)}")
                params[name] = Parameter(name, kind, override, "--param", raw.sourceline)
    for name, value in overrides.items():
        if name.removeprefix("$") not in params:
            raise RtsError(f"--param {name}={value}: no such parameter in {file}; declared: "
                           f"{', '.join(params) or 'none'}")
    return params


# ----------------------------------------------------------------------------- the storyboard

@dataclass
class _Dynamics:
    shape: str
    dimension: str
    value: float


@dataclass
class _Action:
    """One private action on one actor, read and checked before anything runs."""

    el: _El
    name: str
    actor: str
    kind: str  # teleport, speed, lane_change, lane_offset
    params: dict[str, Any]


@dataclass
class _Condition:
    el: _El
    kind: str  # time, distance, state
    delay_s: float
    params: dict[str, Any]
    rising: bool = False


@dataclass
class _Event:
    el: _El
    name: str
    act: int  # index in the importer's acts
    story: str
    maneuver_group: str
    maneuver: str
    priority: str
    actions: list[_Action]
    trigger: list[list[_Condition]] | None


@dataclass
class _Act:
    el: _El
    name: str
    story: str
    trigger: list[list[_Condition]] | None


@dataclass
class _Run:
    """An action under way on one entity: what it changes, until when."""

    action: _Action
    event: int | None  # index in the importer's events; None in Init
    domain: str  # "speed" or "lateral": a new action of the domain ends the running one
    start_s: float
    end_s: float  # when the action ends (inf: continuous)
    move_end_s: float  # when the motion it makes is complete


@dataclass
class _Body:
    """An entity: its place, speed over time (knots) and lateral shifts."""

    name: str
    kind: str
    el: _El
    vehicle: bool = False  # described by a <Vehicle>
    rcs_model: str = "other"  # the key of its RCS model (`RCS_MODELS`)
    center_m: np.ndarray | None = None
    size_m: np.ndarray | None = None
    position_m: np.ndarray | None = None
    heading_rad: float = 0.0
    knots_s: list[float] = field(default_factory=lambda: [0.0])
    knots_mps: list[float] = field(default_factory=lambda: [0.0])
    lane_changes: list[LaneChange] = field(default_factory=list)
    # The .xosc element (tag, line) each lane change came from.
    lane_change_sources: list[tuple[str, int | None]] = field(default_factory=list)
    lane_offset_m: float = 0.0
    runs: dict[str, _Run] = field(default_factory=dict)  # by domain: the latest action

    def trajectory(self) -> Trajectory:
        assert self.position_m is not None
        return Trajectory(TrajectoryPath.line(self.position_m, self.heading_rad),
                          TravelLaw.speed_profile(self.knots_s, self.knots_mps),
                          tuple(self.lane_changes))

    def speed(self, t: float) -> float:
        return float(np.interp(t, self.knots_s, self.knots_mps))

    def travelled(self, t: float) -> float:
        law = TravelLaw.speed_profile(self.knots_s, self.knots_mps)
        k = max(0, int(np.searchsorted(law.knots_s, t, side="right")) - 1)
        dt = t - law.knots_s[k]
        return float(law.s0_m[k] + law.v0_mps[k] * dt + 0.5 * law.a_mps2[k] * dt * dt)

    def left(self) -> np.ndarray:
        return np.array([-math.sin(self.heading_rad), math.cos(self.heading_rad), 0.0])

    def remaining_shift(self, t: float) -> float:
        """Lateral offset the lane changes under way at ``t`` still have to make."""
        out = 0.0
        for lc in self.lane_changes:
            u = min(max((t - lc.start_s) / lc.duration_s, 0.0), 1.0)
            out += lc.offset_m * (1.0 - u * u * u * (10.0 + u * (-15.0 + 6.0 * u)))
        return out

    def set_speed(self, t0: float, target_mps: float, duration_s: float, shape: str) -> float:
        """Change speed from ``t0`` on; later knots are replaced (a new speed action wins).

        Returns how much farther (m) the entity is after a step than the step would put it: a
        step ramps at `MAX_ACCELERATION_MPS2`, centred on ``t0`` (nothing), or from t = 0 when
        ``t0`` is sooner than half the ramp.
        """
        v0 = self.speed(t0)
        if shape == "step" or duration_s < STEP_S:
            if t0 < STEP_S / 2:
                self.knots_s, self.knots_mps = [0.0], [target_mps]
                return 0.0
            # 10 ns over: the scene's times are written to 1 ns.
            ramp = max(STEP_S, abs(target_mps - v0) / MAX_ACCELERATION_MPS2) + 1e-8
            # The speed the ramp starts from is the one half a ramp earlier: lengthen the ramp
            # until it changes that speed at the bound (the speed before changes at most at it).
            for _ in range(4):
                before = self.speed(max(0.0, t0 - ramp / 2))
                ramp = max(ramp, abs(target_mps - before) / MAX_ACCELERATION_MPS2 + 1e-8)
            start = max(0.0, t0 - ramp / 2)
            before = self.speed(start)
            self._truncate(start)
            if not self.knots_s:
                self.knots_s, self.knots_mps = [0.0], [before]
            self.knots_s += [start + ramp] if start == 0.0 else [start, start + ramp]
            self.knots_mps += [target_mps] if start == 0.0 else [before, target_mps]
            return (target_mps - before) * (t0 - start - ramp / 2)
        self._truncate(t0)
        f, _, bend = _SHAPES[shape]
        # Linear pieces: interpolation error <= h^2 / 8 max|v''| (and positions after the
        # transition are exact to O(h^4), as v' vanishes at both ends of cubic and sinusoidal).
        delta = target_mps - v0
        pieces = 1 if bend == 0.0 else min(MAX_SHAPE_PIECES, max(2, math.ceil(
            math.sqrt(abs(delta) * bend / (8.0 * SPEED_TOLERANCE_MPS)))))
        for i in range(pieces + 1):
            self.knots_s.append(t0 + duration_s * i / pieces)
            self.knots_mps.append(v0 + delta * f(i / pieces))
        return 0.0

    def hold_speed(self, t: float) -> None:
        """Keep the speed the entity has at ``t`` from then on (a stopped transition)."""
        v = self.speed(t)
        self._truncate(t)
        self.knots_s.append(t)
        self.knots_mps.append(v)

    def _truncate(self, t: float) -> None:
        keep = [i for i, k in enumerate(self.knots_s) if k < t]
        self.knots_s = [self.knots_s[i] for i in keep]
        self.knots_mps = [self.knots_mps[i] for i in keep]


@dataclass
class ImportResult:
    """What `import_xosc` made: the scene text, its data, the parameters used and the notes."""

    text: str
    scene: dict[str, Any]
    parameters: dict[str, Parameter]
    ego: str
    notes: list[str]
    # Where in the .xosc what the scene writes came from: key path (``targets[1]``,
    # ``ego.lane_changes[0]``, as errors name them) to the element's tag and line.
    sources: dict[str, tuple[str, int | None]] = field(default_factory=dict)

    def source_of(self, key_path: str | None) -> tuple[str, int | None] | None:
        """Return the .xosc element (tag, line) behind a scene key path, or its parent's."""
        while key_path:
            if key_path in self.sources:
                return self.sources[key_path]
            cut = max(key_path.rfind("."), key_path.rfind("["))
            key_path = key_path[:cut] if cut > 0 else ""
        return None


class _Importer:
    def __init__(self, file: str, root: _El, ego: str | None, lane_width_m: float) -> None:
        self.file = file
        self.root = root
        self.lane_width_m = lane_width_m
        self.notes: list[str] = []
        self.sources: dict[str, tuple[str, int | None]] = {}
        self.bodies: dict[str, _Body] = {}
        self.init_actions: list[_Action] = []
        self.acts: list[_Act] = []
        self.events: list[_Event] = []
        self.stop: list[list[_Condition]] = []
        self.names: dict[str, dict[str, int]] = {}  # element type -> name -> how many
        self.description = ""
        self.act_start: dict[int, float] = {}  # by index in self.acts
        self.event_start: dict[int, float] = {}
        self.event_end: dict[int, float] = {}
        self.action_times: dict[str, tuple[float, float]] = {}
        self.runs: list[_Run] = []  # the storyboard's actions as they were applied
        self._read_root()
        self.ego = self._choose_ego(ego)

    # -- reading -------------------------------------------------------------------------

    def _read_root(self) -> None:
        root = self.root
        root.used = True
        if root.tag != "OpenSCENARIO":
            raise root.error(f"<{root.tag}>: not an OpenSCENARIO file (the root element must "
                             f"be <OpenSCENARIO>)")
        header = root.child("FileHeader", required=False)
        if header is not None:
            self.description = header.attrs.get("description", "")
            header.skip()
        for block in root.kids("ParameterDeclarations"):
            block.used = True
            for decl in block.kids("ParameterDeclaration"):
                # Read (and checked) by _parameters before anything else.
                for attr in ("name", "value", "parameterType" if decl.has("parameterType")
                             else "type"):
                    decl.text(attr)
                for group in decl.kids("ConstraintGroup"):
                    for constraint in group.kids("ValueConstraint"):
                        constraint.text("rule")
                        constraint.text("value")
        for block in root.kids("CatalogLocations"):
            if block.children:  # only a CatalogReference would use them, and that is an error
                self.notes.append(f"{self.file}:{block.line}: <CatalogLocations> not used: "
                                  f"catalogs are not read")
            block.skip()
        network = root.child("RoadNetwork", required=False)
        if network is not None:
            if network.children:
                self.notes.append(f"{self.file}:{network.line}: <RoadNetwork> not used: "
                                  f"positions are world coordinates, lanes "
                                  f"{self.lane_width_m:g} m wide")
            network.skip()
        entities = root.need("Entities")
        for obj in entities.kids("ScenarioObject"):
            self._read_entity(obj)
        if not self.bodies:
            raise entities.error("<Entities> needs at least one <ScenarioObject>")
        board = root.need("Storyboard")
        init = board.need("Init")
        actions = init.need("Actions")
        for private in actions.kids("Private"):
            actor = self._entity(private, private.text("entityRef"))
            for item in private.kids("PrivateAction"):
                self.init_actions += self._private_action(item, "", [actor], init=True)
        for other in actions.kids("GlobalAction", "UserDefinedAction"):
            raise other.error(f"<{other.tag}> is not supported by import; supported in "
                              f"<Init>: <Private> actions ({', '.join(SUPPORTED_ACTIONS)})")
        for story in board.kids("Story"):
            self._read_story(story)
        stop = board.child("StopTrigger", required=False)
        if stop is None or not stop.children:
            raise (stop or board).error(
                "<Storyboard> needs a <StopTrigger> (a SimulationTimeCondition gives the "
                "scene's duration_s)")
        self.stop = self._trigger(stop)
        self.stop_el = stop  # its errors name its line
        _check_all_read(root)
        self._check_references()

    def _read_entity(self, obj: _El) -> None:
        name = obj.text("name")
        if name in self.bodies:
            raise obj.error(f"duplicate entity name {name!r}")
        described = obj.kids("Vehicle", "Pedestrian", "MiscObject")
        for extra in obj.children:
            if extra not in described:
                raise extra.error(f"<{extra.tag}> in <ScenarioObject> is not supported by "
                                  f"import; supported: Vehicle, Pedestrian, MiscObject "
                                  f"(controllers and catalogs are not read)")
        if len(described) != 1:
            raise obj.error("<ScenarioObject> needs one <Vehicle>, <Pedestrian> or "
                            "<MiscObject>")
        what = described[0]
        category, kinds = {"Vehicle": ("vehicleCategory", VEHICLE_KINDS),
                           "Pedestrian": ("pedestrianCategory", PEDESTRIAN_KINDS),
                           "MiscObject": ("miscObjectCategory", MISC_KINDS)}[what.tag]
        chosen = what.choice(category, tuple(kinds))
        kind = kinds[chosen]
        body = _Body(name=name, kind=kind, el=obj, vehicle=what.tag == "Vehicle",
                     rcs_model=RCS_MODEL_OF_CATEGORY.get(chosen, kind))
        # Descriptive attributes and parts that do not change what the radar sees.
        for attr in ("name", "mass", "model", "model3d", "role"):
            what.read.add(attr)
        for part in what.kids("Performance", "Axles", "Properties"):
            part.skip()
        for block in what.kids("ParameterDeclarations"):
            block.empty(_ROOT_PARAMETERS_ONLY)
        box = what.child("BoundingBox", required=False)
        if box is not None:
            center, size = box.need("Center"), box.need("Dimensions")
            body.center_m = np.array([center.number(a) for a in ("x", "y", "z")])
            body.size_m = np.array([size.number(a) for a in ("length", "width", "height")])
        self.bodies[name] = body

    def _entity(self, el: _El, name: str) -> str:
        if name not in self.bodies:
            raise el.error(f"unknown entity {name!r}; entities: {', '.join(self.bodies)}")
        return name

    def _read_story(self, story: _El) -> None:
        story_name = story.text("name", "")
        self._named("story", story_name)
        for block in story.kids("ParameterDeclarations"):
            block.empty(_ROOT_PARAMETERS_ONLY)
        for act in story.kids("Act"):
            act_name = act.text("name", "")
            self._named("act", act_name)
            start = act.child("StartTrigger", required=False)
            stop = act.child("StopTrigger", required=False)
            if stop is not None and stop.children:
                raise stop.error("an <Act>'s <StopTrigger> is not supported by import; stop "
                                 "the scene with the <Storyboard>'s <StopTrigger>")
            self.acts.append(_Act(act, act_name, story_name,
                                  self._trigger(start) if start is not None else None))
            for group in act.kids("ManeuverGroup"):
                self._read_group(group, len(self.acts) - 1, story_name)

    def _read_group(self, group: _El, act: int, story: str) -> None:
        group_name = group.text("name", "")
        self._named("maneuverGroup", group_name)
        if group.number("maximumExecutionCount", 1.0) != 1.0:
            raise group.error("maximumExecutionCount other than 1 is not supported by import")
        actors_el = group.need("Actors")
        if actors_el.boolean("selectTriggeringEntities", False):
            raise actors_el.error("<Actors selectTriggeringEntities=\"true\"> is not "
                                  "supported by import; name the actors with <EntityRef>")
        actors = [self._entity(ref, ref.text("entityRef")) for ref in actors_el.kids("EntityRef")]
        for maneuver in group.kids("Maneuver"):
            maneuver_name = maneuver.text("name", "")
            self._named("maneuver", maneuver_name)
            for block in maneuver.kids("ParameterDeclarations"):
                block.empty(_ROOT_PARAMETERS_ONLY)
            for event in maneuver.kids("Event"):
                name = event.text("name", "")
                self._named("event", name)
                if event.number("maximumExecutionCount", 1.0) != 1.0:
                    raise event.error("maximumExecutionCount other than 1 is not supported by "
                                      "import")
                priority = event.choice("priority", ("overwrite", "override", "parallel",
                                                     "skip"), "parallel")
                actions = []
                for action in event.kids("Action"):
                    action_name = action.text("name", "")
                    self._named("action", action_name)
                    private = action.pick("actions", ("PrivateAction",),
                                          ("PrivateAction: " + ", ".join(SUPPORTED_ACTIONS),))
                    if not actors:
                        raise private.error("a private action needs actors: <Actors> of the "
                                            "<ManeuverGroup> names none")
                    actions.append(self._private_action(private, action_name, actors))
                start = event.child("StartTrigger", required=False)
                self.events.append(_Event(
                    event, name, act, story, group_name, maneuver_name, priority,
                    [a for group_actions in actions for a in group_actions],
                    self._trigger(start) if start is not None else None))

    def _named(self, kind: str, name: str) -> None:
        names = self.names.setdefault(kind, {})
        names[name] = names.get(name, 0) + 1

    def _private_action(self, private: _El, name: str, actors: list[str],
                        init: bool = False) -> list[_Action]:
        supported = ("LongitudinalAction", "LateralAction", "TeleportAction")
        action = private.pick("actions", supported, SUPPORTED_ACTIONS)
        if action.tag == "LongitudinalAction":
            action = action.pick("actions", ("SpeedAction",), SUPPORTED_ACTIONS)
        elif action.tag == "LateralAction":
            action = action.pick("actions", ("LaneChangeAction", "LaneOffsetAction",
                                             "LateralDistanceAction"), SUPPORTED_ACTIONS)
        reader = {"TeleportAction": self._teleport, "SpeedAction": self._speed_action,
                  "LaneChangeAction": self._lane_change, "LaneOffsetAction": self._lane_offset,
                  "LateralDistanceAction": self._lateral_distance}
        if action.tag == "TeleportAction" and not init:
            raise action.error("<TeleportAction> is supported in <Init> only (a jump in the "
                               "storyboard has no counterpart in a scene's motion)")
        kind, params = reader[action.tag](action)
        return [_Action(action, name, actor, kind, params) for actor in actors]

    def _teleport(self, action: _El) -> tuple[str, dict[str, Any]]:
        position = action.need("Position").pick("positions", SUPPORTED_POSITIONS,
                                                SUPPORTED_POSITIONS + ("(no road network)",))
        params: dict[str, Any] = {"type": position.tag}
        if position.tag == "WorldPosition":
            params["xyz"] = [position.number(a, 0.0 if a == "z" else None) for a in "xyz"]
            params["h"] = position.number("h", 0.0)
            self._level(position)
        else:
            params["ref"] = self._entity(position, position.text("entityRef"))
            params["dxyz"] = [position.number(a, 0.0 if a == "dz" else None)
                              for a in ("dx", "dy", "dz")]
            orientation = position.child("Orientation", required=False)
            params["h_type"], params["h"] = "relative", 0.0
            if orientation is not None:
                params["h_type"] = orientation.choice("type", ("relative", "absolute"),
                                                      "relative")
                params["h"] = orientation.number("h", 0.0)
                self._level(orientation)
        return "teleport", params

    @staticmethod
    def _level(el: _El) -> None:
        for angle in ("p", "r"):
            if el.number(angle, 0.0) != 0.0:
                raise el.error(f"<{el.tag} {angle}=\"{el.attrs[angle]}\">: pitch and roll are "
                               f"not supported by import (entities stay level)")

    def _dynamics(self, el: _El, shape_attr: str = "dynamicsShape") -> _Dynamics:
        shape = el.choice(shape_attr, SHAPES)
        dimension = el.choice("dynamicsDimension", DIMENSIONS)
        value = el.number("value")
        if el.has("followingMode"):
            el.choice("followingMode", ("position",))
        if value < 0.0 or (value == 0.0 and shape != "step" and dimension != "time"):
            raise el.error(f"<{el.tag} value=\"{el.attrs['value']}\">: must be > 0 for "
                           f"dynamicsDimension {dimension}")
        if shape == "step" and value > 0.0:
            self.notes.append(f"{self.file}:{el.line}: <{el.tag} dynamicsShape=\"step\" "
                              f"value=\"{el.attrs['value']}\">: played as an immediate change "
                              f"(a step takes no time; the value is not used)")
        return _Dynamics(shape, dimension, value)

    def _speed_action(self, action: _El) -> tuple[str, dict[str, Any]]:
        dynamics = self._dynamics(action.need("SpeedActionDynamics"))
        target = action.need("SpeedActionTarget").pick(
            "speed targets", ("AbsoluteTargetSpeed", "RelativeTargetSpeed"))
        params: dict[str, Any] = {"dynamics": dynamics}
        if target.tag == "AbsoluteTargetSpeed":
            params["speed_mps"] = target.number("value")
        else:
            params["ref"] = self._entity(target, target.text("entityRef"))
            params["value"] = target.number("value")
            params["value_type"] = target.choice("speedTargetValueType", ("delta", "factor"))
            if target.boolean("continuous", False):
                raise target.error("<RelativeTargetSpeed continuous=\"true\"> is not supported "
                                   "by import: the speed is taken from the reference once, "
                                   "when the action starts")
        return "speed", params

    def _lane_change(self, action: _El) -> tuple[str, dict[str, Any]]:
        dynamics = self._dynamics(action.need("LaneChangeActionDynamics"))
        target = action.need("LaneChangeTarget").pick(
            "lane change targets", ("RelativeTargetLane",),
            ("RelativeTargetLane (AbsoluteTargetLane needs a road network)",))
        return "lane_change", {
            "dynamics": dynamics, "ref": self._entity(target, target.text("entityRef")),
            "lanes": _lanes(target),
            "target_offset_m": action.number("targetLaneOffset", 0.0)}

    def _lane_offset(self, action: _El) -> tuple[str, dict[str, Any]]:
        continuous = action.boolean("continuous", False)
        dyn = action.need("LaneOffsetActionDynamics")
        shape = dyn.choice("dynamicsShape", SHAPES)
        max_acc = dyn.number("maxLateralAcc") if shape != "step" else \
            dyn.number("maxLateralAcc", 1.0)
        if max_acc <= 0.0:
            raise dyn.error("<LaneOffsetActionDynamics maxLateralAcc> must be > 0")
        target = action.need("LaneOffsetTarget").pick(
            "lane offset targets", ("AbsoluteTargetLaneOffset", "RelativeTargetLaneOffset"))
        params: dict[str, Any] = {"continuous": continuous, "shape": shape,
                                  "max_acc_mps2": max_acc, "value": target.number("value")}
        if target.tag == "RelativeTargetLaneOffset":
            params["ref"] = self._entity(target, target.text("entityRef"))
        return "lane_offset", params

    def _lateral_distance(self, action: _El) -> tuple[str, dict[str, Any]]:
        if action.boolean("freespace", False):
            raise action.error("<LateralDistanceAction freespace=\"true\"> is not supported by "
                               "import; distances are between reference points")
        if action.has("coordinateSystem"):
            action.choice("coordinateSystem", ("entity",))
        side = action.choice("displacement", ("any", "leftToReferencedEntity",
                                              "rightToReferencedEntity"), "any")
        distance = action.number("distance", 0.0)
        if distance < 0.0:
            raise action.error("<LateralDistanceAction distance> must be >= 0")
        # The constraints limit the lateral motion the action makes (OpenSCENARIO's
        # DynamicConstraints: acceleration, deceleration, speed and their rates).
        limits = {"acc": math.inf, "speed": math.inf, "jerk": math.inf}
        constraints = action.child("DynamicConstraints", required=False)
        if constraints is not None:
            for attr, limit in (("maxAcceleration", "acc"), ("maxDeceleration", "acc"),
                                ("maxSpeed", "speed"), ("maxAccelerationRate", "jerk"),
                                ("maxDecelerationRate", "jerk")):
                if constraints.has(attr):
                    value = constraints.number(attr)
                    if value <= 0.0:
                        raise constraints.error(f"<DynamicConstraints {attr}="
                                                f"\"{constraints.attrs[attr]}\">: must be > 0")
                    limits[limit] = min(limits[limit], value)
        return "lateral_distance", {
            "ref": self._entity(action, action.text("entityRef")), "distance_m": distance,
            "side": side, "limits": limits,
            "continuous": action.boolean("continuous", False)}

    def _trigger(self, trigger: _El) -> list[list[_Condition]]:
        trigger.used = True
        if trigger.tag == "StartTrigger" and not trigger.kids("ConditionGroup"):
            owner = trigger.parent.tag if trigger.parent is not None else "element"
            raise trigger.error(f"an empty <StartTrigger> is not supported by import: "
                                f"OpenSCENARIO gives an empty trigger no meaning (the import "
                                f"would start the {owner} at once); give it a "
                                f"<ConditionGroup> (a SimulationTimeCondition for a time)")
        groups = []
        for group in trigger.kids("ConditionGroup"):
            conditions = [self._condition(c) for c in group.kids("Condition")]
            if not conditions:
                raise group.error("<ConditionGroup> needs at least one <Condition>")
            groups.append(conditions)
        return groups

    def _condition(self, cond: _El) -> _Condition:
        out = self._read_condition(cond)
        out.rising = cond.attrs.get("conditionEdge") == "rising"
        return out

    def _read_condition(self, cond: _El) -> _Condition:
        cond.text("name", "")
        delay = cond.number("delay", 0.0)
        if delay < 0.0:
            raise cond.error("<Condition delay> must be >= 0")
        cond.choice("conditionEdge", ("none", "rising"), "none")
        by = cond.pick("conditions", ("ByValueCondition", "ByEntityCondition"),
                       SUPPORTED_CONDITIONS)
        if by.tag == "ByValueCondition":
            inner = by.pick("conditions", ("SimulationTimeCondition",
                                           "StoryboardElementStateCondition"),
                            SUPPORTED_CONDITIONS)
            if inner.tag == "SimulationTimeCondition":
                return _Condition(cond, "time", delay, {
                    "value": inner.number("value"), "rule": inner.choice("rule", tuple(_RULES))})
            kind = inner.choice("storyboardElementType", ("story", "act", "maneuverGroup",
                                                          "maneuver", "event", "action"))
            state = inner.choice("state", ("startTransition", "runningState", "endTransition",
                                           "completeState"))
            return _Condition(cond, "state", delay, {
                "type": kind, "ref": inner.text("storyboardElementRef"),
                "end": state in ("endTransition", "completeState"), "el": inner})
        entities = by.need("TriggeringEntities")
        rule = entities.choice("triggeringEntitiesRule", ("any", "all"))
        refs = [self._entity(r, r.text("entityRef")) for r in entities.kids("EntityRef")]
        if not refs:
            raise entities.error("<TriggeringEntities> needs at least one <EntityRef>")
        inner = by.need("EntityCondition").pick("conditions", ("RelativeDistanceCondition",),
                                                SUPPORTED_CONDITIONS)
        if inner.boolean("freespace", False):
            raise inner.error("<RelativeDistanceCondition freespace=\"true\"> is not supported "
                              "by import; distances are between reference points (use "
                              "freespace=\"false\")")
        if inner.has("coordinateSystem"):
            inner.choice("coordinateSystem", ("entity", "world"))
        if inner.has("routingAlgorithm"):
            inner.choice("routingAlgorithm", ("undefined",))
        return _Condition(cond, "distance", delay, {
            "triggering": refs, "all": rule == "all",
            "ref": self._entity(inner, inner.text("entityRef")),
            "type": inner.choice("relativeDistanceType", ("longitudinal", "lateral",
                                                          "cartesianDistance",
                                                          "euclidianDistance")),
            "world": inner.attrs.get("coordinateSystem") == "world",
            "rule": inner.choice("rule", tuple(_RULES)), "value": inner.number("value")})

    def _check_references(self) -> None:
        for cond in self._conditions():
            if cond.kind != "state":
                continue
            kind, ref = cond.params["type"], cond.params["ref"]
            names = self.names.get(kind, {})
            if ref not in names:
                raise cond.params["el"].error(
                    f"<StoryboardElementStateCondition>: no {kind} named {ref!r}; {kind}s: "
                    f"{', '.join(sorted(names)) or 'none'}")
            if names[ref] > 1:
                raise cond.params["el"].error(
                    f"<StoryboardElementStateCondition>: {names[ref]} {kind}s are named "
                    f"{ref!r}: the reference is ambiguous (give them distinct names)")

    def _conditions(self) -> list[_Condition]:
        triggers = [self.stop, *(a.trigger for a in self.acts),
                    *(e.trigger for e in self.events)]
        return [c for trigger in triggers if trigger for group in trigger for c in group]

    def _choose_ego(self, ego: str | None) -> str:
        if ego is not None:
            if ego not in self.bodies:
                raise RtsError(f"--ego {ego}: no such entity in {self.file}; entities: "
                               f"{', '.join(self.bodies)}")
            return ego
        for name in self.bodies:
            if name.lower() in ("ego", "hero"):  # "hero": CARLA's name for the ego
                return name
        # A radar rides a vehicle: the first one, else the first entity, said in a note.
        vehicles = [name for name, body in self.bodies.items() if body.vehicle]
        chosen = vehicles[0] if vehicles else next(iter(self.bodies))
        which = ("the first vehicle" if vehicles else
                 "the first entity (no vehicle, no entity named Ego or Hero)")
        self.notes.append(f"{self.file}: the ego (radar carrier) is {chosen!r}, {which}; "
                          f"--ego NAME names another")
        return chosen

    # -- playing -------------------------------------------------------------------------

    def play(self) -> float:
        """Apply Init, then every event in time order; return the scene's duration."""
        self._place()
        for action in self._init_order():
            self._run(action, 0.0, None)
        pending_acts = list(self.acts)
        pending = list(range(len(self.events)))
        while True:
            candidates: list[tuple[float, int, Any]] = []
            for act in pending_acts:
                candidates.append((self._trigger_time(act.trigger, 0.0), 0, act))
            for i in pending:
                lower = self.act_start.get(self.events[i].act)
                if lower is not None:
                    candidates.append((self._trigger_time(self.events[i].trigger, lower), 1, i))
            stop = self._trigger_time(self.stop, 0.0)
            candidates.append((stop, 2, None))
            t, order, item = min(candidates, key=lambda c: (c[0], c[1]))
            if order == 2 or not math.isfinite(t):
                break
            if order == 0:
                self._note_rising(item.trigger, 0.0, t)
                pending_acts.remove(item)
                self.act_start[self.acts.index(item)] = t
            else:
                self._note_rising(self.events[item].trigger, self.act_start[
                    self.events[item].act], t)
                pending.remove(item)
                self._start_event(item, t)
        if not math.isfinite(stop):
            raise self.stop_el.error("the <Storyboard>'s <StopTrigger> never fires: the scene's "
                                  "duration is unknown (give it a SimulationTimeCondition)")
        if stop <= 0.0:
            raise self.stop_el.error(f"the <StopTrigger> fires at t = {stop:g} s: the scene "
                                  f"needs a duration > 0")
        for act in pending_acts:
            self.notes.append(f"{self.file}:{act.el.line}: act {act.name!r} never starts "
                              f"before the end ({stop:g} s)")
        for i in pending:
            event = self.events[i]
            self.notes.append(f"{self.file}:{event.el.line}: event {event.name!r} never starts "
                              f"before the end ({stop:g} s)")
        return stop

    def _place(self) -> None:
        teleports = [a for a in self.init_actions if a.kind == "teleport"]
        placed: dict[str, _Action] = {}
        for action in teleports:
            if action.actor in placed:
                raise action.el.error(f"entity {action.actor!r} is placed twice in <Init> "
                                      f"(first at line {placed[action.actor].el.line})")
            placed[action.actor] = action
        # Init happens at t = 0 as a whole: two speeds for one entity there leave one of them
        # unplayed, whichever the order.
        speeds: dict[str, _Action] = {}
        for action in self.init_actions:
            if action.kind != "speed":
                continue
            if action.actor in speeds:
                raise action.el.error(f"entity {action.actor!r} is given a speed twice in "
                                      f"<Init> (first at line {speeds[action.actor].el.line}): "
                                      f"Init happens at t = 0 as a whole; give it one, and "
                                      f"the change in an event of the storyboard")
            speeds[action.actor] = action
        todo = list(teleports)
        while todo:
            ready = [a for a in todo if a.params["type"] == "WorldPosition"
                     or self.bodies[a.params["ref"]].position_m is not None]
            if not ready:
                a = todo[0]
                raise a.el.error(f"the position of {a.actor!r} refers to "
                                 f"{a.params['ref']!r}, which is never placed or refers back "
                                 f"to it")
            for a in ready:
                body = self.bodies[a.actor]
                p = a.params
                if p["type"] == "WorldPosition":
                    body.position_m, body.heading_rad = np.array(p["xyz"]), p["h"]
                else:
                    ref = self.bodies[p["ref"]]
                    assert ref.position_m is not None
                    d = np.array(p["dxyz"])
                    if p["type"] == "RelativeObjectPosition":
                        c, s = math.cos(ref.heading_rad), math.sin(ref.heading_rad)
                        d = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
                    body.position_m = ref.position_m + d
                    body.heading_rad = p["h"] + (ref.heading_rad if p["h_type"] == "relative"
                                                 else 0.0)
                todo.remove(a)
        for body in self.bodies.values():
            if body.position_m is None:
                raise body.el.error(f"entity {body.name!r} is never placed: give it a "
                                    f"<TeleportAction> in <Init>")

    def _init_order(self) -> list[_Action]:
        """Order Init's actions: one relative to another entity follows that entity's own.

        An action relative to another entity (its speed, lane or lateral place) comes after
        that entity's Init actions of its kind: Init happens at t = 0 as a whole, whatever the
        order of the file.
        """
        todo = [a for a in self.init_actions if a.kind != "teleport"]

        def domain(a: _Action) -> str:
            return "speed" if a.kind == "speed" else "lateral"

        out: list[_Action] = []
        while todo:
            # Ready: nothing pending of the entity it refers to, nor earlier of its own.
            ready = [a for i, a in enumerate(todo) if not any(
                domain(b) == domain(a) and (b.actor == a.params.get("ref") != a.actor
                                            or b.actor == a.actor and j < i)
                for j, b in enumerate(todo))]
            if not ready:
                a = todo[0]
                raise a.el.error(f"the initial {domain(a)} action of {a.actor!r} refers to "
                                 f"{a.params['ref']!r}, whose initial {domain(a)} action "
                                 f"refers back to it (Init happens at t = 0 as a whole)")
            out += ready
            todo = [a for a in todo if not any(a is r for r in ready)]
        return out

    def _start_event(self, index: int, t: float) -> None:
        event = self.events[index]
        running = self._running_in_maneuver(index, t)
        if event.priority == "skip" and running:
            self.notes.append(f"{self.file}:{event.el.line}: event {event.name!r} skipped "
                              f"at {t:g} s (priority skip, event "
                              f"{self.events[running[0]].name!r} still running)")
            self.event_start[index] = self.event_end[index] = math.inf
            return
        self.event_start[index] = t
        if event.priority in ("overwrite", "override"):
            for j in running:
                self._stop_event(j, index, t)
        for action in event.actions:
            self._run(action, t, index)
        self._refresh(index)

    def _running_in_maneuver(self, index: int, t: float) -> list[int]:
        """Return the other events of ``index``'s maneuver running at ``t``."""
        maneuver = self.events[index].el.parent
        return [j for j, start in self.event_start.items()
                if j != index and self.events[j].el.parent is maneuver
                and start <= t < self.event_end[j]]

    def _stop_event(self, index: int, by: int, t: float) -> None:
        """Stop a running event at ``t`` (priority overwrite of event ``by``).

        Its speed transitions end where they are; a lateral move cannot stop midway in a scene.
        """
        event, stopper = self.events[index], self.events[by]
        for run in [r for r in self.runs if r.event == index and r.end_s > t]:
            body = self.bodies[run.action.actor]
            # (A lateral step, a 1 ms quintic centred on its start, is complete at once.)
            if run.move_end_s > t + STEP_S and run.domain == "lateral":
                raise stopper.el.error(
                    f"event {stopper.name!r} (priority {stopper.priority}) starts at {t:g} s "
                    f"and would stop event {event.name!r} (line {event.el.line}) in the middle "
                    f"of the lateral move of {run.action.actor!r} (until "
                    f"{run.move_end_s:g} s): a scene's lane change cannot stop midway, this is "
                    f"not supported by import")
            if run.move_end_s > t and body.runs.get("speed") is run:
                body.hold_speed(t)
            run.end_s = t
        self._refresh(index)
        self.notes.append(f"{self.file}:{stopper.el.line}: event {event.name!r} stopped at "
                          f"{t:g} s by event {stopper.name!r} (priority {stopper.priority})")

    def _run(self, action: _Action, t: float, event: int | None) -> None:
        """Apply an action of an event (None: Init) from ``t`` on and record it."""
        body = self.bodies[action.actor]
        domain = "speed" if action.kind == "speed" else "lateral"
        old = body.runs.get(domain)
        if old is not None and old.end_s > t:
            # A new action of the same domain ends the running one.
            if domain == "lateral" and old.move_end_s > t:
                self.notes.append(
                    f"{self.file}:{action.el.line}: lateral move of {action.actor!r} starts at "
                    f"{t:g} s while the one of line {old.action.el.line} is under way (until "
                    f"{old.move_end_s:g} s): played as the sum of both quintics, which ends "
                    f"where the new move aims")
            old.end_s = t
            if old.event is not None:
                self._refresh(old.event)
        changes = len(body.lane_changes)
        duration = self._apply(action, t)
        if domain == "lateral":
            move_end = max((lc.start_s + lc.duration_s for lc in body.lane_changes[changes:]),
                           default=t)
        else:
            move_end = t + duration
        run = _Run(action, event, domain, t, t + duration, move_end)
        body.runs[domain] = run
        if event is not None:
            self.runs.append(run)

    def _refresh(self, index: int) -> None:
        """Set an event's and its actions' end times from its runs (the latest actor's)."""
        runs = [r for r in self.runs if r.event == index]
        self.event_end[index] = max((r.end_s for r in runs), default=self.event_start[index])
        for name in {r.action.name for r in runs}:
            mine = [r for r in runs if r.action.name == name]
            self.action_times[name] = (min(r.start_s for r in mine),
                                       max(r.end_s for r in mine))

    def _apply(self, action: _Action, t: float) -> float:
        """Apply an action from ``t`` on; return its duration."""
        body = self.bodies[action.actor]
        p = action.params
        where = f"{self.file}:{action.el.line}"
        if action.kind == "speed":
            dyn: _Dynamics = p["dynamics"]
            v0 = body.speed(t)
            if "speed_mps" in p:
                target = p["speed_mps"]
            else:
                base = self.bodies[p["ref"]].speed(t)
                target = base + p["value"] if p["value_type"] == "delta" else base * p["value"]
            if not 0.0 <= target <= 150.0:
                raise action.el.error(f"target speed {target:g} m/s of {action.actor!r}: "
                                      f"the import takes 0 to 150 m/s (it does not import "
                                      f"reversing; a scene file drives backwards with a "
                                      f"negative speed_mps on constant_velocity or "
                                      f"speed_profile)")
            duration = self._speed_duration(action, dyn, v0, target)
            peak = (abs(target - v0) * _SHAPES[dyn.shape][1] / duration
                    if dyn.shape != "step" and duration >= STEP_S else 0.0)
            if peak > MAX_ACCELERATION_MPS2 * (1.0 + 1e-6):
                raise action.el.error(
                    f"the speed of {action.actor!r} changes from {v0:g} to {target:g} m/s in "
                    f"{duration:g} s ({dyn.shape}): a peak acceleration of {peak:.6g} m/s2; "
                    f"a scene's accelerations run from {-MAX_ACCELERATION_MPS2:g} to "
                    f"{MAX_ACCELERATION_MPS2:g} m/s2 (a step is played at that bound)")
            ahead_m = body.set_speed(t, target, duration, dyn.shape)
            if abs(ahead_m) >= 1e-3:
                self.notes.append(f"{where}: step of {action.actor!r} at {t:g} s played as a "
                                  f"ramp at {MAX_ACCELERATION_MPS2:g} m/s2 from 0 s (sooner "
                                  f"than half the ramp): positions after it "
                                  f"{abs(ahead_m):.3g} m {'ahead of' if ahead_m > 0 else 'behind'}"
                                  f" a step")
            if dyn.shape in ("cubic", "sinusoidal") and duration >= STEP_S and v0 != target:
                self.notes.append(f"{where}: {dyn.shape} speed transition of "
                                  f"{action.actor!r} as linear pieces (speed within "
                                  f"{SPEED_TOLERANCE_MPS * 1000:g} mm/s)")
            return 0.0 if dyn.shape == "step" else duration
        if action.kind == "lane_change":
            dyn = p["dynamics"]
            ref = self.bodies[p["ref"]]
            shift = self._lateral_gap(body, ref, t) - ref.lane_offset_m \
                + p["lanes"] * self.lane_width_m + p["target_offset_m"]
            body.lane_offset_m = p["target_offset_m"]
            if dyn.shape == "step" or dyn.dimension == "time" and dyn.value < STEP_S:
                duration = 0.0
            elif dyn.dimension == "time":
                duration = dyn.value
            elif dyn.dimension == "rate":
                duration = QUINTIC_PEAK_SLOPE * abs(shift) / dyn.value
            else:
                duration = self._time_to_travel(action, body, t, dyn.value)
            if dyn.dimension == "distance" and dyn.shape != "step" and abs(shift) >= 1e-9 \
                    and duration >= lane_change_seconds(shift):  # else `_shift` says how
                self.notes.append(f"{self.file}:{action.el.line}: lane change of "
                                  f"{action.actor!r} over {dyn.value:g} m played over the "
                                  f"{duration:.3f} s its speeds as known at {t:.3f} s take to "
                                  f"cover it: a speed action that starts later does not "
                                  f"stretch it")
            self._shift(action, body, t, shift, duration, dyn.shape)
            return duration
        if action.kind == "lane_offset":
            if "ref" in p:
                new_offset = self.bodies[p["ref"]].lane_offset_m + p["value"]
            else:
                new_offset = p["value"]
            shift = new_offset - body.lane_offset_m
            body.lane_offset_m = new_offset
            duration = 0.0 if p["shape"] == "step" else math.sqrt(
                LANE_CHANGE_PEAK * abs(shift) / p["max_acc_mps2"])
            self._shift(action, body, t, shift, duration, p["shape"])
            if p["continuous"] and "ref" in p:
                self.notes.append(f"{where}: continuous lane offset of {action.actor!r} "
                                  f"relative to {p['ref']!r} set once at {t:g} s; later "
                                  f"lateral moves of {p['ref']!r} are not followed")
            return math.inf if p["continuous"] else duration
        if action.kind == "lateral_distance":
            ref = self.bodies[p["ref"]]
            gap = self._lateral_gap(body, ref, t)  # ref left of body's final lateral place
            left = {"leftToReferencedEntity": True, "rightToReferencedEntity": False}.get(
                p["side"], gap <= 0.0)
            shift = gap + (p["distance_m"] if left else -p["distance_m"])
            body.lane_offset_m += shift
            limits = p["limits"]
            duration = max(math.sqrt(LANE_CHANGE_PEAK * abs(shift) / limits["acc"]),
                           QUINTIC_PEAK_SLOPE * abs(shift) / limits["speed"],
                           (QUINTIC_PEAK_JERK * abs(shift) / limits["jerk"]) ** (1.0 / 3.0))
            self._shift(action, body, t, shift, duration, "LateralDistanceAction")
            if p["continuous"]:
                self.notes.append(f"{where}: continuous lateral distance of {action.actor!r} "
                                  f"set once at {t:g} s; later lateral moves of {p['ref']!r} "
                                  f"are not followed")
                return math.inf
            return duration
        raise AssertionError(action.kind)

    def _speed_duration(self, action: _Action, dyn: _Dynamics, v0: float,
                        target: float) -> float:
        if dyn.shape == "step":
            return 0.0
        if dyn.dimension == "time":
            return dyn.value
        if dyn.dimension == "rate":
            return abs(target - v0) * _SHAPES[dyn.shape][1] / dyn.value
        if v0 + target <= 0.0:
            raise action.el.error("a speed transition over a distance needs a speed > 0")
        # Every shape's mean over the transition is halfway: the distance sets the time.
        return 2.0 * dyn.value / (v0 + target)

    def _lateral_gap(self, body: _Body, ref: _Body, t: float) -> float:
        """How far left of ``body`` (where its lateral moves end) ``ref`` is at ``t``."""
        if ref is body:
            return 0.0
        motion = TrajectorySet([body.trajectory(), ref.trajectory()]).evaluate(
            np.array([t]), acceleration=False)
        gap = motion.position_m[0, 1] - motion.position_m[0, 0]
        return float(gap @ body.left()) - body.remaining_shift(t)

    def _time_to_travel(self, action: _Action, body: _Body, t: float, distance: float) -> float:
        start = body.travelled(t)
        horizon = t + 1.0
        while body.travelled(horizon) - start < distance:
            horizon = t + 2.0 * (horizon - t)
            if horizon - t > SEARCH_HORIZON_S:
                raise action.el.error(f"{action.actor!r} does not cover {distance:g} m within "
                                      f"{SEARCH_HORIZON_S:g} s of the action's start")
        return float(brentq(lambda x: body.travelled(x) - start - distance, t, horizon,
                            xtol=XTOL_S)) - t

    def _shift(self, action: _Action, body: _Body, t: float, shift: float, duration: float,
               shape: str) -> None:
        if abs(shift) < 1e-9:
            return
        where = f"{self.file}:{action.el.line}"
        shortest = lane_change_seconds(shift)
        if duration < shortest:
            # Faster than a scene's lane change may be sideways (as a speed step, which ramps
            # at the bound): the shortest one within it, centred on the shift's middle, so the
            # offset is the file's once both are over.
            start = max(0.0, t + duration / 2 - shortest / 2)
            body.lane_changes.append(LaneChange(start, shortest, shift))
            body.lane_change_sources.append(_source(action.el))
            what = "step" if duration < STEP_S else f"shift over {duration:.3f} s"
            self.notes.append(f"{where}: lateral {what} of {action.actor!r} ({shift:+.3f} m) "
                              f"played as the shortest quintic lane change within "
                              f"{MAX_ACCELERATION_MPS2:g} m/s2 sideways: {shortest:.3f} s from "
                              f"{start:.3f} s")
            return
        body.lane_changes.append(LaneChange(t, duration, shift))
        body.lane_change_sources.append(_source(action.el))
        self.notes.append(f"{where}: {shape} lateral shift of {action.actor!r} ({shift:+.3f} m "
                          f"over {duration:.3f} s from {t:.3f} s) played as the scene "
                          f"format's quintic lane change")

    # -- conditions ---------------------------------------------------------------------

    def _note_rising(self, trigger: list[list[_Condition]] | None, lower: float,
                     t: float) -> None:
        """Note a rising edge that fired at ``t`` because it was true from ``lower`` on."""
        for group in trigger or []:
            if max(self._condition_time(c, lower) for c in group) != t:
                continue
            for c in group:
                fired = self._condition_time(c, lower) - c.delay_s
                if c.rising and c.kind != "state" and abs(fired - lower) <= XTOL_S and \
                        self._true_at(c, lower):
                    self.notes.append(
                        f"{self.file}:{c.el.line}: condition {c.el.attrs.get('name', '')!r} "
                        f"(conditionEdge rising) is already true when its evaluation starts at "
                        f"{lower:g} s: fired then (a simulator may instead wait for it to turn "
                        f"false and true again)")

    def _true_at(self, cond: _Condition, t: float) -> bool:
        p = cond.params
        if cond.kind == "time":
            return bool(_RULES[p["rule"]](t, p["value"]))
        # A distance condition whose search finds it at ``t`` holds there.
        return True

    def _trigger_time(self, trigger: list[list[_Condition]] | None, lower: float) -> float:
        """First time from ``lower`` the trigger fires on the motion known now (inf: not now).

        Condition groups are OR-ed, conditions inside a group AND-ed: the latest of their first
        times, which holds for conditions that stay true once true (documented).
        """
        if not trigger:
            return lower
        return min(max(self._condition_time(c, lower) for c in group) for group in trigger)

    def _condition_time(self, cond: _Condition, lower: float) -> float:
        p = cond.params
        if cond.kind == "time":
            rule = _RULES[p["rule"]]
            if rule(lower, p["value"]):
                t = lower
            elif p["rule"] in ("greaterThan", "greaterOrEqual", "equalTo") and \
                    p["value"] >= lower:
                t = p["value"]
            elif p["rule"] == "notEqualTo":
                # False only at the instant its evaluation starts (the value): true right
                # after, the limit of the times it holds, as for greaterThan.
                t = lower
            else:
                t = math.inf
        elif cond.kind == "state":
            t = self._element_time(p["type"], p["ref"], p["end"])
            t = max(t, lower)
        else:
            times = [self._distance_time(p, who, lower) for who in p["triggering"]]
            t = max(times) if p["all"] else min(times)
        return t + cond.delay_s

    def _element_time(self, kind: str, name: str, end: bool) -> float:
        """When a storyboard element starts (or ends); inf while not known."""
        if kind == "action":
            times = self.action_times.get(name)
            return math.inf if times is None else times[end]
        if kind == "event":
            index = [i for i, e in enumerate(self.events) if e.name == name]
            table = self.event_end if end else self.event_start
            return min((table.get(i, math.inf) for i in index), default=math.inf)

        def inside(e: _Event) -> bool:
            return {"story": e.story, "act": self.acts[e.act].name,
                    "maneuverGroup": e.maneuver_group, "maneuver": e.maneuver}[kind] == name

        events = [i for i, e in enumerate(self.events) if inside(e)]
        if end:
            return max((self.event_end.get(i, math.inf) for i in events), default=math.inf)
        acts = [i for i, a in enumerate(self.acts)
                if (a.story if kind == "story" else a.name) == name] \
            if kind in ("story", "act") else [self.events[i].act for i in events]
        return min((self.act_start.get(a, math.inf) for a in acts), default=math.inf)

    def _distance_time(self, p: dict[str, Any], who: str, lower: float) -> float:
        """First time from ``lower`` the distance between ``who`` and the reference obeys."""
        body, ref = self.bodies[who], self.bodies[p["ref"]]
        rule, value = _RULES[p["rule"]], p["value"]
        sets = TrajectorySet([body.trajectory(), ref.trajectory()])

        def distance(t: np.ndarray) -> np.ndarray:
            pos = sets.evaluate(t, acceleration=False).position_m
            gap = pos[:, 1] - pos[:, 0]
            if p["type"] in ("cartesianDistance", "euclidianDistance"):
                return np.asarray(np.linalg.norm(gap, axis=-1))
            axis = np.array([1.0, 0.0, 0.0]) if p["type"] == "longitudinal" else \
                np.array([0.0, 1.0, 0.0])
            if not p["world"]:
                c, s = math.cos(body.heading_rad), math.sin(body.heading_rad)
                axis = np.array([c * axis[0] - s * axis[1], s * axis[0] + c * axis[1], 0.0])
            return np.asarray(np.abs(gap @ axis))

        step = SEARCH_STEP_S
        start = lower
        while start < SEARCH_HORIZON_S:
            grid = start + step * np.arange(20001)
            d = distance(grid)
            hit = np.flatnonzero(rule(d, value))
            if p["rule"] in ("equalTo",):
                hit = np.flatnonzero(np.diff(np.sign(d - value)) != 0)
                if np.any(d == value):
                    hit = np.union1d(hit, np.flatnonzero(d == value))
                if hit.size:
                    i = int(hit[0])
                    if d[i] == value:
                        return float(grid[i])
                    return float(brentq(lambda x: distance(np.array([x]))[0] - value,
                                        grid[i], grid[i + 1], xtol=XTOL_S))
            elif hit.size:
                i = int(hit[0])
                if i == 0:
                    return float(grid[0])
                # The rule turns true between grid[i-1] and grid[i], where the distance
                # passes the value: that instant (for a strict rule, the limit of its times).
                return float(brentq(lambda x: distance(np.array([x]))[0] - value,
                                    grid[i - 1], grid[i], xtol=XTOL_S))
            start = float(grid[-1])
        return math.inf

    # -- writing ------------------------------------------------------------------------

    def scene(self, name: str, duration_s: float, radar: str, rig: str,
              frame_rate_hz: float) -> dict[str, Any]:
        ego = self.bodies[self.ego]
        mount_x = DEFAULT_MOUNT_X_M
        if ego.center_m is not None and ego.size_m is not None:
            mount_x = float(ego.center_m[0] + ego.size_m[0] / 2.0)
        ego_spec: dict[str, Any] = {"motion": _motion(ego, 0.0)}
        self.sources = {"ego": _source(ego.el)}
        if ego.lane_changes:
            ego_spec["lane_changes"] = _lane_changes(ego)
            self.sources.update({f"ego.lane_changes[{i}]": where
                                 for i, where in enumerate(ego.lane_change_sources)})
        targets: list[dict[str, Any]] = []
        used: set[str] = set()
        for body in self.bodies.values():
            if body is ego:
                continue
            height = float(body.center_m[2]) if body.center_m is not None else \
                DEFAULT_HEIGHT_M.get(body.kind, 0.5)
            target: dict[str, Any] = {"name": self._target_name(body.name, used),
                                      "kind": body.kind, "motion": _motion(body, height)}
            at = f"targets[{len(targets)}]"
            self.sources[at] = _source(body.el)
            if body.lane_changes:
                target["lane_changes"] = _lane_changes(body)
                self.sources.update({f"{at}.lane_changes[{i}]": where
                                     for i, where in enumerate(body.lane_change_sources)})
            target["rcs"] = copy.deepcopy(RCS_MODELS[body.rcs_model])
            targets.append(target)
        source = self.description.strip().rstrip(".")
        description = (f"{source}. " if source else "") + f"Imported from {Path(self.file).name}."
        # A scene plays whole frames, each held a frame period: the last one covers the stop.
        n_frames = max(1, math.ceil(duration_s * frame_rate_hz - FRAME_SLACK))
        if abs(n_frames - duration_s * frame_rate_hz) > FRAME_SLACK:
            self.notes.append(f"{self.file}:{self.stop_el.line}: the storyboard stops at "
                              f"{duration_s:.6g} s, rounded up to {n_frames} frames at "
                              f"{frame_rate_hz:g} Hz: duration_s {n_frames / frame_rate_hz:g}")
        duration_s = n_frames / frame_rate_hz
        return {"rts_scenario": 1, "name": name, "description": description,
                "duration_s": _round(duration_s), "frame_rate_hz": frame_rate_hz,
                "radar": {"profile": radar,
                          "mount": {"x_m": _round(mount_x), "z_m": MOUNT_HEIGHT_M}},
                "rig": rig, "ego": ego_spec, "targets": targets}

    def _target_name(self, name: str, used: set[str]) -> str:
        clean = re.sub(r"[^A-Za-z0-9_.-]", "_", name) or "target"
        out, n = clean, 2
        while out in used:
            out, n = f"{clean}-{n}", n + 1
        used.add(out)
        if out != name:
            self.notes.append(f"entity {name!r} is target {out!r} (names allow letters, digits "
                              f"and _ . -)")
        return out


def _lanes(target: _El) -> float:
    lanes = target.number("value")
    if not lanes.is_integer():
        raise target.error(f"<{target.tag} value=\"{target.attrs['value']}\">: must be a whole "
                           f"number of lanes")
    return lanes


def _round(x: float) -> float:
    """Round away float noise (nanometres, nanoseconds) so the file reads well."""
    value = round(float(x), 9)
    return 0.0 if value == 0.0 else value


def _motion(body: _Body, height_m: float) -> dict[str, Any]:
    assert body.position_m is not None
    position = [_round(body.position_m[0]), _round(body.position_m[1]),
                _round(body.position_m[2] + height_m)]
    heading = _round(math.degrees(math.remainder(body.heading_rad, 2.0 * math.pi)))
    speeds = set(body.knots_mps)
    if len(speeds) == 1:
        speed = body.knots_mps[0]
        if speed == 0.0:
            return {"type": "stationary", "position_m": position, "heading_deg": heading}
        return {"type": "constant_velocity", "position_m": position, "heading_deg": heading,
                "speed_mps": _round(speed)}
    return {"type": "speed_profile", "position_m": position, "heading_deg": heading,
            "profile": [{"t_s": _round(t), "speed_mps": _round(v)}
                        for t, v in zip(body.knots_s, body.knots_mps, strict=True)]}


def _source(el: _El) -> tuple[str, int | None]:
    return el.tag, el.line


def _lane_changes(body: _Body) -> list[dict[str, float]]:
    return [{"start_s": _round(lc.start_s), "duration_s": _round(lc.duration_s),
             "offset_m": _round(lc.offset_m)} for lc in body.lane_changes]


# ---------------------------------------------------------------------------------- the entry

def _parse(path: Path) -> Any:
    try:
        from lxml import etree
    except ImportError:
        raise RtsError("import needs lxml: pip install 'rts-scenario[xosc]'") from None
    if not path.is_file():
        raise RtsError(f"{path}: {'is a folder' if path.is_dir() else 'file not found'}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise ScenarioError(f"file larger than {MAX_FILE_BYTES // (1024 * 1024)} MB",
                            file=str(path))
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             remove_comments=True, remove_pis=True, huge_tree=False)
    try:
        tree = etree.parse(str(path), parser)
    except etree.XMLSyntaxError as exc:
        line = exc.position[0] if exc.position else None
        message = re.sub(r",? line \d+(, column \d+)?\s*$", "", str(exc.msg))
        if "Excessive depth" in message:
            # libxml's own advice (an option of its parser) is none the user can take.
            raise ScenarioError(f"elements nested deeper than {MAX_XML_DEPTH} levels (import's "
                                f"limit, for any element, skipped ones included)",
                                file=str(path), line=line) from None
        raise ScenarioError(f"malformed XML: {message}", file=str(path), line=line) from None
    except OSError as exc:
        raise RtsError(f"{path}: cannot read: {exc}") from None
    # libxml2 expands internal entities in attribute values whatever the parser's options: a
    # value would then come from a declaration, not from where it stands. OpenSCENARIO files
    # declare none.
    dtd = tree.docinfo.internalDTD
    declared = [e.name for e in dtd.iterentities()] if dtd is not None else []
    if declared:
        raise ScenarioError(f"the DOCTYPE declares entities ({', '.join(declared)}), which "
                            f"are not supported: write their values where they are used",
                            file=str(path), line=1)
    return tree.getroot()


def import_xosc(path: str | Path, *, radar: str, rig: str, ego: str | None = None,
                parameters: dict[str, str] | None = None, name: str | None = None,
                frame_rate_hz: float = DEFAULT_FRAME_RATE_HZ,
                lane_width_m: float = DEFAULT_LANE_WIDTH_M) -> ImportResult:
    """Convert an OpenSCENARIO 1.x file (the subset in ``docs/import.md``) to a scene.

    Parameters
    ----------
    path : str or Path
        The ``.xosc`` file.
    radar, rig : str
        The scene's ``radar.profile`` and ``rig`` as written (preset names or paths relative to
        where the scene will be written).
    ego : str, optional
        The entity that carries the radar; default the entity named ``Ego`` (any case), else the
        first one.
    parameters : dict, optional
        Values overriding declared parameters, by name (with or without ``$``).
    name : str, optional
        The scene's name (default: the file's stem).
    frame_rate_hz, lane_width_m : float
        The scene's frame rate and the lane width for ``RelativeTargetLane``.

    Raises
    ------
    ScenarioError
        Located in the ``.xosc`` file (line) for anything outside the subset.
    RtsError
        For a bad argument (an unknown parameter or ego).
    """
    path = Path(path)
    file = str(path)
    raw = _parse(path)
    params = _parameters(raw, file, parameters or {})
    _substitute(raw, file, params)
    importer = _Importer(file, _El(file, raw, None), ego, lane_width_m)
    duration = importer.play()
    scene_name = name or path.name.removesuffix(".xosc")
    scene = importer.scene(scene_name, duration, radar, rig, frame_rate_hz)
    used = ", ".join(f"{p.name}={p.value}" + (" (--param)" if p.source == "--param" else "")
                     for p in params.values()) or "none declared"
    header = [f"Imported by rts-scenario import from {path.name} (OpenSCENARIO 1.x subset, "
              f"docs/import.md).",
              f"Parameters: {used}.",
              f"Ego (radar carrier): {importer.ego}; targets in world coordinates.",
              *(f"note: {n}" for n in importer.notes)]
    body = yaml.safe_dump(scene, sort_keys=False, default_flow_style=None, width=100,
                          allow_unicode=True)
    text = "".join(f"# {' '.join(line.split())}\n" for line in header) + body
    return ImportResult(text=text, scene=scene, parameters=params, ego=importer.ego,
                        notes=importer.notes, sources=importer.sources)
