"""The solver's plan: everything precomputed per rig FE geometry, virtual array and method.

A `SolverPlan` holds the quads' geometry, the method's per-quad kernels, the global-maximum
checks the survey found necessary and the FEs' response kernels. It is a function of values only
(FE angles, grid shape, element positions, wavelength, method, tuning constants, code), named
by a sha256 of those values (`plan_key`), and cached by that name: in memory for the process and
on disk in the user's cache directory (`plan_cache_dir`) across processes. Two rigs with the same
numbers share a plan; a rig changed with ``dataclasses.replace`` gets its own.

The disk cache is a convenience: a file that cannot be read, is corrupt or comes from other code
is ignored and rebuilt; a directory that cannot be written means no disk cache.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import pickle
import tempfile
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from .. import quads as quads_module
from ..arrays import SourceResponse, VirtualArray, direction_cosines
from ..errors import SolverError
from ..quads import QuadGeometry
from ..registry import Registry
from ..responses import FrontEndModel
from ..rig import Rig
from ..settings import CACHE_DIR_ENV, cache_dir
from . import exact, globalmax
from .exact import ExactQuad, ExactTables, PhaseMap
from .globalmax import GlobalMaxCheck
from .reasons import Reason

FloatArray = NDArray[np.float64]

# Nodes per quad side of the precomputed split map.
SPLIT_MAP_NODES = 17
# The per-target local-maximum test is skipped in quads whose nodes all curve downward by at
# least this fraction of a single FE's main-lobe curvature.
CLEAR_MAXIMUM = 0.1
# A quad gets the run-time global-maximum check when a node's strongest far direction comes
# within this fraction more of splitting: targets between the nodes may come closer still.
SURVEY_MARGIN = 0.1
# Plans kept in memory (a sweep over a few rigs and arrays; each is a few MB, up to ~20 MB for
# a 12 TX x 16 RX cascade on an 8-quad rig, mostly the split check's probes over the field of
# view).
MEMORY_PLANS = 16
# Environment variable naming the disk cache directory; "off" or empty disables it.

Origin = Literal["built", "memory", "disk"]


class QuadKernel(Protocol):
    """What a method provides per quad."""

    def solve(
        self, az_rad: FloatArray, el_rad: FloatArray
    ) -> tuple[FloatArray, NDArray[np.uint8]]:
        """Return ``(weights (N, 4), reason (N,))``."""
        ...


# Solver methods by name: a class with ``build(rig, array, fes) -> QuadKernel``. Packages add
# their own through the entry-point group.
METHODS = Registry("method", {
    "paper": "rts_scenario.solver.paper:PaperQuad",
    "exact": "rts_scenario.solver.exact:ExactQuad",
}, entry_point_group="rts_scenario.solver_methods", error=SolverError)


@dataclass(frozen=True, eq=False)
class SolverPlan:
    """Precomputed solver state for one (rig FE geometry, array, method, FE response model).

    Plans compare by identity; ``key`` names the values a plan stands for.

    Attributes
    ----------
    key : str
        `plan_key` of the values the plan was built from (hex sha256).
    method : str
        Method name.
    geometry : QuadGeometry
        The rig's quads in angle space.
    kernels : tuple, length Q
        The method's kernel per quad.
    checks : tuple, length Q
        Global-maximum check per quad, ``None`` where the survey found no possible split.
    responses : tuple of SourceResponse, length Q
        Response ``f_q`` of each quad's four FEs (paper order) on the array, with derivatives.
    exact_tables : ExactTables or None
        The exact method's quads packed for its compiled kernel (other methods: ``None``).
    origin : {"built", "memory", "disk"}
        Where `solver_plan` got this plan from (not part of the plan's value).
    seconds : float
        Wall time `solver_plan` spent getting it, seconds (not part of the plan's value).
    """

    key: str
    method: str
    geometry: QuadGeometry
    kernels: tuple[QuadKernel, ...]
    checks: tuple[GlobalMaxCheck | None, ...]
    responses: tuple[SourceResponse, ...]
    exact_tables: ExactTables | None = None
    origin: Origin = "built"
    seconds: float = 0.0

    def describe(self) -> str:
        """One line for a run's timing summary, e.g. ``plan 12 ms (disk)``."""
        return f"plan {self.seconds * 1e3:.0f} ms ({self.origin})"


def solver_plan(
    rig: Rig, array: VirtualArray, method: str, model: FrontEndModel | None = None
) -> SolverPlan:
    """Return the plan for ``rig``, ``array`` and ``method``, from a cache when possible.

    With ``model`` (the radar's physical antennas) the FEs' responses are modeled from the
    bench geometry (`rts_scenario.responses`) instead of plane waves.

    Looks in memory, then on disk (see `plan_cache_dir`), else builds it with `build_plan`
    and stores it in both. The returned plan's ``origin`` and ``seconds`` say which and how long
    it took.

    Raises
    ------
    SolverError
        The method cannot solve on this array (raised by the method's kernel).
    """
    start = time.perf_counter()
    key = plan_key(rig, array, method, model)
    with _key_lock(key):
        origin: Origin = "memory"
        plan = _MEMORY.get(key)
        if plan is None:
            directory = plan_cache_dir()
            origin = "disk"
            plan = _load(directory, key)
            if plan is None:
                origin = "built"
                plan = build_plan(rig, array, method, model, key=key)
                _store(directory, key, plan)
            _MEMORY.put(key, plan)
    return replace(plan, origin=origin, seconds=time.perf_counter() - start)


def build_plan(
    rig: Rig,
    array: VirtualArray,
    method: str,
    model: FrontEndModel | None = None,
    *,
    key: str | None = None,
) -> SolverPlan:
    """Build the plan from the values of ``rig``, ``array``, ``method`` and ``model`` (no cache).

    Every quad's kernel is surveyed on a grid of nodes to learn which run-time checks it needs.
    With ``model``, the FEs' modeled response vectors serve the global-maximum checks, the
    plan's responses and the methods that take them (``uses_response_vectors``).
    """
    method_class = METHODS.get(method)
    build: Callable[..., QuadKernel] = method_class.build
    takes_vectors = bool(getattr(method_class, "uses_response_vectors", False))
    if model is not None:
        model.check(array)
    geometry = QuadGeometry.of(rig)
    kernels: list[QuadKernel] = []
    checks: list[GlobalMaxCheck | None] = []
    responses = []
    for q, fes in enumerate(rig.quads):
        vectors = None if model is None else model.vectors(rig, fes, array)
        check = GlobalMaxCheck.build(rig, array, fes, vectors)
        kernel = build(rig, array, fes, vectors) if takes_vectors else build(rig, array, fes)
        kernel, can_split = _survey_quad(kernel, check, geometry.polygons[q], array)
        kernels.append(kernel)
        checks.append(check if can_split else None)
        u, s = direction_cosines(np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes]))
        responses.append(array.source_response(u, s, vectors))
    exact = [k for k in kernels if isinstance(k, ExactQuad)]
    return SolverPlan(
        key=plan_key(rig, array, method, model) if key is None else key, method=method,
        geometry=geometry, kernels=tuple(kernels), checks=tuple(checks),
        responses=tuple(responses),
        exact_tables=ExactTables.of(exact) if exact and len(exact) == len(kernels) else None,
    )


