"""Performance figures, each measured beside its comparison in the same run.

`rts-scenario bench` prints them and the benchmarks in ``tests/benchmarks`` assert them. Every
figure has a comparison measured in the same process, alternating with it where both are short
(best of several rounds each), because the machine may be shared and noisy: a ratio measured
in one run means more than two absolute figures from different runs.

- CAN: messages per second from cycles to checked detections, in process, against python-can's
  virtual bus with a reader (a copy of each message and a queue).
- Solver: the exact method's target-frames per second against the paper method's; its memory
  traffic against a copy of arrays four times the last-level cache (the streaming bandwidth).
- Radar: an `adc` frame against its two windowed FFTs alone; `analytic` frames per second.
- Quantization: the quantization-aware schedule against the continuous one.
- Scale: time per target-frame of a 60 s run with 512 targets against 8 targets; peak memory.
- Start-up: ``import rts_scenario`` and a command's start-up before its cut-in run (imports
  and first use), each in fresh interpreters, against ``import numpy``; a repeated run of the
  cut-in scene in process.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Figure:
    """One measured figure, its comparison from the same run, and the goal it is held to."""

    name: str
    value: float
    unit: str
    comparison: str
    comparison_value: float
    ratio: float
    goal: str
    met: bool

    def line(self) -> str:
        """Render the figure for people."""
        return (f"{self.name:44s} {self.value:>14,.4g} {self.unit:15s} vs {self.comparison} "
                f"{self.comparison_value:,.4g}: {self.ratio:.2f}x  goal {self.goal}  "
                f"{'met' if self.met else 'NOT met'}")


def best_of(fn: Callable[[], Any], rounds: int) -> float:
    """Return the shortest of ``rounds`` timed calls (s)."""
    out = np.inf
    for _ in range(rounds):
        start = time.perf_counter()
        fn()
        out = min(out, time.perf_counter() - start)
    return float(out)


def alternating(first: Callable[[], Any], second: Callable[[], Any],
                rounds: int) -> tuple[float, float]:
    """Return each one's best time over ``rounds`` rounds taken in turn (s)."""
    a = b = np.inf
    for _ in range(rounds):
        a = min(a, best_of(first, 1))
        b = min(b, best_of(second, 1))
    return float(a), float(b)


# -- the shared scene: 60 s at 20 Hz, awr1843boost, 8 targets around the ego -------------------

def eight_target_scene(folder: Path, targets: int = 8, duration_s: float = 60.0) -> Path:
    """Write the scene the radar, CAN and scale figures use (targets on the wide grid).

    The targets move at one speed: they keep 5 m (17 range bins) apart, beyond each other's
    CFAR window, so the radar sees every one of them in every cycle (at their own speeds they
    drifted into each other's training cells, where a CA-CFAR loses the weaker).
    """
    import yaml

    rng = np.random.default_rng(4)
    scene = {"rts_scenario": 1, "name": f"perf-{targets}", "duration_s": duration_s,
             "frame_rate_hz": 20.0, "radar": {"profile": "awr1843boost"},
             "rig": "wide-3x5", "seed": 1,
             "ego": {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                                "speed_mps": 22.0}},
             "targets": [{"name": f"car{i}", "frame": "ego",
                          "rcs": {"rcs_dbsm": float(rng.uniform(0, 20))},
                          "motion": {"type": "constant_velocity",
                                     "position_m": [float(20 + 5 * i),
                                                    float(rng.uniform(-4, 4)), 0.6],
                                     "speed_mps": 0.15}}
                         for i in range(targets)]}
    path = folder / "perf.scenario.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return path


# -- CAN --------------------------------------------------------------------------------------

CAN_GOAL_PER_S = 100_000


