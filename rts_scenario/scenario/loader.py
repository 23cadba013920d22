"""Load and check ``*.scenario.yaml`` files.

Safe YAML only; every node's line and column are kept; the JSON Schema in
``rts_scenario/data/scenario.schema.json`` rejects unknown keys, wrong types and out-of-range
values; then the checks the schema cannot express (times in order, distinct waypoints, unique
names, files inside the scene's folder tree). Every error is one `ScenarioError` reading
``file:line:col: key.path: message``.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import re
import unicodedata
from contextvars import ContextVar
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RtsError, ScenarioError
from ..file_kinds import kind_by_name, kind_name, load_kind, other_than_fragment
from ..located_yaml import Document, KeyPath, format_key_path, load_yaml, validate
from ..radar.angle import estimator_problem
from ..radar.profile import RadarProfile
from ..radar.profile import preset_names as radar_presets
from ..rig import Rig
from ..rig import preset_names as rig_presets
from ..suffixes import SCENE_SUFFIX
from .model import (
    DEFAULT_TOLERANCES,
    LIMITS,
    SCENE_LIMITS,
    Effects,
    Expectations,
    Mount,
    RadarOptions,
    RcsModel,
    Scenario,
    TargetSpec,
)
from .trajectory import (
    REVERSAL_DEG,
    LaneChange,
    Trajectory,
    TravelLaw,
    lane_change_ramp,
    reversal_waypoints,
)
from .trajectory import Path as TrajectoryPath

# What a run can stream and check in reasonable time and memory (a 24 h scene at 20 Hz with 28
# targets); the schema states it on duration_s and frame_rate_hz.
MAX_TARGET_FRAMES = 50_000_000
# The scene's frames, each held for its frame period, must play duration_s to within this share
# of a frame period: a duration written to a few decimals passes, half a frame more does not.
FRAME_SLACK = 1e-3


@lru_cache(maxsize=1)
def _shipped_schema() -> dict[str, Any]:
    """Return the shipped JSON Schema file as it is: the built-in estimators only."""
    text = resources.files("rts_scenario").joinpath("data/scenario.schema.json").read_text()
    schema: dict[str, Any] = json.loads(text)
    return schema


@lru_cache(maxsize=1)
def scenario_schema() -> dict[str, Any]:
    """Return the JSON Schema of scene files (also shipped for editors).

    ``radar.estimator`` admits the built-in estimators (the shipped file's enum) and any
    installed in the ``rts_scenario.estimators`` entry-point group.
    """
    from ..radar.angle import estimator_names

    schema = copy.deepcopy(_shipped_schema())
    estimator = schema["properties"]["radar"]["properties"]["estimator"]
    estimator["enum"] = [*estimator["enum"],
                         *(n for n in estimator_names() if n not in estimator["enum"])]
    return schema


def _schema_for(data: object) -> dict[str, Any]:
    """`scenario_schema`, or the shipped file's where it judges ``data`` the same.

    A scene whose ``radar.estimator`` is absent or built in is judged alike by both; only
    another value needs the installed estimators, whose look-up reads every installed
    package's entry points (tens of milliseconds at a command's start).
    """
    shipped = _shipped_schema()
    radar = data.get("radar") if isinstance(data, dict) else None
    if not isinstance(radar, dict) or "estimator" not in radar or radar["estimator"] in (
            shipped["properties"]["radar"]["properties"]["estimator"]["enum"]):
        return shipped
    return scenario_schema()


def _fragment_schema() -> dict[str, Any]:
    schema = _shipped_schema()
    return {"$ref": "#/$defs/fragment", "$defs": schema["$defs"]}


def load_scenario(path: str | Path, overrides: dict[str, Any] | None = None) -> Scenario:
    """Load, validate and compile a scene file.

    ``overrides`` replaces values by key path (``radar.estimator``, ``targets.0.rcs.rcs_dbsm``)
    before validation: one combination of the scene's ``parametrize`` block.

    Raises
    ------
    ScenarioError
        With file, line, column, key path, the offending value and what is allowed.
    """
    path = Path(path)
    doc = load_kind(path, ".scenario.yaml")
    if not isinstance(doc.data, dict):
        got = "an empty file" if doc.data is None else type(doc.data).__name__
        raise doc.error((), f"a scene must be a mapping of keys, got {got}")
    for dotted, value in (overrides or {}).items():
        _override(doc, dotted, value)
    effects_spec = doc.data.get("effects")
    if isinstance(effects_spec, dict) and "measurement_noise" in effects_spec:
        raise doc.error(("effects", "measurement_noise"),
                        "not supported; the simulated radar's noise comes from radar.noise")
    _check_target_limits(doc)
    validate(doc, _schema_for(doc.data), remember=not overrides)
    _check_scene_name(doc)
    _check_marks(doc)
    data = doc.data
    root = path.resolve().parent

    target_sources: list[tuple[Document, KeyPath, dict[str, Any]]] = []
    included: dict[Path, int] = {}
    for i, name in enumerate(data.get("include", [])):
        fragment_path = _inside(doc, ("include", i), root, name)
        if fragment_path in included:
            first = included[fragment_path]
            raise doc.error(("include", i),
                            f"{name!r} is included twice (first as include[{first}] "
                            f"{data['include'][first]!r}); include each fragment once")
        included[fragment_path] = i
        fragment = load_yaml(fragment_path)
        other = other_than_fragment(fragment_path, fragment.data)
        if other is not None:
            raise doc.error(("include", i), f"{name!r} is {other}")
        if not isinstance(fragment.data, dict):
            raise fragment.error((), "a fragment must be a mapping with a 'targets' list")
        _check_target_limits(fragment)
        validate(fragment, _fragment_schema())
        target_sources += [(fragment, ("targets", j), t)
                           for j, t in enumerate(fragment.data["targets"])]
    target_sources += [(doc, ("targets", j), t) for j, t in enumerate(data["targets"])]
    limits = data.get("expectations", {}).get("expected_limits", [])
    if target_sources and "nothing_checked" in limits:
        # Declared, it lets an empty bench pass on a radar that cannot fail its check: a scene
        # whose targets make something checkable has no such run.
        raise doc.error(("expectations", "expected_limits", limits.index("nothing_checked")),
                        "'nothing_checked' is for a scene without targets (an empty bench "
                        "played to the built-in simulated radar, which makes no false "
                        "detections); a scene with targets checks them")
    if not target_sources and "max_false_detections_per_frame" not in data.get(
            "expectations", {}):
        # A run of an empty bench checks only the radar's false detections: the scene says how
        # many it allows, so a scene that lost its targets by mistake does not pass as one.
        raise doc.error(("targets",),
                        "the scene has no targets (none here and none in an included "
                        "fragment): it can only test the radar's false detections on an empty "
                        "bench; to mean that, set expectations.max_false_detections_per_frame "
                        "(e.g. 0), else give at least one target")
    radar = _load_referenced(doc, ("radar", "profile"), root, data["radar"]["profile"],
                             radar_presets(), RadarProfile.preset, RadarProfile.from_file,
                             ".radar.yaml")
    estimator = data["radar"].get("estimator", "bartlett")
    if (problem := estimator_problem(estimator, radar.array)) is not None:
        # As bad input here (validate, any --method): the run would stop on it (exit 3).
        raise doc.error(("radar", "estimator") if "estimator" in data["radar"] else ("radar",),
                        problem)
    rig = _load_referenced(doc, ("rig",), root, data["rig"], rig_presets(), Rig.preset,
                           Rig.from_file, ".rig.yaml")
    effects = Effects(rcs_fluctuation=data.get("effects", {}).get("rcs_fluctuation", "none"))
    frames = _Frames(float(data["duration_s"]), float(data["frame_rate_hz"]))
    _check_frames(doc, frames)
    ego_spec = data.get("ego", {"motion": {"type": "stationary", "position_m": [0, 0, 0]}})
    ego = _trajectory(doc, ("ego",), ego_spec, frames)
    _ego_corners(doc, ego_spec["motion"], data["radar"].get("mount", {}))

    targets = []
    seen: dict[str, tuple[Document, KeyPath]] = {}
    for source, key, spec in target_sources:
        if spec["name"] in seen:
            first_doc, first_key = seen[spec["name"]]
            line = first_doc.marks.get((*first_key, "name"), (None,))[0]
            raise source.error(
                (*key, "name"),
                f"duplicate target name {spec['name']!r} (first used in {first_doc.file}"
                f"{f':{line}' if line else ''}); names must be unique",
            )
        seen[spec["name"]] = (source, key)
        targets.append(_target(source, key, spec, effects.rcs_fluctuation, frames))

    _check_size(doc, frames, len(targets))
    problem = radar.frame_rate_problem(frames.rate_hz, rig)
    if problem is not None:
        raise doc.error(("frame_rate_hz",), problem)
    expect = data.get("expectations", {})
    return Scenario(
        variant=variant_id(overrides or {}), parameters=dict(overrides or {}),
        name=data["name"], description=data.get("description", ""), file=str(path),
        duration_s=float(data["duration_s"]), frame_rate_hz=float(data["frame_rate_hz"]),
        seed=int(data.get("seed", 0)), radar=radar,
        mount=Mount(**data["radar"].get("mount", {})), rig=rig, ego=ego,
        targets=tuple(targets),
        expectations=Expectations(
            tolerances={**DEFAULT_TOLERANCES, **expect.get("tolerances", {})},
            detection_rate=float(expect.get("detection_rate", 0.9)),
            max_false_detections_per_frame=float(
                expect.get("max_false_detections_per_frame", 0.1)
            ),
            expected_limits=frozenset(expect.get("expected_limits", ())),
            # Which tolerances the scene means (a quantity a mapping leaves out fails on
            # those), as against the defaults it took.
            tolerances_written=frozenset(expect.get("tolerances", {})),
        ),
        effects=effects,
        marks=tuple(data.get("marks", [])),
        radar_options=_radar_options(data["radar"], empty=not target_sources),
    )


def _check_scene_name(doc: Document) -> None:
    """Refuse a scene name that is blank or holds characters that are not printed as such.

    The name heads the verdict lines (``PASS name (file)``), reports and pytest items: a line
    break in it would print a verdict line of its own, a terminal escape recolour the output.
    """
    name = doc.data["name"]
    if not name.strip():
        raise doc.error(("name",), f"got {name!r}, a blank name; a scene's name is one line of "
                                   f"printable text (e.g. cut-in)")
    for position, char in enumerate(name):
        if unicodedata.category(char) in ("Cc", "Cf", "Zl", "Zp"):
            raise doc.error(("name",), f"got {name!r}: the control character {char!r} at "
                                       f"position {position}; a scene's name is one line of "
                                       f"printable text (e.g. cut-in)")


# pytest's own marks that do something only with arguments, which a scene's marks cannot give:
# bare, pytest applies them as no-ops.
MARKS_NEEDING_ARGUMENTS = {
    "parametrize": "vary a scene with its parametrize block (scenarios/README.md, "
                   "Parametrization)",
    "usefixtures": "a scene's run uses no fixtures of the test suite",
    "filterwarnings": "filter warnings in the project's pytest configuration",
}
# The marks that change a scene's verdict: a misspelt one would silently run a scene meant to
# be skipped, or fail a suite on a failure the scene expects.
VERDICT_MARKS = ("skip", "skipif", "xfail")


def _near_miss(word: str, mark: str) -> bool:
    """Whether ``word`` looks like a misspelt ``mark``: close to it (difflib), or it in capitals.

    A letter left out, added or two swapped (``skp``, ``xfial``, ``skipp``) is close; a
    word one letter apart in the middle (``skid``, ``ship``) is not.
    """
    if word in VERDICT_MARKS:
        return False
    import difflib  # here: only a scene's marks are judged by it

    return word.lower() == mark or bool(
        difflib.get_close_matches(word.lower(), [mark], n=1, cutoff=NEAR_MISS_RATIO))


# difflib's ratio from which a mark is taken for a misspelt verdict mark (2 x letters in common
# over both lengths): skp/skip 0.86, xfial/xfail 0.80; skid/skip and ship/skip 0.75.
NEAR_MISS_RATIO = 0.8


def _check_marks(doc: Document) -> None:
    """Refuse marks that would silently do nothing, or not what they look like they do.

    pytest's marks that need arguments (bare, no-ops), and near misses of the marks that change
    a verdict (``skp``, ``xfial``): the plugin registers every scene mark, so pytest's
    ``--strict-markers`` cannot catch those.
    """
    for i, mark in enumerate(doc.data.get("marks", [])):
        if mark in MARKS_NEEDING_ARGUMENTS:
            raise doc.error(("marks", i),
                            f"{mark!r} is a pytest mark that needs arguments, which a scene's "
                            f"marks cannot give (bare, pytest ignores it); "
                            f"{MARKS_NEEDING_ARGUMENTS[mark]}")
        near = next((m for m in VERDICT_MARKS if _near_miss(mark, m)), None)
        if near is not None:
            raise doc.error(("marks", i),
                            f"{mark!r} looks like a misspelt {near!r}, which would then not "
                            f"apply; the marks that change a verdict are "
                            f"{', '.join(map(repr, VERDICT_MARKS))}: write {near!r}, or name "
                            f"the label so that it is not mistaken for one")


def _check_target_limits(doc: Document) -> None:
    """Refuse a limit of the whole scene in a target's ``expected_limits``.

    The verdict reads those from ``expectations.expected_limits`` alone: on a target one
    would be ignored.
    """
    targets = doc.data.get("targets") if isinstance(doc.data, dict) else None
    for j, target in enumerate(targets if isinstance(targets, list) else ()):
        limits = target.get("expected_limits") if isinstance(target, dict) else None
        for i, name in enumerate(limits if isinstance(limits, list) else ()):
            if isinstance(name, str) and name in SCENE_LIMITS:
                allowed = ", ".join(repr(n) for n in LIMITS if n not in SCENE_LIMITS)
                raise doc.error(("targets", j, "expected_limits", i),
                                f"{name!r} is a limit of the whole scene, not of one target: "
                                f"list it in expectations.expected_limits; a target's "
                                f"expected_limits allow {allowed}")


def _radar_options(radar: dict[str, Any], empty: bool) -> RadarOptions:
    options = {k: v for k, v in radar.items() if k in ("fidelity", "estimator", "cfar", "noise")}
    if empty and options.get("fidelity", "auto") == "auto":
        # False detections are all an empty bench checks, and only the cube has them.
        options["fidelity"] = "adc"
    return RadarOptions(**options)


def _check_frames(doc: Document, frames: _Frames) -> None:
    """Refuse frames that do not play the scene's duration.

    Frame f plays from ``f / frame_rate_hz`` for one frame period: the ``n`` frames play
    ``n / frame_rate_hz`` s. Where ``duration_s`` is not a whole number of frame periods (to
    within `FRAME_SLACK`), they would play longer or shorter than declared: a scene under one
    frame period long would hold its first frame, frozen, for the whole period.
    """
    periods = frames.duration_s * frames.rate_hz
    if abs(periods - frames.n) <= FRAME_SLACK:
        return
    rate, declared = frames.rate_hz, frames.duration_s
    period = 1.0 / rate
    played = frames.n * period
    counts = sorted({max(1, math.floor(periods)), max(1, math.ceil(periods))})

    def whole(n_periods: float) -> bool:
        return abs(n_periods - round(n_periods)) <= FRAME_SLACK and round(n_periods) >= 1

    durations = " or ".join(_shown(n * period, lambda d: whole(d * rate)) for n in counts)
    max_rate = _shipped_schema()["properties"]["frame_rate_hz"]["maximum"]
    # Only rates the schema takes: a duration of 1e-300 s has none.
    rates = " or ".join(_shown(n / declared, lambda r: whole(declared * r)) for n in counts
                        if n / declared <= max_rate)
    plural = "s" if frames.n > 1 else ""
    held = f"held {period:g} s each" if frames.n > 1 else f"held {period:g} s"
    if periods >= 1.0:
        key, hint = "duration_s", ""
    elif whole(declared / rate) and 1.0 / rate <= _shipped_schema()["properties"][
            "frame_rate_hz"]["maximum"]:
        key = "frame_rate_hz"
        hint = (f" (frame_rate_hz counts frames per second: if {rate:g} s is the frame period, "
                f"frame_rate_hz: {_shown(1.0 / rate, lambda r: whole(declared * r))})")
    elif rate < 1.0:  # frames held over a second each: the rate is the suspect
        key = "frame_rate_hz"
        hint = " (frame_rate_hz counts frames per second, the inverse of the frame period)"
    else:  # a usual rate, a duration shorter than one of its frames
        key, hint = "duration_s", ""
    raise doc.error(
        (key,),
        f"duration_s = {declared:g} s at frame_rate_hz = {rate:g} Hz is {periods:.6g} frame "
        f"periods, not a whole number of them: the scene would play {frames.n} frame{plural} "
        f"{held}, {played:g} s in all, not the {declared:g} s declared{hint}; the frames must "
        f"cover duration_s to within {FRAME_SLACK:g} of a frame period: e.g. duration_s: "
        f"{durations} ({' or '.join(map(str, counts))} frame{'s' if counts[-1] > 1 else ''})"
        + (f" or frame_rate_hz: {rates}" if rates else
           f" (no frame rate up to {max_rate:g} Hz plays {declared:g} s in whole frames)"),
    )


def _shown(value: float, fits: Any) -> str:
    """``value`` in as few digits (from 6) as keep ``fits(shown value)`` true."""
    return next((f"{value:.{d}g}" for d in range(6, 18) if fits(float(f"{value:.{d}g}"))),
                repr(value))


def _check_size(doc: Document, frames: _Frames, n_targets: int) -> None:
    """Refuse scenes with more target-frames than a run can stream (`MAX_TARGET_FRAMES`)."""
    n_frames = frames.n
    if n_frames * max(1, n_targets) > MAX_TARGET_FRAMES:
        raise doc.error(
            ("duration_s",),
            f"duration_s x frame_rate_hz = {frames.duration_s:g} s x {frames.rate_hz:g} Hz = "
            f"{n_frames:,} frames x {n_targets} targets = {n_frames * max(1, n_targets):,} "
            f"target-frames; "
            f"the limit is {MAX_TARGET_FRAMES:,} (shorten duration_s or lower frame_rate_hz)",
        )


# Combinations one scene file's parametrize block may give: each is a test, a run, loaded
# where it is collected.
MAX_COMBINATIONS = 100_000


def _key_part(part: str) -> str | int:
    """Return a key path's part: a list index where it is ASCII digits (not ``²``), else a key."""
    return int(part) if part.isascii() and part.isdigit() else part


