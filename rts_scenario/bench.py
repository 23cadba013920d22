"""Speed against angle error of every solver method on every shipped array, and end to end.

The error is measured on the paper's evaluation grid by the independent peak search
(`rts_scenario.evaluation`); the throughput by solving N random targets spread over the same
region. The end-to-end row runs a motorway scene of any length through the pipeline (simulated
radar, virtual CAN, checker) and reports how much faster than real time the desk runs it.
"""

from __future__ import annotations

import json
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .arrays import PRESETS, VirtualArray
from .atomic import write_atomic
from .evaluation import GRID_AZ_DEG, GRID_EL_DEG, angle_errors, evaluation_grid
from .peak_search import find_peak
from .report import strict
from .rig import Rig
from .solver import METHODS, solve_weights


@dataclass(frozen=True)
class BenchRow:
    """One line of the speed-against-error table."""

    method: str
    array: str
    rig: str
    targets: int
    throughput_per_s: float
    feasible: int
    grid_points: int
    rms_az_deg: float
    rms_el_deg: float
    max_az_deg: float
    max_el_deg: float


def throughput(
    method: str, array: VirtualArray, rig: Rig, targets: int, repeats: int, seed: int = 0
) -> float:
    """Best-of-``repeats`` target-frames per second for ``targets`` random targets in the grid."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(GRID_AZ_DEG[0], GRID_AZ_DEG[-1], targets)
    el = rng.uniform(GRID_EL_DEG[0], GRID_EL_DEG[-1], targets)
    solve_weights(az[:64], el[:64], rig=rig, array=array, method=method)  # builds the cache
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        solve_weights(az, el, rig=rig, array=array, method=method)
        best = min(best, time.perf_counter() - start)
    return targets / best


def run(targets: int = 1_000_000, repeats: int = 3, rig_name: str = "kit-table1") -> list[BenchRow]:
    """Measure every method on every array preset.

    The exact method's compiled kernel is loaded first (unless ``RTS_SCENARIO_JIT=off`` or
    numba is missing): in "auto" a process loads it only after a million targets, so a
    smaller ``targets`` would time the numpy code (`format_table` says which ran).
    """
    from .solver.compiled import exact_kernel

    exact_kernel(None)
    rig = Rig.preset(rig_name)
    rows = []
    for array_name in PRESETS:
        array = VirtualArray.preset(array_name)
        for method in METHODS:
            sol, err_az, err_el = angle_errors(method, array, rig)
            rows.append(BenchRow(
                method=method, array=array_name, rig=rig_name, targets=targets,
                throughput_per_s=throughput(method, array, rig, targets, repeats),
                feasible=int(sol.feasible.sum()), grid_points=len(sol.feasible),
                rms_az_deg=float(np.sqrt(np.mean(err_az**2))),
                rms_el_deg=float(np.sqrt(np.mean(err_el**2))),
                max_az_deg=float(np.abs(err_az).max()), max_el_deg=float(np.abs(err_el).max()),
            ))
    return rows


@dataclass(frozen=True)
class QuantizationRow:
    """Angle error left by an attenuator step, per array and quantization mode."""

    array: str
    step_db: float
    mode: str
    rms_deg: float
    max_deg: float


def quantization(step_db: float = 0.5, rig_name: str = "kit-table1") -> list[QuantizationRow]:
    """Exact weights on the evaluation grid through an attenuator with ``step_db`` steps.

    The error is the distance (deg) from the set angle to where the independent peak search
    finds the synthesized target, for naive rounding and for the quantization-aware choice.
    """
    from .kinematics import Tracks
    from .radar.profile import RadarProfile
    from .schedule import QUANTIZATION_MODES, build_schedule

    az, el = evaluation_grid()
    n = az.size
    ones = np.ones((1, n), dtype=bool)
    preset = Rig.preset(rig_name)
    limits = replace(preset.limits, attenuation_step_db=step_db, echoes_per_channel=n)
    rig = replace(preset, limits=limits)
    rows = []
    for array_name in PRESETS:
        radar = RadarProfile.preset(array_name)
        tracks = Tracks(names=tuple(f"p{i}" for i in range(n)), t_s=np.zeros(1),
                        range_m=np.full((1, n), 10.0), radial_velocity_mps=np.zeros((1, n)),
                        doppler_hz=np.zeros((1, n)), rcs_dbsm=np.full((1, n), 10.0),
                        az_deg=az[None], el_deg=el[None], position_m=np.zeros((1, n, 3)),
                        present=ones, in_coverage=ones, in_range=ones, in_velocity=ones)
        for mode in QUANTIZATION_MODES[::-1]:
            sch = build_schedule(tracks, rig, radar, quantization=mode)
            # The schedule solves for the FEs' echoes as the radar receives them on the bench:
            # superpose those (the model of `rts_scenario.responses`) to see the quantization.
            array = radar.steering_array
            vectors = radar.front_end_model.vectors(rig, np.arange(rig.n_front_ends), array)
            x = np.einsum("nc,mnc->nm", sch.weight[0], vectors[:, rig.quads[sch.quad[0]]])
            p_az, p_el = find_peak(array, x)
            err = np.hypot(p_az - az, p_el - el)
            rows.append(QuantizationRow(array=array_name, step_db=step_db, mode=mode,
                                        rms_deg=float(np.sqrt(np.mean(err**2))),
                                        max_deg=float(err.max())))
    return rows


def format_quantization(rows: list[QuantizationRow]) -> str:
    """Render the quantization rows as a table for people."""
    head = f"{'array':<13} {'attenuator step':>15} {'mode':<6} {'rms error':>10} {'max error':>10}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.array:<13} {r.step_db:>12.2f} dB {r.mode:<6} "
                     f"{r.rms_deg:>10.4f} {r.max_deg:>10.4f}")
    lines.append("angle errors in degrees (exact method, same grid and peak search as above)")
    return "\n".join(lines)


def format_table(rows: list[BenchRow]) -> str:
    """Render the rows as a fixed-width table for people."""
    from .solver.compiled import exact_kernel

    head = (f"{'method':<7} {'array':<13} {'target-frames/s':>16} {'feasible':>9} "
            f"{'rms az':>10} {'rms el':>10} {'max az':>10} {'max el':>10}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.method:<7} {r.array:<13} {r.throughput_per_s:>16,.0f} "
            f"{r.feasible:>4}/{r.grid_points:<4} "
            f"{_deg(r.rms_az_deg)} {_deg(r.rms_el_deg)} {_deg(r.max_az_deg)} {_deg(r.max_el_deg)}"
        )
    rig = rows[0].rig if rows else "?"
    lines.append(
        f"angle errors in degrees: independent Bartlett peak search, rig {rig}, "
        f"az {GRID_AZ_DEG[0]:g}..{GRID_AZ_DEG[-1]:g} ({GRID_AZ_DEG.size}) x "
        f"el {GRID_EL_DEG[0]:g}..{GRID_EL_DEG[-1]:g} ({GRID_EL_DEG.size}); "
        f"throughput: best of repeats, N = {rows[0].targets if rows else 0:,}; exact method: "
        + ("compiled kernel (numba)" if exact_kernel(0) is not None else
           "numpy code (RTS_SCENARIO_JIT=off, or numba missing or without a cache directory)")
    )
    return "\n".join(lines)


def _deg(value: float) -> str:
    return f"{value:>10.2e}" if value < 1e-2 else f"{value:>10.3f}"


@dataclass(frozen=True)
class HonestRow:
    """Detected angle error of a method on the honest simulated bench (FEs at their distance)."""

    method: str
    radar: str
    estimator: str
    fidelity: str
    rig: str
    rms_az_deg: float
    max_az_deg: float
    rms_el_deg: float
    max_el_deg: float
    missed: int


# (radar, estimator, fidelity) of the honest-bench table: both estimators on both small radars,
# the cascade imaging radar in the analytic fidelity (its ADC cube is large).
HONEST_CASES = (
    *((radar, estimator, fidelity) for radar in ("paper", "awr1843boost")
      for estimator in ("bartlett", "ti") for fidelity in ("analytic", "adc")),
    ("cascade-12x16", "bartlett", "analytic"),
)


def honest(rig_name: str = "kit-table1",
           cases: tuple[tuple[str, str, str], ...] = HONEST_CASES) -> list[HonestRow]:
    """Measure detected minus set angle on the evaluation grid per method, radar, fidelity.

    The simulated radar follows the physics (spherical paths from its physical antennas to each
    FE at its distance, the RTS delay model, noise off); the solver's methods work from the FE
    directions. The gap between the two is what synthesis for real geometry has to close.
    """
    from .calibration import grid_errors, simulated_measure
    from .radar.profile import RadarProfile
    from .radar.simulate import ChannelErrors

    rig = Rig.preset(rig_name)
    rows = []
    nan = float("nan")
    for radar_name, estimator, fidelity in cases:
        radar = RadarProfile.preset(radar_name)
        measure = simulated_measure(radar, rig, ChannelErrors.none(rig.n_front_ends),
                                    fidelity=fidelity, estimator=estimator)
        for method in (*METHODS, "estimator"):
            err = grid_errors(rig, radar, measure, method=method, estimator=estimator)
            az, el = np.abs(err[:, 0]), np.abs(err[:, 1])
            seen = np.isfinite(az) & np.isfinite(el)
            any_seen = bool(seen.any())
            rows.append(HonestRow(
                method=method, radar=radar_name, estimator=estimator, fidelity=fidelity,
                rig=rig_name,
                rms_az_deg=float(np.sqrt(np.mean(az[seen] ** 2))) if any_seen else nan,
                max_az_deg=float(az[seen].max()) if any_seen else nan,
                rms_el_deg=float(np.sqrt(np.mean(el[seen] ** 2))) if any_seen else nan,
                max_el_deg=float(el[seen].max()) if any_seen else nan,
                missed=int((~seen).sum())))
    return rows


def format_honest(rows: list[HonestRow]) -> str:
    """Render the honest-bench rows for people."""
    head = (f"{'method':<9} {'radar':<13} {'estimator':<9} {'fidelity':<9} {'rms az':>8} "
            f"{'max az':>8} {'rms el':>8} {'max el':>8} {'missed':>6}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.method:<9} {r.radar:<13} {r.estimator:<9} {r.fidelity:<9} "
                     f"{r.rms_az_deg:>8.4f} "
                     f"{r.max_az_deg:>8.4f} {r.rms_el_deg:>8.4f} {r.max_el_deg:>8.4f} "
                     f"{r.missed:>6}")
    rig = rows[0].rig if rows else "?"
    lines.append(f"detected angle errors in degrees on the honest simulated bench: rig {rig} "
                 f"(FEs at their distance), the same grid, noise off; missed: grid points the "
                 f"method could not synthesize or the radar did not see")
    return "\n".join(lines)


# The motorway scene's vehicles drift with this period (s), so no two frames one counter wrap
# (65,536 frames) apart see the same ground truth.
DRIFT_PERIOD_S = 60.0


def motorway_scene(duration_s: float) -> str:
    """Return a motorway scene of any length as YAML: four vehicles drifting around the ego.

    Speed profiles with a 60 s period keep every vehicle in the wide-3x5 rig's coverage for as
    long as the scene lasts; the awr1843boost radar runs in its analytic fidelity.
    """
    cycles = int(duration_s // DRIFT_PERIOD_S) + 2

    def profile(swing: float, phase: int) -> str:
        points = [f"{{t_s: {i * DRIFT_PERIOD_S / 2:g}, speed_mps: "
                  f"{25.0 + (swing if (i + phase) % 2 else -swing):g}}}"
                  for i in range(2 * cycles)]
        return "[" + ", ".join(points) + "]"

    vehicles = [("lead", "[35, 0, 0.6]", "{rcs_dbsm: 10.0, fluctuation: swerling1}", 0.4, 0),
                ("left", "[22, 3.5, 0.6]", "{rcs_dbsm: 9.0}", 0.3, 1),
                ("right", "[50, -3.5, 1.0]", "{rcs_dbsm: 12.0}", 0.5, 0),
                ("far", "[70, 0.3, 1.2]", "{rcs_dbsm: 15.0, fluctuation: swerling3}", 0.6, 1)]
    targets = "".join(
        f"  - {{name: {name}, rcs: {rcs},\n"
        f"     motion: {{type: speed_profile, position_m: {position},\n"
        f"              profile: {profile(swing, phase)}}}}}\n"
        for name, position, rcs, swing, phase in vehicles)
    return (f"rts_scenario: 1\nname: motorway-{duration_s:g}s\nduration_s: {duration_s:g}\n"
            "frame_rate_hz: 20.0\nseed: 3\n"
            "radar:\n  profile: awr1843boost\n  mount: {x_m: 3.7, z_m: 0.5}\n"
            "  fidelity: analytic\nrig: wide-3x5\n"
            "ego:\n  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 25.0}\n"
            f"targets:\n{targets}"
            "expectations:\n"
            "  tolerances: {range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 1.0}\n"
            "  detection_rate: 0.9\n")


@dataclass(frozen=True)
class EndToEndRow:
    """A scene run end to end through the pipeline."""

    scene: str
    duration_s: float
    frames: int
    targets: int
    wall_s: float
    realtime_factor: float
    target_frames_per_s: float
    solver_plan: str
    passed: bool


def end_to_end(duration_s: float = 60.0) -> EndToEndRow:
    """Run `motorway_scene` of ``duration_s`` through the pipeline and time it."""
    from .pipeline import run_scene
    from .scenario import load_scenario

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "motorway.scenario.yaml"
        path.write_text(motorway_scene(duration_s))
        scene = load_scenario(path)
        start = time.perf_counter()
        report = run_scene(scene).report
        wall = time.perf_counter() - start
    frames = scene.n_frames
    return EndToEndRow(scene=scene.name, duration_s=duration_s, frames=frames,
                       targets=len(scene.targets), wall_s=wall, realtime_factor=duration_s / wall,
                       target_frames_per_s=frames * len(scene.targets) / wall,
                       solver_plan=report.solver_plan, passed=report.passed)


def format_end_to_end(row: EndToEndRow) -> str:
    """Render the end-to-end row for people."""
    return (f"end to end: {row.scene} ({row.frames} frames x {row.targets} targets, simulated "
            f"radar, virtual CAN, checker) in {row.wall_s:.2f} s: {row.realtime_factor:.1f}x "
            f"real time, {row.target_frames_per_s:,.0f} target-frames/s, solver plan "
            f"{row.solver_plan}, {'PASS' if row.passed else 'FAIL'}")


def write_json(rows: list[BenchRow], quantized: list[QuantizationRow], path: str | Path,
               end: EndToEndRow | None = None, honest_rows: list[HonestRow] | None = None,
               figures: list[Any] | None = None) -> None:
    """Write the tables as JSON.

    ``{"solver", "quantization", "honest", "end_to_end", "performance"}``, every key always
    (docs/cli.md): a section not measured is ``[]``, or ``null`` for ``end_to_end``;
    ``performance`` holds `rts_scenario.perf.Figure` records.
    """
    data: dict[str, object] = {"solver": [asdict(r) for r in rows],
                               "quantization": [asdict(r) for r in quantized],
                               "honest": [asdict(r) for r in honest_rows or []],
                               "end_to_end": None if end is None else asdict(end),
                               "performance": [asdict(f) for f in figures or []]}
    write_atomic(path, json.dumps(strict(data), indent=2, allow_nan=False) + "\n")


def write_markdown(rows: list[BenchRow], quantized: list[QuantizationRow], path: str | Path,
                   end: EndToEndRow | None = None, honest_rows: list[HonestRow] | None = None,
                   figures: list[Any] | None = None) -> None:
    """Write the tables as Markdown, as the README shows them (``rts-scenario bench --markdown``).

    The speed-against-error tables as printed, in fenced blocks, then the performance figures
    (`rts_scenario.perf.Figure`) as a Markdown table; a section not measured is left out.
    """
    from .perf import format_markdown

    def block(text: str) -> str:
        return f"```\n{text}\n```"

    parts = ["### Speed against error", block(f"{format_table(rows)}\n\n"
                                              f"{format_quantization(quantized)}")]
    if honest_rows:
        parts += ["### The honest simulated bench", block(format_honest(honest_rows))]
    if end is not None:
        parts += ["### End to end", block(format_end_to_end(end))]
    if figures:
        parts += ["### Performance against its comparisons", format_markdown(figures)]
    write_atomic(path, "\n\n".join(parts) + "\n")