def can_rate(rounds: int = 5) -> Figure:
    """Messages per second: cycles -> encode -> bus -> decode -> check, in process."""
    from .canbus import DetectionPublisher, DetectionReceiver, ListenerBus, open_bus
    from .check import check_cycles
    from .kinematics import compute_tracks
    from .radar.simulate import SimulatedRadar
    from .scenario import load_scenario
    from .schedule import build_schedule

    with tempfile.TemporaryDirectory() as folder:
        scene = load_scenario(eight_target_scene(Path(folder)))
    tracks = compute_tracks(scene)
    schedule = build_schedule(tracks, scene.rig, scene.radar)
    frames = SimulatedRadar(scene.radar, scene.rig, fidelity="analytic",
                            rng=np.random.default_rng(0)).process(schedule)
    sent: list[int] = []

    def check(receiver: DetectionReceiver) -> None:
        report = check_cycles(scene.name, tracks, schedule.status, receiver.flush(),
                              scene.expectations, bus=vars(receiver.stats))
        if not (receiver.stats.clean and report.frames["checked"] == schedule.n_frames):
            raise RuntimeError("CAN figure: the cycles did not come through clean")

    def in_process() -> None:
        receiver = DetectionReceiver()
        with ListenerBus([receiver]) as bus:
            publisher = DetectionPublisher(bus)
            publisher.publish_many(frames)
        sent.append(publisher.sent)
        check(receiver)

    def virtual_bus() -> None:
        receiver = DetectionReceiver()
        with open_bus(channel="perf") as listen, open_bus(channel="perf") as talk:
            publisher = DetectionPublisher(talk)
            publisher.publish_many(frames)  # as the in-process path: the same encoding work
            # Every message is queued once sent: no wait for the last (it would be timed).
            while (msg := listen.recv(timeout=0)) is not None:
                receiver.on_message_received(msg)
        check(receiver)

    fast, slow = alternating(in_process, virtual_bus, rounds)
    n = sent[-1]
    return Figure("CAN cycles -> encode -> bus -> decode -> check", n / fast, "messages/s",
                  "python-can virtual bus", n / slow, slow / fast,
                  f">= {CAN_GOAL_PER_S:,} messages/s", n / fast >= CAN_GOAL_PER_S)


# -- solver -----------------------------------------------------------------------------------

def solver_speed(array_name: str, rig_name: str = "kit-table1", targets: int = 1_000_000,
                 rounds: int = 3) -> list[Figure]:
    """Exact against paper (target-frames/s), and the exact method against a streaming copy."""
    from .arrays import VirtualArray
    from .rig import Rig
    from .solver import solve_weights

    rig, array = Rig.preset(rig_name), VirtualArray.preset(array_name)
    rng = np.random.default_rng(0)
    if rig_name == "wide-3x5":
        az, el = rng.uniform(-20, 20, targets), rng.uniform(-8, 8, targets)
    else:
        az, el = rng.uniform(-3, 3, targets), rng.uniform(-6, 6, targets)
    for method in ("paper", "exact"):  # plans built (or read) before timing
        solve_weights(az[:64], el[:64], rig=rig, array=array, method=method)
    exact_s, paper_s = alternating(
        lambda: solve_weights(az, el, rig=rig, array=array, method="exact"),
        lambda: solve_weights(az, el, rig=rig, array=array, method="paper"), rounds)
    bandwidth = streaming_copy_bandwidth(rounds * 2)
    # The solver's traffic: az and el in, weights (4 x float64), quad (int64) and reason out.
    solver_bytes = targets * (8 + 8 + 32 + 8 + 1)
    rate = targets / exact_s
    name = f"exact solver {array_name} on {rig_name}"
    return [
        Figure(name, rate, "target-frames/s", "paper method", targets / paper_s,
               paper_s / exact_s, ">= 1.0x the paper method", exact_s <= paper_s),
        Figure(f"{name}: memory traffic", solver_bytes / exact_s / 1e9, "GB/s",
               "streaming copy", bandwidth / 1e9, solver_bytes / exact_s / bandwidth,
               ">= 0.10x the streaming copy", solver_bytes / exact_s >= 0.1 * bandwidth),
    ]


# Where sysfs gives no cache sizes: the largest last-level cache of the machines this runs on.
_DEFAULT_CACHE_BYTES = 32 << 20
_CACHE_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30}


def last_level_cache_bytes(root: Path = Path("/sys/devices/system/cpu/cpu0/cache")) -> int:
    """Return the largest CPU cache (bytes) that sysfs lists, else `_DEFAULT_CACHE_BYTES`."""
    sizes = []
    for entry in root.glob("index*/size"):
        try:
            text = entry.read_text().strip().upper()
        except OSError:
            continue
        digits, unit = text.rstrip("KMG"), text[len(text.rstrip("KMG")):]
        if digits.isdigit() and unit in _CACHE_UNITS:
            sizes.append(int(digits) * _CACHE_UNITS[unit])
    return max(sizes, default=_DEFAULT_CACHE_BYTES)