def parametrizations(path: str | Path) -> list[tuple[str, dict[str, Any]]]:
    """List the scene's test combinations: ``(id, overrides)``; one ``("", {})`` if none.

    A key of the ``parametrize`` block is one key path, or several joined by commas that vary
    together (as in ``pytest.mark.parametrize("a,b", ...)``): each of its values is then a list
    with one value per path. The combinations are the product over the keys.
    """
    if Path(path).is_dir():  # `sweep DIR` and `pytest DIR` take one; a scene is a file
        raise ScenarioError(f"cannot read file: a folder, where a scene file goes "
                            f"({Path(path) / '*'}{SCENE_SUFFIX}); rts-scenario sweep and "
                            f"pytest take folders", file=str(path))
    # A file of another kind (a DBC, a rig) is named as such, not read as a broken scene.
    doc = load_kind(path, ".scenario.yaml")
    block = doc.data.get("parametrize") if isinstance(doc.data, dict) else None
    if not block:
        return [("", {})]
    # The file as written is none of the runs: what the block puts in place is judged in each
    # combination (`load_scenario`), so a placeholder there is no error of the file.
    placed = [tuple(_key_part(p) for p in path.strip().split("."))
              for key in block if isinstance(key, str) for path in key.split(",")
              ] if isinstance(block, dict) else []
    validate(doc, _schema_for(doc.data), skip=placed)
    for key, values in block.items():
        _check_plain(doc, ("parametrize", key), values)
    axes = [_parameter_axis(doc, key, values) for key, values in block.items()]
    # Each key path once: a second one silently took the place of the first's value. Paths
    # compare by their parts as the loader reads them (``targets.00`` is ``targets.0``).
    first_entry: dict[str, str] = {}
    parts: dict[str, tuple[str | int, ...]] = {}
    for key in block:
        for dotted in (p.strip() for p in key.split(",")):
            normal = tuple(_key_part(p) for p in dotted.split("."))
            same = next((d for d, n in parts.items() if n == normal), None)
            if same is not None:
                where = ("in the same entry" if first_entry[same] == key
                         else f"first in {first_entry[same]!r}")
                also = f" (as {same!r})" if same != dotted else ""
                raise doc.error(("parametrize", key),
                                f"{dotted}: a key path given twice{also} ({where}); each key "
                                f"path takes one value per run")
            first_entry[dotted] = key
            parts[dotted] = normal
    # A key path inside another: one's value replaces the part of the other's it lies in (or
    # is replaced by it), and the run is labelled with a value it may not play.
    for inner, inner_parts in parts.items():
        for outer, outer_parts in parts.items():
            if len(outer_parts) < len(inner_parts) and inner_parts[:len(outer_parts)] == \
                    outer_parts:
                entry = first_entry[outer]
                raise doc.error(("parametrize", first_entry[inner]),
                                f"{inner} lies inside the key path {outer!r}"
                                + (f" (in {entry!r})" if entry != outer else "")
                                + f" varied too: a run would take one's value in place of "
                                  f"the other's and be named after both; write the values "
                                  f"for {inner} into those of {outer}, or vary only key "
                                  f"paths inside it")
    count = math.prod(len(axis) for axis in axes)
    if count > MAX_COMBINATIONS:
        # Each is loaded where it is collected (a few ms): 10^8 hung a session without a word.
        raise doc.error(("parametrize",),
                        f"{count:,} combinations ({' x '.join(str(len(a)) for a in axes)}); at "
                        f"most {MAX_COMBINATIONS:,} in one scene file: split it into several "
                        f"files, or vary fewer keys together")
    combos: list[tuple[str, dict[str, Any]]] = []
    seen: dict[str, int] = {}
    values_seen: dict[str, int] = {}
    for choice in itertools.product(*axes):
        overrides = {path: value for group in choice for path, value in group}
        name = variant_id(overrides)
        if name in seen:
            # Runs are told apart by their id (pytest items, run reports, recorded logs).
            raise doc.error(("parametrize",),
                            f"combinations {seen[name] + 1} and {len(combos) + 1} have the same "
                            f"id {name!r}: list each value once; keys whose paths end alike "
                            f"need values that differ")
        seen[name] = len(combos)
        # 10 and 10.0 differ in their ids, not in what they play.
        played = repr({path: _number_value(value) for path, value in overrides.items()})
        if played in values_seen:
            before = values_seen[played]
            raise doc.error(("parametrize",),
                            f"combinations {before + 1} and {len(combos) + 1} "
                            f"({combos[before][0]!r} and {name!r}) play the same values: list "
                            f"each value once")
        values_seen[played] = len(combos)
        combos.append((name, overrides))
    return combos