def plan_key(
    rig: Rig, array: VirtualArray, method: str, model: FrontEndModel | None = None
) -> str:
    """Name of the plan for these values: hex sha256 of everything the plan depends on.

    That is the rig's FE angles and grid shape, the array's element positions and wavelength,
    the method, the solver's tuning constants, and the package version and code; with a
    ``model``, also the radar's physical antennas and the FEs' distances and antenna offsets
    (never the calibration: the plan does not use it).
    """
    modeled = () if model is None else (*model.key, *model.rig_key(rig))
    digest = hashlib.sha256()
    for part in (*rig.key, *array.key, *modeled, method, repr(_tuning()), _code_fingerprint()):
        data = part if isinstance(part, bytes) else repr(part).encode()
        digest.update(len(data).to_bytes(8, "little"))
        digest.update(data)
    return digest.hexdigest()


def plan_cache_dir() -> Path | None:
    """Directory of the disk cache of plans, or ``None`` when disabled (`settings.cache_dir`)."""
    return cache_dir()


def clear_memory_cache() -> None:
    """Forget the plans held in memory (the disk cache stays)."""
    _MEMORY.clear()


def _survey_quad(
    kernel: QuadKernel, check: GlobalMaxCheck, polygon: FloatArray, array: VirtualArray
) -> tuple[QuadKernel, bool]:
    """Solve a grid of nodes over the quad to learn which run-time checks it needs.

    Returns the kernel (the exact one without its per-target local-maximum test where every
    node is a clear local maximum) and whether any node's peak is not, or is only just (see
    `SURVEY_MARGIN`), the global maximum over the field of view.
    """
    t = np.linspace(0.0, 1.0, SPLIT_MAP_NODES)
    a, b = (g.ravel() for g in np.meshgrid(t, t))
    # Bilinear map from the unit square to the corners FE 0, 1, 3, 2.
    p0, p1, p3, p2 = polygon
    pts = ((1 - a) * (1 - b))[:, None] * p0 + (a * (1 - b))[:, None] * p1 \
        + (a * b)[:, None] * p3 + ((1 - a) * b)[:, None] * p2
    az, el = np.radians(pts[:, 0]), np.radians(pts[:, 1])
    if isinstance(kernel, ExactQuad):
        weights, reason, margin = kernel.solve_with_curvature(az, el, curvature=True)
        assert margin is not None
        k2 = array.wavenumber_rad_per_m**2
        natural = k2 * min(float(np.mean(array.y_m**2)), float(np.mean(array.z_m**2)))
        solved = reason != Reason.NO_SOLUTION
        if np.all(margin[solved] < -CLEAR_MAXIMUM * natural):
            kernel = replace(kernel, check_local_max=False)
    else:
        weights, reason = kernel.solve(az, el)
    if np.any(reason == Reason.SPLIT):
        return kernel, True
    ok = reason == Reason.OK
    return kernel, bool(np.any(check.splits(az[ok], el[ok], weights[ok], SURVEY_MARGIN)))