def streaming_copy_bytes(cache_bytes: int | None = None) -> int:
    """Size of each array of the streaming copy: four times the last-level cache, >= 64 MiB.

    STREAM's rule: with arrays this large the copy reads and writes memory, not the cache
    (a copy that fits in the cache measures the cache, several times faster).
    """
    cache = last_level_cache_bytes() if cache_bytes is None else cache_bytes
    return max(4 * cache, 64 << 20)


def streaming_copy_bandwidth(rounds: int) -> float:
    """Return the streaming limit (bytes/s): a copy of `streaming_copy_bytes`, read plus written.

    The faster of one thread and the solver's worker threads (each copying its share): the
    solver runs on all of them, and one core alone may not reach what the memory gives.
    """
    from .workers import THREADS, run_parts

    source = np.ones(streaming_copy_bytes() // 8)
    sink = np.empty_like(source)
    one_s = best_of(lambda: np.copyto(sink, source), rounds)
    bounds = np.linspace(0, source.size, THREADS + 1).astype(int)
    shares = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def copy_share(share: slice) -> None:
        np.copyto(sink[share], source[share])

    all_s = best_of(lambda: run_parts(copy_share, shares), rounds)
    return 2 * source.nbytes / min(one_s, all_s)


# -- radar ------------------------------------------------------------------------------------

ANALYTIC_GOAL_FRAMES_PER_S = 5000
ADC_GOAL_OVER_FFTS = 3.0


def radar_rates(rounds: int = 5, frames: int = 20) -> list[Figure]:
    """Time adc frames against their FFTs alone; analytic frames per second (8 targets).

    The adc figure is a frame's share of ``frames`` consecutive ones (the steady state: the
    radar draws each frame's noise on a second thread while the frame before is processed,
    and a frame waits for it), against the radar's own two FFTs (in place, on a cube of the
    same shape), timed with no noise being drawn beside them.
    """
    from .kinematics import compute_tracks
    from .radar.simulate import SimulatedRadar
    from .scenario import load_scenario
    from .schedule import build_schedule

    with tempfile.TemporaryDirectory() as folder:
        scene = load_scenario(eight_target_scene(Path(folder)))
    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar)
    adc = SimulatedRadar(scene.radar, scene.rig, fidelity="adc", rng=np.random.default_rng(0))
    p = scene.radar
    shape = (p.chirp_loops, p.array.n_elements, p.adc_samples)
    noise = np.random.default_rng(1).standard_normal((2, *shape))
    cube = noise[0] + 1j * noise[1]

    def ffts() -> None:
        # As `SimulatedRadar` takes them (in place; its windows are in the cube's weights).
        # Unitary scaling, so that the repeated transforms keep the values' size.
        for _ in range(frames):
            np.fft.ifft(cube, axis=2, out=cube, norm="ortho")
            np.fft.fft(cube, axis=0, out=cube, norm="ortho")

    batch = schedule.frames(0, frames)
    adc.process(batch)
    frame_s = fft_s = np.inf
    for _ in range(rounds):
        frame_s = min(frame_s, best_of(lambda: adc.process(batch), 1) / frames)
        adc.finish_noise()  # the draw ahead done: it must not run beside the FFTs
        fft_s = min(fft_s, best_of(ffts, 1) / frames)
    part = schedule.frames(0, 1200)

    def analytic() -> None:
        SimulatedRadar(scene.radar, scene.rig, fidelity="analytic",
                       rng=np.random.default_rng(0)).process(part)

    analytic_s = best_of(analytic, 5)
    rate = part.n_frames / analytic_s
    return [
        Figure(f"adc frame, awr1843boost, 8 targets ({frames} in a row)", frame_s * 1e3,
               "ms", "its two FFTs alone", fft_s * 1e3, frame_s / fft_s,
               f"<= {ADC_GOAL_OVER_FFTS:g}x its FFTs", frame_s <= ADC_GOAL_OVER_FFTS * fft_s),
        Figure("analytic radar, awr1843boost, 8 targets", rate, "frames/s",
               "the goal", ANALYTIC_GOAL_FRAMES_PER_S, rate / ANALYTIC_GOAL_FRAMES_PER_S,
               f">= {ANALYTIC_GOAL_FRAMES_PER_S:,} frames/s",
               rate >= ANALYTIC_GOAL_FRAMES_PER_S),
    ]


# -- quantization -----------------------------------------------------------------------------

QUANTIZATION_GOAL = 1.5