# A mark pytest can take (the schema's pattern for ``marks``).
MARK_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def written_marks(data: Any, overrides: dict[str, Any]) -> tuple[str, ...]:
    """Return the marks a scene gives one of its combinations, read from its data as written.

    ``data`` is the scene file's YAML data and ``overrides`` the combination (a ``marks`` key
    path among them sets the marks as it does for `load_scenario`). For a scene that loads,
    these are its ``marks``; for one that does not, what selecting or skipping it by its marks
    goes by. Marks pytest could not take, and marks a broken file does not give, are left out
    (loading it reports what is wrong).
    """
    if not isinstance(data, dict):
        return ()
    # Only the marks, so that a sweep of many combinations does not copy whole scenes.
    marks_only = Document({"marks": copy.deepcopy(data.get("marks"))}, "", {})
    for key, value in overrides.items():
        if key.split(".", 1)[0] == "marks":
            try:
                _override(marks_only, key, value)
            except ScenarioError:
                return ()
    marks = marks_only.data.get("marks")
    if not isinstance(marks, list):
        return ()
    return tuple(m for m in marks if isinstance(m, str) and MARK_NAME.fullmatch(m))


def _number_value(value: Any) -> Any:
    """Return a number as the float it plays (bools and other values as they are)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        # An integer no float holds exactly stays itself: 2**60 and 2**60 + 1 differ.
        return float(value) if float(value) == value else value
    if isinstance(value, list):
        return [_number_value(v) for v in value]
    return value


def variant_id(overrides: dict[str, Any]) -> str:
    """Name a combination as the pytest plugin names its item: ``speed_mps=10.0-1=-0.5``.

    Each value by the last part of its key path, in the block's order; ``""`` for none.
    """
    return "-".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in overrides.items())


def select_variant(path: str | Path, variant: str | None, option: str = "--variant",
                   unnamed: str = "") -> tuple[str, dict[str, Any]]:
    """Return the combination ``(id, overrides)`` of the scene named ``variant``.

    For a command that plays or checks one run of a scene: a scene without ``parametrize``
    has the one combination ``("", {})``, taken when ``variant`` is None; a parametrized scene
    has no default (its file as written is none of its runs). ``unnamed`` says, in the error,
    where else the variant could have come from.

    Raises
    ------
    RtsError
        ``variant`` is None and the scene is parametrized, or it names no combination of the
        scene; the message lists the combinations to choose from.
    """
    combos = dict(parametrizations(path))
    if variant is None and list(combos) == [""]:
        return "", {}
    if variant is not None and variant in combos:
        return variant, combos[variant]
    if list(combos) == [""]:
        raise RtsError(f"{option} {variant}: {path} has no parametrize block, so no variants; "
                       f"leave {option} out")
    choices = ", ".join(combos)
    if variant is None:
        raise RtsError(f"{path}: a parametrized scene ({len(combos)} variants){unnamed}: choose "
                       f"one with {option} ID: {choices}")
    raise RtsError(f"{option} {variant}: not a variant of {path}; valid: {choices}")


def _check_plain(doc: Document, key: KeyPath, value: Any) -> None:
    """Refuse a value no report can hold: YAML's dates, timestamps, binary data.

    A run's ``parameters`` go into the JSON reports (``run --json``, ``sweep --json``).
    """
    if isinstance(value, list):
        for i, item in enumerate(value):
            _check_plain(doc, (*key, i), item)
    elif isinstance(value, dict):
        for k, item in value.items():
            _check_plain(doc, key, k)
            _check_plain(doc, (*key, k), item)
    elif value is not None and not isinstance(value, str | int | float):  # bool is an int
        kind = {"date": "a date", "datetime": "a timestamp", "bytes": "binary data"}.get(
            type(value).__name__, f"a {type(value).__name__}")
        raise doc.error(key, f"got {kind} ({value}); a value must be a string, a number, "
                             f"true, false, null, or a list or mapping of them (quote it: "
                             f"'{value}')")


def _parameter_axis(doc: Document, key: str,
                    values: list[Any]) -> list[list[tuple[str, Any]]]:
    """One axis of the product: per value, the (key path, value) pairs it sets."""
    paths = [p.strip() for p in key.split(",")]
    if len(paths) > 1 and not all(paths):
        raise doc.error(("parametrize", key),
                        f"{key!r}: an empty key path between commas; write 'a.b, c.d'")
    if not all(paths) or any(not part for path in paths for part in path.split(".")):
        raise doc.error(("parametrize", key),
                        f"{key!r}: an empty key path, or an empty part between dots; write a "
                        f"key path such as 'radar.estimator' or 'targets.0.rcs.rcs_dbsm'")
    if len(paths) == 1:
        return [[(key, value)] for value in values]
    axis = []
    for i, value in enumerate(values):
        if not isinstance(value, list) or len(value) != len(paths):
            raise doc.error(
                ("parametrize", key, i),
                f"needs a list of {len(paths)} values (one per key path: {', '.join(paths)}), "
                f"got {value!r}",
            )
        axis.append(list(zip(paths, value, strict=True)))
    return axis


def _override(doc: Document, key: str, value: Any) -> None:
    parts: list[str | int] = [_key_part(p) for p in key.split(".")]
    # The parametrize block's entry that gives the key path: an error in it points there.
    block = doc.data.get("parametrize")
    entry = next((k for k in (block if isinstance(block, dict) else {})
                  if key in (p.strip() for p in k.split(","))), None)
    at: KeyPath = ("parametrize", entry) if entry is not None else ("parametrize",)
    node: Any = doc.data
    for i, part in enumerate(parts[:-1]):
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            raise doc.error(at, f"{key}: no such key path in the scene (at "
                                f"{'.'.join(map(str, parts[: i + 1]))})") from None
    try:
        node[parts[-1]] = value
    except (IndexError, TypeError):
        raise doc.error(at, f"{key}: no such key path in the scene") from None
    # The value now there is the parametrize block's: an error in it points at its entry.
    where = doc.marks.get(at)
    if where is not None:
        path = tuple(parts)
        for old in [m for m in doc.marks if m[:len(path)] == path]:
            del doc.marks[old]
        doc.marks[path] = where


# While `scene_files` loads a scene: the files its references resolve to, in order.
_READING: ContextVar[list[Path] | None] = ContextVar("_READING", default=None)


def scene_files(path: str | Path, overrides: dict[str, Any] | None = None) -> list[Path]:
    """Return the files loading the scene reads besides itself: fragments, rig, radar profile.

    Those it gets to: a scene that does not load gives the ones before its error (the error
    is the caller's to meet when it loads the scene itself). A command checks its outputs
    against them before it writes anything: an output that is one of them (a link, a hard
    link) would destroy what the scene is made of.
    """
    found: list[Path] = []
    token = _READING.set(found)
    try:
        load_scenario(path, overrides)
    except Exception:  # noqa: BLE001 - reported where the command loads the scene
        pass
    finally:
        _READING.reset(token)
    return list(dict.fromkeys(found))


def _inside(doc: Document, key: KeyPath, root: Path, name: str) -> Path:
    """Resolve a relative file reference; refuse anything outside the scene's folder tree."""
    candidate = Path(name)
    if candidate.is_absolute():
        raise doc.error(key, f"must be a path relative to the scene's folder, got {name!r}")
    resolved = (root / candidate).resolve()
    if not resolved.is_relative_to(root):
        raise doc.error(
            key, f"{name!r} leaves the scene's folder tree ({root}); files must stay inside it"
        )
    if resolved.is_dir():
        raise doc.error(key, f"{name!r} is a folder; name a file in it")
    if not resolved.is_file():
        raise doc.error(key, f"file not found: {name!r} (looked in {root})")
    reading = _READING.get()
    if reading is not None:
        reading.append(resolved)
    return resolved


def _load_referenced(doc: Document, key: KeyPath, root: Path, name: str, presets: list[str],
                     preset: Any, from_file: Any, suffix: str) -> Any:
    if name in presets:
        return preset(name)
    # A file named as another kind is refused as such.
    other = kind_by_name(name)
    if other is not None and other != suffix:
        raise doc.error(key, f"{name!r} is {kind_name(other)} (*{other}); "
                             f"{format_key_path(key)} takes a preset ({', '.join(presets)}) "
                             f"or a *{suffix} file")
    # A name that is no preset is a file when it looks like one or one exists by that name.
    looks_like_file = name.endswith((suffix, ".yaml", ".yml")) or "/" in name
    if not looks_like_file and not (root / name).is_file():
        raise doc.error(
            key, f"unknown preset {name!r}; valid presets: {', '.join(presets)}, or a relative "
                 f"path to a *{suffix} file",
        )
    stem = name.removesuffix(suffix)
    if stem != name and stem in presets and not (root / name).is_file():
        raise doc.error(key, f"file not found: {name!r} (looked in {root}); the preset {stem!r} "
                             f"is named without {suffix}: {format_key_path(key)}: {stem}")
    resolved = _inside(doc, key, root, name)
    try:
        return from_file(resolved)
    except ScenarioError as exc:
        if exc.line is not None:  # located in the file itself
            raise
        # About the whole file (another kind of file, unreadable, empty): the scene's key
        # that names it is where to look.
        named_first = exc.detail.startswith(f"{resolved} ")
        raise doc.error(key, f"{name!r}{exc.detail[len(str(resolved)):]}" if named_first
                        else f"{name}: {exc.detail}") from None
    except RtsError as exc:
        raise doc.error(key, f"{name}: {exc}") from None


class _Frames:
    """The scene's frame times, ``f / frame_rate_hz`` for ``f < n``, as the kinematics uses them."""

    def __init__(self, duration_s: float, frame_rate_hz: float) -> None:
        self.duration_s = duration_s
        self.rate_hz = frame_rate_hz
        self.n = max(1, int(round(duration_s * frame_rate_hz)))

    @property
    def last_s(self) -> float:
        return (self.n - 1) / self.rate_hz

    def first_at_or_after(self, t_s: float) -> int:
        """Index of the first frame at or after ``t_s`` (may be ``n``: none)."""
        f = max(0, math.ceil(t_s * self.rate_hz))
        # The product rounds: step to the exact boundary the kinematics' comparison draws.
        while f > 0 and (f - 1) / self.rate_hz >= t_s:
            f -= 1
        while f / self.rate_hz < t_s:
            f += 1
        return f

    def describe(self) -> str:
        return f"duration_s = {self.duration_s:g} s at {self.rate_hz:g} Hz"

    def describe_end(self) -> str:
        return f"the scene's last frame at {self.last_s:g} s ({self.describe()})"


def _target(doc: Document, key: KeyPath, spec: dict[str, Any], default_fluct: str,
            frames: _Frames) -> TargetSpec:
    appear = float(spec.get("appear_s", 0.0))
    disappear = float(spec.get("disappear_s", np.inf))
    if disappear <= appear:
        raise doc.error((*key, "disappear_s"),
                        f"must be later than appear_s = {appear:g}, got {disappear:g}")
    # A target present in no frame has nothing to check and would pass with 0 frames.
    first = frames.first_at_or_after(appear)
    if first >= frames.n:
        raise doc.error((*key, "appear_s"),
                        f"the target appears at {appear:g} s, after {frames.describe_end()}: "
                        f"it would be present in no "
                        f"frame and nothing could be checked; appear_s must be <= "
                        f"{frames.last_s:g}")
    if first / frames.rate_hz >= disappear:
        raise doc.error((*key, "disappear_s"),
                        f"no frame falls between appear_s = {appear:g} s and disappear_s = "
                        f"{disappear:g} s (frames every {1 / frames.rate_hz:g} s, the first "
                        f"after appear_s at {first / frames.rate_hz:g} s): the target would be "
                        f"present in no frame and nothing could be checked")
    frame = spec.get("frame", "world")
    return TargetSpec(
        name=spec["name"], kind=spec.get("kind", "other"), frame=frame,
        trajectory=_trajectory(doc, key, spec, frames),
        rcs=_rcs(doc, (*key, "rcs"), spec["rcs"], default_fluct),
        appear_s=appear, disappear_s=disappear,
        expected_limits=frozenset(spec.get("expected_limits", ())),
    )


def _rcs(doc: Document, key: KeyPath, spec: dict[str, Any], default_fluct: str) -> RcsModel:
    values = spec["rcs_dbsm"]
    aspects = spec.get("aspect_deg")
    fluctuation = spec.get("fluctuation", default_fluct)
    if isinstance(values, list) != (aspects is not None):
        raise doc.error(
            key, "an RCS table needs both aspect_deg (list) and rcs_dbsm (list of the same "
                 "length); a constant RCS gives rcs_dbsm alone",
        )
    if aspects is None:
        return RcsModel(rcs_dbsm=np.array([float(values)]), fluctuation=fluctuation)
    if len(aspects) != len(values):
        raise doc.error((*key, "rcs_dbsm"),
                        f"needs one value per aspect_deg entry ({len(aspects)}), got "
                        f"{len(values)}")
    wrapped = np.mod(np.asarray(aspects, dtype=float), 360.0)
    if np.unique(np.round(wrapped, 9)).size != wrapped.size:
        raise doc.error((*key, "aspect_deg"),
                        f"aspect angles must be distinct modulo 360 deg, got {aspects}")
    order = np.argsort(wrapped)
    return RcsModel(rcs_dbsm=np.asarray(values, dtype=float)[order], aspect_deg=wrapped[order],
                    fluctuation=fluctuation)


def _trajectory(doc: Document, key: KeyPath, spec: dict[str, Any],
                frames: _Frames) -> Trajectory:
    motion = spec["motion"]
    mkey = (*key, "motion")
    kind = motion["type"]
    for i, lc in enumerate(spec.get("lane_changes", [])):
        _starts_in_scene(doc, (*key, "lane_changes", i, "start_s"), float(lc["start_s"]),
                         frames, "the lane change starts", "it would never happen")
        _check_sideways(doc, (*key, "lane_changes", i), float(lc["offset_m"]),
                        float(lc["duration_s"]))
    lane_changes = tuple(
        LaneChange(float(lc["start_s"]), float(lc["duration_s"]), float(lc["offset_m"]))
        for lc in spec.get("lane_changes", [])
    )
    _check_sideways_together(doc, (*key, "lane_changes"), lane_changes)
    if kind == "waypoints":
        trajectory = _waypoints(doc, mkey, motion, lane_changes, frames)
        if key == ("ego",):
            _check_ego_moves_while_changing_lanes(doc, key, trajectory)
        return trajectory
    start = np.asarray(motion["position_m"], dtype=float)
    path = TrajectoryPath.line(start, np.radians(motion.get("heading_deg", 0.0)))
    if kind == "stationary":
        law = TravelLaw.pieces([0.0], [0.0], [0.0])
    elif kind == "constant_velocity":
        law = TravelLaw.pieces([0.0], [motion["speed_mps"]], [0.0])
    elif kind == "constant_acceleration":
        v0, a = float(motion["speed_mps"]), float(motion["acceleration_mps2"])
        if a * v0 < 0.0:  # braking, forwards or backwards: stops, never turns back
            law = TravelLaw.pieces([0.0, v0 / -a], [v0, 0.0], [a, 0.0])
        else:  # from standstill it drives off forwards; braking there, it stands
            law = TravelLaw.pieces([0.0], [v0], [max(a, 0.0) if v0 == 0.0 else a])
    else:  # speed_profile
        law = _speed_profile(doc, (*mkey, "profile"), motion["profile"])
    who = f"target {spec['name']!r}" if "name" in spec else "the ego"
    # A target is held to the limit while present: up to its last frame before disappear_s.
    disappear = float(spec.get("disappear_s", np.inf))
    gone = frames.first_at_or_after(disappear) if disappear < frames.last_s else frames.n
    until = (gone - 1) / frames.rate_hz if gone < frames.n else None
    _check_speed(doc, (*mkey, "acceleration_mps2") if "acceleration_mps2" in motion else mkey,
                 law, frames, who, until)
    trajectory = Trajectory(path=path, law=law, lane_changes=lane_changes)
    if key == ("ego",):
        _check_ego_moves_while_changing_lanes(doc, key, trajectory)
    return trajectory


def _check_ego_moves_while_changing_lanes(doc: Document, key: KeyPath,
                                          trajectory: Trajectory) -> None:
    """Refuse an ego lane change during which the ego stands or turns from forwards to back.

    The ego's body (and the radar on it) faces its motion. A lane change of an ego that
    stands along its path would turn it to face sideways, and where its speed along the path
    reaches 0 the body would flip between facing its motion and its back (driving backwards)
    on rounding: the radar's heading would jump by 90 to 180 deg between frames. A car cannot
    move sideways while it stands. The speed along the path is linear between the travel
    law's knots, so it reaches 0 within a lane change exactly where it is <= 0 at one of
    them or at an end and >= 0 at another.
    """
    law = trajectory.law
    for i, change in enumerate(trajectory.lane_changes):
        t0, t1 = change.start_s, change.start_s + change.duration_s
        times = np.sort([t0, t1, *law.knots_s[(law.knots_s > t0) & (law.knots_s < t1)]])
        piece = np.searchsorted(law.knots_s, times, side="right") - 1
        speed = law.v0_mps[piece] + law.a_mps2[piece] * (times - law.knots_s[piece])
        if speed.min() <= 0.0 <= speed.max():
            # The first 0: at a sample, or between two (one piece: linear there).
            sign = np.sign(speed)
            j = int(np.flatnonzero((sign == 0) | (sign != sign[0]))[0])
            at = float(times[j]) if sign[j] == 0 or j == 0 else float(
                times[j - 1] + (times[j] - times[j - 1]) * speed[j - 1]
                / (speed[j - 1] - speed[j]))
            raise doc.error((*key, "lane_changes", i),
                            f"the ego's speed along its path is 0 at {at:g} s, during this "
                            f"lane change ({t0:g} to {t1:g} s): the ego (and the radar on it) "
                            f"faces its motion, and standing it would face sideways or flip "
                            f"between frames; a car cannot move sideways while it stands: end "
                            f"the lane change before the ego stops, or start it once it moves")


# Speeds along a path run from -MAX_SPEED_MPS to MAX_SPEED_MPS (the schema's bound on each
# speed given; the loader holds a motion's every speed within the scene to it).
MAX_SPEED_MPS = 150.0
# Accelerations along a path run from -MAX_ACCELERATION_MPS2 to MAX_ACCELERATION_MPS2 (the
# schema's bound on acceleration_mps2; the loader holds the accelerations a speed profile's or
# the waypoints' speeds imply to it): beyond any road vehicle's braking, and a speed jump
# written by mistake (a time or a distance a thousand times too short) shows as one.
MAX_ACCELERATION_MPS2 = 15.0
# Peak of the lane change's quintic ramp's second derivative, 10 / sqrt(3) at tau = (3 -
# sqrt(3)) / 6: its sideways acceleration peaks at this times offset / duration^2.
LANE_CHANGE_PEAK = 10.0 / math.sqrt(3.0)


def lane_change_seconds(offset_m: float) -> float:
    """Shortest lane change of ``offset_m`` within `MAX_ACCELERATION_MPS2` sideways (s)."""
    return math.sqrt(LANE_CHANGE_PEAK * abs(offset_m) / MAX_ACCELERATION_MPS2)


def _check_acceleration(doc: Document, key: KeyPath, acceleration_mps2: float,
                        implied_by: str) -> None:
    """Refuse an acceleration ``implied_by`` (words) beyond +-`MAX_ACCELERATION_MPS2`."""
    # A hair over the bound: an acceleration of exactly 15 m/s2 computed from speeds and
    # times written to a few decimals may round above it.
    if abs(acceleration_mps2) <= MAX_ACCELERATION_MPS2 * (1.0 + 1e-6):
        return
    raise doc.error(key, f"{implied_by} is an acceleration of {acceleration_mps2:.6g} m/s2; "
                         f"accelerations run from {-MAX_ACCELERATION_MPS2:g} to "
                         f"{MAX_ACCELERATION_MPS2:g} m/s2 (as acceleration_mps2 of "
                         f"constant_acceleration)")


def _check_sideways(doc: Document, key: KeyPath, offset_m: float, duration_s: float) -> None:
    """Refuse a lane change whose peak sideways acceleration is beyond `MAX_ACCELERATION_MPS2`.

    The quintic's peak is `LANE_CHANGE_PEAK` times ``offset / duration^2`` (the same bound as
    along the path: a 3.5 m change takes 1.16 s at least).
    """
    peak = LANE_CHANGE_PEAK * abs(offset_m) / duration_s**2 if duration_s > 0 else math.inf
    if peak <= MAX_ACCELERATION_MPS2 * (1.0 + 1e-6):
        return
    shortest = lane_change_seconds(offset_m)
    raise doc.error((*key, "duration_s"),
                    f"a lane change of {offset_m:g} m in {duration_s:g} s is a sideways "
                    f"acceleration of up to {peak:.6g} m/s2; accelerations run from "
                    f"{-MAX_ACCELERATION_MPS2:g} to {MAX_ACCELERATION_MPS2:g} m/s2 (as "
                    f"acceleration_mps2 of constant_acceleration): give duration_s >= "
                    f"{math.ceil(shortest * 1000) / 1000:g} s, or a smaller offset_m")


def _check_sideways_together(doc: Document, key: KeyPath,
                             changes: tuple[LaneChange, ...]) -> None:
    """Refuse lane changes that overlap in time beyond `MAX_ACCELERATION_MPS2` together.

    Each is held to the bound alone (`_check_sideways`); where they overlap their sideways
    accelerations add. Between the starts and ends of the changes the sum is one cubic in
    time, whose largest magnitude is at an end of the piece or where its derivative is 0:
    exact, not sampled.
    """
    if len(changes) < 2:
        return
    ends = sorted({t for c in changes for t in (c.start_s, c.start_s + c.duration_s)})
    for a, b in itertools.pairwise(ends):
        active = [i for i, c in enumerate(changes)
                  if c.start_s <= a and c.start_s + c.duration_s >= b]
        if len(active) < 2:
            continue
        from numpy.polynomial import Polynomial  # here: 2 ms of a command's start, rarely used

        total = Polynomial([0.0])
        for i in active:
            c = changes[i]
            tau = Polynomial([-c.start_s / c.duration_s, 1.0 / c.duration_s])
            total += c.offset_m / c.duration_s**2 * (60 * tau - 180 * tau**2 + 120 * tau**3)
        roots = np.asarray(total.deriv().roots(), dtype=complex)
        inner = roots.real[(np.abs(roots.imag) < 1e-12) & (roots.real > a) & (roots.real < b)]
        times = [a, b, *inner.tolist()]
        values = np.abs(total(np.array(times)))
        peak = float(values.max())
        if peak <= MAX_ACCELERATION_MPS2 * (1.0 + 1e-6):
            continue
        at = times[int(values.argmax())]
        which = " and ".join(f"lane_changes[{i}]" for i in active)
        raise doc.error(key, f"{which} overlap in time: together they accelerate sideways up "
                             f"to {peak:.6g} m/s2 (at {at:.6g} s); accelerations run from "
                             f"{-MAX_ACCELERATION_MPS2:g} to {MAX_ACCELERATION_MPS2:g} m/s2 "
                             f"(as acceleration_mps2 of constant_acceleration): start one after "
                             f"the other ends, or make them longer")


def _check_speed(doc: Document, key: KeyPath, law: TravelLaw, frames: _Frames,
                 who: str, until_s: float | None = None) -> None:
    """Refuse a motion whose speed leaves +-`MAX_SPEED_MPS` by the scene's last frame.

    ``until_s``: the last frame of a target that disappears before the scene's last (None:
    the scene's). The speed is linear in time on each piece of ``law``: it peaks at a piece's
    ends.
    """
    last_s = frames.last_s if until_s is None else until_s
    starts = law.knots_s
    ends = np.minimum(np.append(starts[1:], np.inf), last_s)
    within = starts <= last_s
    end_speed = law.v0_mps + law.a_mps2 * np.maximum(ends - starts, 0.0)
    over = within & (np.abs(end_speed) > MAX_SPEED_MPS * (1.0 + 1e-12))
    if not over.any():
        return
    k = int(np.argmax(over))
    v0, a = float(law.v0_mps[k]), float(law.a_mps2[k])
    limit = math.copysign(MAX_SPEED_MPS, end_speed[k])
    at_s = float(starts[k]) + (limit - v0) / a
    end = (frames.describe_end() if until_s is None else
           f"its last frame at {until_s:g} s (disappear_s; {frames.describe()})")
    raise doc.error(key, f"{who} reaches {limit:g} m/s at {at_s:.6g} s ({a:g} m/s2 from "
                         f"{v0:g} m/s), before {end}: speeds run from {-MAX_SPEED_MPS:g} to "
                         f"{MAX_SPEED_MPS:g} m/s; accelerate less, or "
                         + ("end the scene" if until_s is None else "let it disappear")
                         + " before the speed leaves them")


def _speed_profile(doc: Document, key: KeyPath, profile: list[dict[str, float]]) -> TravelLaw:
    times = [float(p["t_s"]) for p in profile]
    speeds = [float(p["speed_mps"]) for p in profile]
    for i in range(1, len(times)):
        if times[i] <= times[i - 1]:
            raise doc.error((*key, i, "t_s"),
                            f"times must increase, got {times[i]:g} after {times[i - 1]:g}")
        _check_acceleration(
            doc, (*key, i),
            (speeds[i] - speeds[i - 1]) / (times[i] - times[i - 1]),
            f"from profile[{i - 1}] to profile[{i}] the speed goes from {speeds[i - 1]:g} to "
            f"{speeds[i]:g} m/s in {times[i] - times[i - 1]:.6g} s: that")
    return TravelLaw.speed_profile(times, speeds)


def _starts_in_scene(doc: Document, key: KeyPath, start_s: float, frames: _Frames, what: str,
                     outcome: str) -> None:
    """Refuse a change of motion that starts at the last frame or later.

    Frames sample the motion: such a change would show in none of them.
    """
    if start_s >= frames.last_s:
        raise doc.error(key, f"{what} at {start_s:g} s, at or after {frames.describe_end()}: "
                             f"{outcome}; start_s must be < {frames.last_s:g}")


# A lateral offset may jump at most this far where a polyline turns (m).
CORNER_JUMP_M = 0.01


def _corner_offset(doc: Document, key: KeyPath, points: np.ndarray, t_s: float,
                   lane_changes: tuple[LaneChange, ...]) -> None:
    """Refuse a lateral offset where a polyline turns (at ``points[1]``, reached at ``t_s``).

    The object turns in no time there, and its left normal with it: a point ``d`` to the
    left of the path would jump ``2 |d| sin(angle / 2)``.
    """
    changes = np.array([(lc.offset_m, lc.start_s, lc.duration_s) for lc in lane_changes],
                       dtype=np.float64).reshape(-1, 3)
    offset = float(changes[:, 0] @ lane_change_ramp((t_s - changes[:, 1]) / changes[:, 2]))
    before, after = np.diff(points[:, :2], axis=0)
    norms = np.linalg.norm(before), np.linalg.norm(after)
    if min(norms) < 1e-9 or offset == 0.0:  # a vertical piece has no left to turn
        return
    cos = float(np.clip(np.dot(before, after) / (norms[0] * norms[1]), -1.0, 1.0))
    angle = math.acos(cos)
    jump = 2.0 * abs(offset) * math.sin(0.5 * angle)
    if jump > CORNER_JUMP_M:
        side = "left" if offset > 0 else "right"
        raise doc.error(key, f"the path turns {math.degrees(angle):.3g} deg at this waypoint "
                             f"(at {t_s:.6g} s) while the object is {abs(offset):.3g} m to the "
                             f"{side} of it (lane_changes): a polyline turns in no time, so the "
                             f"object would jump {jump:.3g} m; use path: spline, or end the "
                             f"lateral offset before the corner")


# The ego's path may turn at most this far where a polyline turns (deg): its radar turns with it.
EGO_CORNER_DEG = 0.01


def _ego_corners(doc: Document, motion: dict[str, Any], mount: dict[str, float]) -> None:
    """Refuse an ego polyline that turns at a waypoint: its radar would turn in no time."""
    if motion["type"] != "waypoints" or motion.get("path", "polyline") != "polyline":
        return
    points = np.array([p["position_m"] for p in motion["points"]], dtype=float)[:, :2]
    chords = np.diff(points, axis=0)
    lengths = np.linalg.norm(chords, axis=1)
    for i in range(len(chords)):
        if lengths[i] < 1e-9:  # straight up or down: no heading, the body would face x
            raise doc.error(
                ("ego", "motion", "points", i + 1, "position_m"),
                "the ego's path runs straight up or down from the waypoint before: it has no "
                "heading there (its radar would face the world's x axis); give the waypoints a "
                "horizontal distance")
        if i == 0:
            continue
        cos = float(np.clip(chords[i - 1] @ chords[i] / (lengths[i - 1] * lengths[i]), -1, 1))
        angle = math.degrees(math.acos(cos))
        if angle > EGO_CORNER_DEG:
            lever = math.hypot(float(mount.get("x_m", 0.0)), float(mount.get("y_m", 0.0)))
            jump = 2.0 * lever * math.sin(math.radians(angle) / 2.0)
            raise doc.error(
                ("ego", "motion", "points", i, "position_m"),
                f"the ego's path turns {angle:.3g} deg at this waypoint: a polyline turns in no "
                f"time, and the radar with it, so every target's azimuth would jump "
                f"{angle:.3g} deg between two frames"
                + (f" and the radar ({lever:.3g} m from the ego's reference point) {jump:.3g} m"
                   f" sideways" if jump >= 0.001 else "")
                + f"; use path: spline (the ego's path may turn at most {EGO_CORNER_DEG:g} deg "
                  f"at a polyline's waypoint)")


def _waypoints(doc: Document, key: KeyPath, motion: dict[str, Any],
               lane_changes: tuple[LaneChange, ...], frames: _Frames) -> Trajectory:
    start = float(motion.get("start_s", 0.0))
    _starts_in_scene(doc, (*key, "start_s"), start, frames,
                     "the object would start along its waypoints",
                     "it would stand at its first waypoint throughout")
    points = np.array([p["position_m"] for p in motion["points"]], dtype=float)
    speeds = [float(p["speed_mps"]) for p in motion["points"]]
    gaps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    for i, gap in enumerate(gaps):
        if gap < 1e-6:
            raise doc.error((*key, "points", i + 1, "position_m"),
                            f"repeats waypoint {i}; consecutive waypoints must differ")
        if speeds[i] == 0.0 and speeds[i + 1] == 0.0:
            raise doc.error((*key, "points", i + 1, "speed_mps"),
                            f"waypoints {i} and {i + 1} both have speed 0: the object would "
                            f"never get from one to the other (to stop at both, add a waypoint "
                            f"between them with a speed above 0)")
    if motion.get("path", "polyline") == "spline":
        for i in reversal_waypoints(points):
            if speeds[i] != 0.0:
                before, after = points[i] - points[i - 1], points[i + 1] - points[i]
                cos = before @ after / (np.linalg.norm(before) * np.linalg.norm(after))
                angle = math.degrees(math.acos(max(-1.0, float(cos))))
                # As many digits as show the turn beyond the limit (90.000001, not 90).
                shown = next((f"{angle:.{d}g}" for d in range(3, 17)
                              if float(f"{angle:.{d}g}") > REVERSAL_DEG), f"{angle!r}")
                raise doc.error(
                    (*key, "points", i, "speed_mps"),
                    f"the path reverses at this waypoint (it turns {shown} deg, more than "
                    f"{REVERSAL_DEG:g} deg): a spline path has a cusp there, where the object "
                    f"stops and backs out; speed_mps must be 0 here, got {speeds[i]:g} (to "
                    f"drive round the turn instead, add waypoints that turn by at most "
                    f"{REVERSAL_DEG:g} deg each)")
        path, at_points = TrajectoryPath.spline(points)
    else:
        path = TrajectoryPath.polyline(points)
        at_points = path.arc_m
    lengths = np.diff(at_points)
    knots, v0, acc = ([0.0], [0.0], [0.0]) if start > 0.0 else ([], [], [])
    t = start
    for i, length in enumerate(lengths):
        a = (speeds[i + 1] ** 2 - speeds[i] ** 2) / (2.0 * length)
        _check_acceleration(
            doc, (*key, "points", i + 1),
            a, f"from waypoint {i} to waypoint {i + 1} the speed goes from {speeds[i]:g} to "
               f"{speeds[i + 1]:g} m/s over {length:.6g} m of path: that")
        if i > 0 and motion.get("path", "polyline") == "polyline":
            _corner_offset(doc, (*key, "points", i, "position_m"), points[i - 1: i + 2], t,
                           lane_changes)
        knots.append(t)
        v0.append(speeds[i])
        acc.append(a)
        t += 2.0 * length / (speeds[i] + speeds[i + 1])
    knots.append(t)
    v0.append(speeds[-1])
    acc.append(0.0)
    trajectory = Trajectory(path=path, law=TravelLaw.pieces(knots, v0, acc),
                            lane_changes=lane_changes)
    if motion.get("path", "polyline") == "spline":
        _check_turns(doc, key, trajectory, np.array(knots[-len(points):]))
    return trajectory


# Points per piece of a spline path (between two waypoints) its sideways acceleration is
# checked on (`_check_turns`): the spline's curvature is smooth between waypoints.
TURN_SAMPLES = 64


def _check_turns(doc: Document, key: KeyPath, trajectory: Trajectory,
                 at_waypoints_s: np.ndarray) -> None:
    """Refuse a spline path that turns harder than `MAX_ACCELERATION_MPS2` sideways.

    Its acceleration across the direction of travel (``v^2`` times the path's curvature, and
    its lane changes' with it), on `TURN_SAMPLES` times between each two waypoints: a path that
    bends sharply between waypoints far apart, driven fast, would have the object slide
    sideways as no car can (the same bound as along the path and for lane changes).
    """
    from .trajectory import TrajectorySet

    share = np.linspace(0.0, 1.0, TURN_SAMPLES + 1)
    t = (at_waypoints_s[:-1, None] + np.diff(at_waypoints_s)[:, None] * share).ravel()
    motion = TrajectorySet([trajectory]).evaluate(t)
    assert motion.acceleration_mps2 is not None  # evaluated with it
    a, tangent = motion.acceleration_mps2[:, 0], motion.tangent[:, 0]
    speed = np.linalg.norm(motion.velocity_mps[:, 0], axis=1)
    # Across the path's tangent (a unit vector, defined where the object stands too).
    along = np.einsum("ij,ij->i", a, tangent)
    across = np.linalg.norm(a - along[:, None] * tangent, axis=1)
    worst = int(np.argmax(across))
    if across[worst] <= MAX_ACCELERATION_MPS2 * (1.0 + 1e-6):
        return
    piece = worst // (TURN_SAMPLES + 1)
    radius = speed[worst] ** 2 / across[worst]
    raise doc.error((*key, "points", piece + 1),
                    f"between waypoints {piece} and {piece + 1} the spline path turns (with "
                    f"the object's lane changes) at {t[worst]:.3g} s with a radius of "
                    f"{radius:.3g} m at {speed[worst]:.3g} m/s: a sideways acceleration of "
                    f"{across[worst]:.3g} m/s2; accelerations run from "
                    f"{-MAX_ACCELERATION_MPS2:g} to {MAX_ACCELERATION_MPS2:g} m/s2 (as "
                    f"acceleration_mps2 of constant_acceleration): lower the speeds there, or "
                    f"add waypoints that keep the path straighter")