def _tuning() -> tuple[float | int, ...]:
    """Return the constants that shape a plan, read at call time (changed: a new plan)."""
    return (
        SPLIT_MAP_NODES, CLEAR_MAXIMUM, SURVEY_MARGIN,
        *globalmax.FIELD_OF_VIEW, globalmax.PROBES_PER_CELL, globalmax.EXCLUSION_CELLS,
        globalmax.SAMPLING_LOSS, globalmax.GHOST_POWER,
        PhaseMap.NODES, exact._NEGATIVE_TOL, exact._RANK_TOL, exact._MAX_ITERATIONS,
        exact._PHASE_TOL, exact._GAIN_TOL, exact._RESIDUAL_TOL,
        quads_module.DEGENERATE_AREA_DEG2,
    )


@lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """Package version plus a hash of the code a plan is built and pickled with.

    An editable install keeps its version while its code changes; a plan pickled by other code
    must not be taken for this code's.
    """
    try:
        version = importlib.metadata.version("rts-scenario")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    package = Path(__file__).resolve().parent.parent
    sources = sorted(package.joinpath("solver").glob("*.py"))
    sources += [package / name for name in ("arrays.py", "quads.py", "responses.py", "rig.py")]
    digest = hashlib.sha256()
    for path in sources:
        try:
            digest.update(path.read_bytes())
        except OSError:
            digest.update(path.name.encode())
    return f"{version}:{digest.hexdigest()}"


class _MemoryCache:
    """A small least-recently-used map from plan key to plan, safe across threads."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._plans: OrderedDict[str, SolverPlan] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: str) -> SolverPlan | None:
        with self._lock:
            plan = self._plans.get(key)
            if plan is not None:
                self._plans.move_to_end(key)
            return plan

    def put(self, key: str, plan: SolverPlan) -> None:
        with self._lock:
            self._plans[key] = plan
            self._plans.move_to_end(key)
            while len(self._plans) > self._size:
                self._plans.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._plans.clear()


_MEMORY = _MemoryCache(MEMORY_PLANS)
_KEY_LOCKS: dict[str, threading.Lock] = {}
_KEY_LOCKS_GUARD = threading.Lock()


def _key_lock(key: str) -> threading.Lock:
    """One lock per plan key: threads wanting the same plan build it once."""
    with _KEY_LOCKS_GUARD:
        return _KEY_LOCKS.setdefault(key, threading.Lock())


def _load(directory: Path | None, key: str) -> SolverPlan | None:
    """Read the plan stored under ``key``; ``None`` if absent, unreadable or not this code's."""
    if directory is None:
        return None
    try:
        with open(directory / key, "rb") as file:
            stored = pickle.load(file)
    # Unpickling garbage or another version's classes can raise nearly anything: all of it
    # means "no usable cache file".
    except Exception:
        return None
    if isinstance(stored, SolverPlan) and stored.key == key:
        return stored
    return None


def _store(directory: Path | None, key: str, plan: SolverPlan) -> None:
    """Write the plan under ``key`` atomically; on any OS error keep going without it."""
    if directory is None:
        return
    temp: str | None = None
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(
            dir=directory, prefix=f".{key[:16]}.", suffix=".tmp", delete=False
        ) as file:
            temp = file.name
            pickle.dump(plan, file, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(temp, directory / key)
        temp = None
    # A kernel that cannot be pickled (a user's method) just goes without the disk cache.
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        pass
    finally:
        if temp is not None:
            try:
                os.unlink(temp)
            except OSError:
                pass


__all__ = [
    "CACHE_DIR_ENV",
    "METHODS",
    "QuadKernel",
    "SolverPlan",
    "build_plan",
    "clear_memory_cache",
    "plan_cache_dir",
    "plan_key",
    "solver_plan",
]