def quantization_ratio(rounds: int = 5) -> Figure:
    """Time the quantization-aware schedule (0.5 dB steps) against the continuous one."""
    from .kinematics import compute_tracks
    from .scenario import load_scenario
    from .schedule import build_schedule

    with tempfile.TemporaryDirectory() as folder:
        scene = load_scenario(eight_target_scene(Path(folder), targets=32))
    tracks = compute_tracks(scene)

    def rig_for(step_db: float) -> Any:
        limits = dataclasses.replace(scene.rig.limits, attenuation_step_db=step_db,
                                     echoes_per_channel=64)
        return dataclasses.replace(scene.rig, limits=limits)

    continuous, stepped = rig_for(0.0), rig_for(0.5)
    build_schedule(tracks, continuous, scene.radar)
    build_schedule(tracks, stepped, scene.radar, quantization="aware")
    aware_s, continuous_s = alternating(
        lambda: build_schedule(tracks, stepped, scene.radar, quantization="aware"),
        lambda: build_schedule(tracks, continuous, scene.radar), rounds)
    ratio = aware_s / continuous_s
    return Figure("quantization-aware schedule (0.5 dB attenuator steps), 1200 x 32",
                  aware_s * 1e3, "ms",
                  "continuous schedule", continuous_s * 1e3, ratio,
                  f"<= {QUANTIZATION_GOAL:g}x continuous", ratio <= QUANTIZATION_GOAL)


# -- scale ------------------------------------------------------------------------------------

SCALE_GOAL = 2.0
_SCALE_RUN = textwrap.dedent("""
    import json, sys, tempfile, time
    from pathlib import Path
    import numpy as np, yaml
    from importlib import resources
    from rts_scenario.pipeline import RunOptions, run_scene
    from rts_scenario.scenario import load_scenario
    # What a run loads where it first needs it (scipy's modules), loaded before: the runs
    # compare their own time and memory, not which libraries their frames happened to need
    # (the Hungarian method's, 0.1 s and 100 MB, only where detections offer a choice).
    import scipy.interpolate, scipy.optimize, scipy.sparse.csgraph, scipy.special

    k, duration = int(sys.argv[1]), float(sys.argv[2])
    folder = Path(tempfile.mkdtemp())
    rig = yaml.safe_load(resources.files("rts_scenario").joinpath(
        "data/rigs/wide-3x5.rig.yaml").read_text())
    rig["name"] = "wide-many"
    rig.setdefault("limits", {})["echoes_per_channel"] = 1024
    (folder / "wide.rig.yaml").write_text(yaml.safe_dump(rig))
    rng = np.random.default_rng(5)
    targets = []
    for i in range(k):  # 12..60 m, +-15 deg
        x, az = 12 + 48 * i / k, np.radians(rng.uniform(-15, 15))
        targets.append({"name": f"t{i}", "frame": "ego", "rcs": {"rcs_dbsm": 10.0},
                        "motion": {"type": "constant_velocity",
                                   "position_m": [float(x), float(x * np.tan(az)), 0.6],
                                   "speed_mps": float(rng.uniform(0, 0.2))}})
    # 512 targets within 48 m share range-Doppler neighbourhoods: the analytic radar reads
    # each as if alone (a scale test of the software, not of a radar), which the scene says.
    scene = {"rts_scenario": 1, "name": f"scale-{k}", "duration_s": duration,
             "frame_rate_hz": 20.0, "rig": "wide.rig.yaml", "seed": 1,
             "radar": {"profile": "awr1843boost", "fidelity": "analytic"},
             "expectations": {"expected_limits": ["crowded_in_analytic"]},
             "ego": {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0],
                                "speed_mps": 22.0}},
             "targets": targets}
    path = folder / "scale.scenario.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    loaded = load_scenario(path)
    start = time.perf_counter()
    result = run_scene(loaded, RunOptions(can_fd=True))
    # Less the solver plan's building (once per rig and array, then cached): not the run's.
    seconds = time.perf_counter() - start - result.report.timing.get("plan_s", 0.0)
    peak = next(int(line.split()[1]) for line in open("/proc/self/status")
                if line.startswith("VmHWM"))
    print(json.dumps({"targets": k, "frames": loaded.n_frames, "seconds": seconds,
                      "peak_mb": peak / 1024, "passed": result.report.passed}))
""")


def scale_run(targets: int, duration_s: float = 60.0) -> dict[str, Any]:
    """Run the scale scene with ``targets`` in a fresh process: time, frames, peak memory."""
    out = subprocess.run([sys.executable, "-c", _SCALE_RUN, str(targets), str(duration_s)],
                         capture_output=True, text=True, check=True, timeout=3600)
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def memory_slopes(runs: dict[int, dict[str, Any]]) -> tuple[float, float, bool]:
    """Peak memory per added target (MB) over the first and the second step of three runs.

    ``runs``: `scale_run` results by target count (three). Linear in targets: the second
    step's slope no steeper than twice the first's, with 0.5 MB per target of slack for a
    first slope near 0 (the runs' peaks also hold the interpreter and the libraries).
    """
    few, middle, many = sorted(runs)
    first = (runs[middle]["peak_mb"] - runs[few]["peak_mb"]) / (middle - few)
    second = (runs[many]["peak_mb"] - runs[middle]["peak_mb"]) / (many - middle)
    return first, second, second <= max(2.0 * first, 0.5)


# Target counts whose peak memory tells its growth (`scale`): a run's batch is 500 frames up to
# 32 targets (`preflight.frames_per_batch`), its peak growing with the batch, and 16,384
# target-frames beyond: there the peak grows by what a target keeps.
MEMORY_TARGETS = (128, 320)


def scale(duration_s: float = 60.0, many: int = 512) -> list[Figure]:
    """Time per target-frame and peak memory: ``many`` targets against 8 (fresh processes).

    Two more runs (`MEMORY_TARGETS`) tell with ``many`` whether memory grows linearly
    (`memory_slopes`).
    """
    runs = {k: scale_run(k, duration_s) for k in (8, *MEMORY_TARGETS, many)}
    per = {k: r["seconds"] / (k * r["frames"]) for k, r in runs.items()}
    ratio = per[many] / per[8]
    passed = all(r["passed"] for r in runs.values())
    first, second, linear = memory_slopes({k: runs[k] for k in (*MEMORY_TARGETS, many)})
    low, middle = MEMORY_TARGETS
    return [
        Figure(f"run, {many} targets x {duration_s:g} s, per target-frame", per[many] * 1e6,
               "us", "8 targets", per[8] * 1e6, ratio, f"<= {SCALE_GOAL:g}x 8 targets",
               ratio <= SCALE_GOAL and passed),
        Figure(f"run, {many} targets x {duration_s:g} s, peak memory per added target "
               f"({middle} -> {many})", second, "MB", f"{low} -> {middle} targets", first,
               second / first if first > 0 else np.inf,
               "linear in targets: <= 2x (or 0.5 MB)", linear and passed),
    ]


# -- start-up ---------------------------------------------------------------------------------

IMPORT_GOAL_S = 0.150
REPEAT_RUN_GOAL_S = 0.35


def fresh_interpreter_env(pycache: Path) -> dict[str, str]:
    """Return the environment of a timed fresh interpreter: bytecode read from ``pycache``.

    An installed package's modules are compiled once (pip compiles them on install; an editable
    install on first import). ``PYTHONDONTWRITEBYTECODE`` would make every timed interpreter
    compile this package's sources again (about 0.1 s), which no installed command pays, so it
    is dropped and the bytecode goes to ``pycache`` (``PYTHONPYCACHEPREFIX``): the first,
    untimed interpreter writes it, the timed ones read it.
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def _fresh_seconds(code: str, rounds: int, pycache: Path | None) -> float:
    """Best value printed by ``code`` in ``rounds`` fresh interpreters (after an untimed one)."""
    with tempfile.TemporaryDirectory() as scratch:
        env = fresh_interpreter_env(Path(scratch) if pycache is None else pycache)

        def once() -> float:
            done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                  check=True, env=env)
            return float(done.stdout.split()[-1])

        once()  # writes the bytecode (and the solver plan's disk cache)
        return min(once() for _ in range(rounds))


def import_seconds(module: str, rounds: int = 5, pycache: Path | None = None) -> float:
    """Best time of ``import module`` in a fresh interpreter (s), bytecode cached."""
    code = f"import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"
    return _fresh_seconds(code, rounds, pycache)


def startup_seconds(scene: str | Path, rounds: int = 5, pycache: Path | None = None) -> float:
    """Return what a fresh command spends before it runs ``scene`` as fast as a repeated run (s).

    Its imports as the command makes them (python-can's MF4 support deferred,
    `rts_scenario.mf4.defer`; the collector paused, `rts_scenario.startup`) plus its first
    run, less a second run in the same interpreter. Whatever the first run loads on first use
    (scipy for an assignment, the solver plan from its disk cache) counts; the plan is built,
    if at all, in the untimed first interpreter.
    """
    code = textwrap.dedent(f"""
        import time
        t = time.perf_counter()
        from rts_scenario.mf4 import defer
        from rts_scenario.startup import command_imports, mark_command_process
        defer()
        mark_command_process()
        with command_imports():
            from rts_scenario.pipeline import run_scene
        run_scene({str(scene)!r})
        first = time.perf_counter() - t
        t = time.perf_counter()
        run_scene({str(scene)!r})
        print(first - (time.perf_counter() - t))
    """)
    return _fresh_seconds(code, rounds, pycache)


def startup(scene: str | Path | None = None, rounds: int = 5) -> list[Figure]:
    """Start-up in fresh interpreters against ``import numpy``; a repeated cut-in run.

    ``import rts_scenario`` loads its names when they are first used, so it alone costs next to
    nothing: the second figure is what a command spends before its run goes as fast as a
    repeated one (`startup_seconds`: the imports the run needs, scipy's where it is used
    included). Both with bytecode cached, as an installed package has it
    (`fresh_interpreter_env`). Without ``scene`` only the first.
    """
    from .pipeline import run_scene

    with tempfile.TemporaryDirectory() as pycache:
        cache = Path(pycache)
        package = import_seconds("rts_scenario", rounds, cache)
        numpy = import_seconds("numpy", rounds, cache)
        out = [Figure("import rts_scenario (fresh interpreter)", package * 1e3, "ms",
                      "import numpy", numpy * 1e3, package / numpy,
                      f"<= {IMPORT_GOAL_S * 1e3:.0f} ms", package <= IMPORT_GOAL_S)]
        if scene is None:
            return out
        command = startup_seconds(scene, rounds, cache)
    out.append(Figure("start-up of a cut-in run (the command's)", command * 1e3, "ms",
                      "import numpy", numpy * 1e3, command / numpy,
                      f"<= {IMPORT_GOAL_S * 1e3:.0f} ms", command <= IMPORT_GOAL_S))
    run_scene(scene)  # the solver plan is built (or read) once
    repeat = best_of(lambda: run_scene(scene), rounds)
    out.append(Figure("repeated cut-in run, in process", repeat * 1e3, "ms",
                      "the goal", REPEAT_RUN_GOAL_S * 1e3, repeat / REPEAT_RUN_GOAL_S,
                      f"<= {REPEAT_RUN_GOAL_S * 1e3:.0f} ms", repeat <= REPEAT_RUN_GOAL_S))
    return out


def all_figures(cut_in: str | Path | None = None, scale_s: float = 60.0) -> list[Figure]:
    """Every figure, in the order of the list above (``scale_s`` 0 skips the scale runs)."""
    figures = [can_rate()]
    for array_name, rig_name in (("paper", "kit-table1"), ("awr1843boost", "kit-table1"),
                                 ("awr1843boost", "wide-3x5")):
        figures += solver_speed(array_name, rig_name)
    figures += radar_rates()
    figures.append(quantization_ratio())
    if scale_s > 0:
        figures += scale(scale_s)
    figures += startup(cut_in)
    return figures


def _number(value: float) -> str:
    """Render a value for a table: whole thousands grouped, else three significant digits."""
    return f"{value:,.0f}" if abs(value) >= 1000 else f"{value:.3g}"


def format_markdown(figures: list[Figure]) -> str:
    """Render the figures as the Markdown table of the README (`rts-scenario bench --markdown`)."""
    lines = ["| figure | measured | comparison (same run) | ratio | goal | |",
             "|---|---|---|---|---|---|"]
    for f in figures:
        lines.append(f"| {f.name} | {_number(f.value)} {f.unit} | {f.comparison}: "
                     f"{_number(f.comparison_value)} {f.unit} | {f.ratio:.3g}× | "
                     f"{f.goal.replace('>=', '≥').replace('<=', '≤')} | "
                     f"{'met' if f.met else '**not met**'} |")
    return "\n".join(lines)


def format_figures(figures: list[Figure]) -> str:
    """Render the figures as a table for people."""
    return "\n".join(["performance (each against its comparison, same run)",
                      *(f.line() for f in figures)])


__all__ = ["Figure", "all_figures", "can_rate", "format_figures", "format_markdown",
           "last_level_cache_bytes", "memory_slopes",
           "quantization_ratio", "radar_rates", "scale", "solver_speed", "startup",
           "streaming_copy_bandwidth", "streaming_copy_bytes"]
