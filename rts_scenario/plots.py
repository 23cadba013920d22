"""PNG plots of a run: the scene and coverage, the schedule, the errors (needs matplotlib)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .arrays import FloatArray
from .atomic import open_atomic
from .errors import RtsError
from .plot_data import ERROR_KEYS
from .quads import quad_polygons

if TYPE_CHECKING:


    from .pipeline import RunResult


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RtsError("--plot needs matplotlib: pip install 'rts-scenario[plot]'") from None
    return plt


def require_matplotlib() -> None:
    """Raise the `RtsError` plots would raise without matplotlib (before a run, not after)."""
    _pyplot()


def safe_stem(name: str) -> str:
    """Return a file name stem for a scene or rig name: only ``[A-Za-z0-9._=[]-]``, no leading dot.

    Names come from files anyone may write; a stem never leaves the plot folder. ``=`` and
    brackets are kept so that a run of a parametrized scene keeps the name pytest gives it
    (``cut-in[estimator=ti]``). A name longer than `MAX_STEM` is cut, with a digest of it.
    """
    stem = re.sub(r"[^A-Za-z0-9._=\[\]-]+", "_", name).lstrip(".") or "scene"
    if len(stem) > MAX_STEM:
        # A file name holds 255 bytes: a long name (a scene's, a variant's id with a long
        # value) keeps its start and a digest of the whole, which tells it from its kin.
        import hashlib

        digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:10]
        stem = f"{stem[:MAX_STEM - 11]}-{digest}"
    return stem


# The longest stem `safe_stem` gives: room beside it in a file name of 255 bytes for what a
# run adds (a log's own stem and suffix, "-calibration.png", a sidecar's ".rts.json").
MAX_STEM = 120


# The errors plotted, by tolerance key (the keys `PlotData.errors` gathers them by): labels.
_ERRORS = dict(zip(ERROR_KEYS, ("range (m)", "radial velocity (m/s)", "azimuth (deg)",
                                "elevation (deg)"), strict=True))



def write_plots(result: RunResult, folder: str | Path, stem: str | None = None) -> list[Path]:
    """Write the run's plots into ``folder``; return the files written.

    ``stem`` starts every file name (default: the scene's name, made safe by `safe_stem`).
    The plots draw what the run gathered (`RunResult.plot`, `RunOptions.plot`): a long
    scene's series thinned to their first, last and extreme samples (`Envelope`).
    """
    plt = _pyplot()
    data = result.plot
    if data is None:
        raise RtsError("plots need the run's plot data: run with RunOptions(plot=True)")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    scene = result.scene
    stem = safe_stem(stem if stem is not None else scene.name)
    names = [t.name for t in scene.targets]
    colors = plt.cm.tab10(np.arange(len(names)) % 10)
    written = []

    fig, (top, angles) = plt.subplots(1, 2, figsize=(13, 5.5))
    _, x = data.x_m.samples()
    _, y = data.y_m.samples()
    _, az = data.az_deg.samples()
    _, el = data.el_deg.samples()
    _, az_ok = data.checkable_az_deg.samples()
    _, el_ok = data.checkable_el_deg.samples()
    for k, name in enumerate(names):
        seen = ~np.isnan(x[:, k])
        top.plot(y[seen, k], x[seen, k], color=colors[k], label=name)
        angles.plot(az[seen, k], el[seen, k], color=colors[k])
        ok = ~np.isnan(az_ok[:, k])
        angles.plot(az_ok[ok, k], el_ok[ok, k], ".", ms=2, color=colors[k])
    _draw_ends(top, y, x, colors)
    _draw_ends(angles, az, el, colors)
    for poly in quad_polygons(scene.rig):
        ring = np.vstack([poly, poly[:1]])
        angles.fill(ring[:, 0], ring[:, 1], color="0.85", zorder=0)
        angles.plot(ring[:, 0], ring[:, 1], color="0.6", lw=0.8, zorder=0)
    # Under the targets' tracks: a target straight ahead is often in an FE's direction.
    angles.plot(scene.rig.az_deg, scene.rig.el_deg, "k^", ms=6, label="front ends", zorder=1)
    top.set(xlabel="y (m, left)", ylabel="x (m, forward)",
            title="targets seen from the radar (o: start, dot: end)")
    top.invert_xaxis()
    if top.get_legend_handles_labels()[0]:  # no target: nothing to name
        top.legend(fontsize=7, loc="best")
    angles.set(xlabel="azimuth (deg, left)", ylabel="elevation (deg)",
               title="directions and rig coverage (dots: checkable frames)")
    angles.invert_xaxis()
    angles.legend(fontsize=7, loc="best")
    fig.suptitle(f"{stem}: scene")
    written.append(_save(fig, folder / f"{stem}-scene.png"))

    fig, (att, delay) = plt.subplots(2, 1, figsize=(12, 7), sharex=True)
    t_att, attenuation = data.attenuation_db.samples()
    t_delay, delay_ns = data.delay_ns.samples()
    played = []
    for k, name in enumerate(names):
        for c in range(4):
            on = ~np.isnan(attenuation[:, 4 * k + c])
            if on.any():  # each target named once, on its first channel that plays
                att.plot(t_att[on, 4 * k + c], attenuation[on, 4 * k + c], ".", ms=2,
                         color=colors[k], label=None if name in played else name)
                played.append(name)
        on = ~np.isnan(delay_ns[:, k])
        delay.plot(t_delay[on, k], delay_ns[on, k], ".", ms=2, color=colors[k])
    att.set(ylabel="attenuation per channel (dB)",
            title="schedule" if played else "schedule: no target played")
    if played:
        att.legend(fontsize=7, loc="best", markerscale=4)
    delay.set(xlabel="time (s)", ylabel="RTS delay (ns)")
    written.append(_save(fig, folder / f"{stem}-schedule.png"))

    fig, axes = plt.subplots(len(_ERRORS), 1, figsize=(12, 9), sharex=True)
    for ax, (key, label) in zip(axes, _ERRORS.items(), strict=True):
        tol = scene.expectations.tolerances[key]
        ax.axhspan(-tol, tol, color="0.9", zorder=0)
        t, err = data.errors[key].samples()
        for k in range(len(names)):
            ax.plot(t[:, k], err[:, k], ".", ms=2, color=colors[k])
        ax.set_ylabel(label)
    t_missed, _ = data.missed.samples()
    for k in range(len(names)):
        t = t_missed[~np.isnan(t_missed[:, k]), k]
        axes[0].plot(t, np.zeros_like(t), "x", ms=3, color=colors[k])
    axes[0].set_title("detection errors (band: tolerance; x: missed)")
    axes[-1].set_xlabel("time (s)")
    written.append(_save(fig, folder / f"{stem}-errors.png"))
    return written


def _draw_ends(ax: Any, x: FloatArray, y: FloatArray, colors: FloatArray) -> None:
    """Mark where each column's path (x, y: (P, K), NaN where none) starts and ends.

    A target that does not move has a path of no length: the marks are all it shows.
    """
    seen = ~np.isnan(x) & ~np.isnan(y)
    has = seen.any(axis=0)
    if not has.any():  # no target, or none present
        return
    columns = np.flatnonzero(has)
    first = np.argmax(seen, axis=0)[has]
    last = (x.shape[0] - 1 - np.argmax(seen[::-1], axis=0))[has]
    ax.scatter(x[first, columns], y[first, columns], s=36, facecolors="none",
               edgecolors=colors[has], zorder=2)
    ax.scatter(x[last, columns], y[last, columns], s=12, color=colors[has], zorder=2)


def _save(fig: Any, path: Path) -> Path:
    """Save ``fig`` as the PNG ``path``, replaced whole (`open_atomic`), and close it."""
    fig.tight_layout()
    with open_atomic(path, "wb") as file:
        fig.savefig(file, dpi=110, format="png")
    fig.clf()
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def write_calibration_plot(result: Any, folder: str | Path, name: str) -> Path:
    """Plot every pair's delay sweep and its fitted model.

    The position along the pair against the phase each delay step gives.
    """
    plt = _pyplot()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    pairs = result.pairs
    cols = min(3, len(pairs))
    rows = int(np.ceil(len(pairs) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, p in zip(axes.ravel(), pairs, strict=False):
        order = np.argsort(p.sweep_deg)
        ax.plot(p.sweep_deg[order], p.model_shift_deg[order], "-", lw=1, label="model fit")
        ax.plot(p.sweep_deg, p.shift_deg, "o", ms=3, label="radar")
        ax.axvline(p.phase_deg, color="k", lw=0.8)
        ax.set(title=f"FE {p.a}-{p.b}: {p.phase_deg:+.2f} deg, {p.gain_db:+.3f} dB",
               xlabel="phase of FE b's delay step (deg)", ylabel="along the pair (deg)")
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(pairs):]:
        ax.axis("off")
    return _save(fig, folder / f"{safe_stem(name)}-calibration.png")


# A sweep plot's value for a run without the parameter (another scene's runs).
_NOT_SET = "(not set)"


def write_sweep_plot(entries: list[dict[str, Any]], path: str | Path) -> Path:
    """Plot a sweep's verdicts over its parameters into one PNG; return the file.

    One parameter that every run has: each run's verdict (pass, fail, error, xfail, xpass,
    skipped) against the parameter's value, one row per scene. Two that every run has: a grid
    of the pass rate over both values, each cell marked ``passed/runs``. Otherwise (more, none,
    or parameters some runs lack, as scenes parametrized over different keys): the pass rate
    per value of each parameter (per scene when no run has a parameter), one panel each, the
    runs without the parameter as the value ``(not set)``: every run is in every panel. Rates
    are over the runs that ran, as in the sweep's summary (skipped runs left out).
    """
    from .sweep import value_name

    plt = _pyplot()
    keys = list(dict.fromkeys(k for e in entries for k in e["parameters"]))
    colors = {"pass": "tab:green", "fail": "tab:red", "error": "tab:orange",
              "xfail": "tab:purple", "xpass": "tab:blue", "skipped": "tab:gray"}
    markers = {"pass": "o", "fail": "X", "error": "s", "xfail": "x", "xpass": "P",
               "skipped": "_"}
    ran = [e for e in entries if e["status"] != "skipped"]

    def values_of(key: str) -> list[str]:
        return list(dict.fromkeys(value_name(e["parameters"][key]) if key in e["parameters"]
                                  else _NOT_SET for e in entries))

    # The verdict and grid plots only where every run has the keys: a run without one had no
    # place in them and was left out of the plot.
    everywhere = all(k in e["parameters"] for e in entries for k in keys)
    if len(keys) == 1 and everywhere:
        key = keys[0]
        values = values_of(key)
        scenes = list(dict.fromkeys(str(e["scene"]) for e in entries))
        fig, ax = plt.subplots(figsize=(max(6.0, 0.6 * len(values) + 3), 1.2 + 0.5 * len(scenes)))
        for status in colors:
            picked = [e for e in entries if e["status"] == status and key in e["parameters"]]
            if not picked:
                continue
            ax.plot([values.index(value_name(e["parameters"][key])) for e in picked],
                    [scenes.index(str(e["scene"])) for e in picked], markers[status], ms=10,
                    color=colors[status], label=status, linestyle="none")
        ax.set_xticks(range(len(values)), values)
        ax.set_yticks(range(len(scenes)), scenes)
        ax.set_xlim(-0.5, len(values) - 0.5)
        ax.set_ylim(-0.5, len(scenes) - 0.5)
        ax.set(xlabel=key, title="sweep: verdict per run")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    elif len(keys) == 2 and everywhere:
        (kx, ky), (xs, ys) = keys, (values_of(keys[0]), values_of(keys[1]))
        runs = np.zeros((len(ys), len(xs)))
        passed = np.zeros_like(runs)
        for e in ran:
            p = e["parameters"]
            if kx in p and ky in p:
                cell = (ys.index(value_name(p[ky])), xs.index(value_name(p[kx])))
                runs[cell] += 1
                passed[cell] += e["status"] == "pass"
        rate = np.full_like(runs, np.nan)
        np.divide(passed, runs, out=rate, where=runs > 0)
        fig, ax = plt.subplots(figsize=(max(5.0, 0.8 * len(xs) + 3), max(3.0, 0.5 * len(ys) + 2)))
        image = ax.imshow(rate, cmap="RdYlGn", vmin=0.0, vmax=1.0, origin="lower",
                          aspect="auto")
        for (i, j), n in np.ndenumerate(runs):
            if n:
                ax.text(j, i, f"{passed[i, j]:.0f}/{n:.0f}", ha="center", va="center",
                        fontsize=8)
        ax.set_xticks(range(len(xs)), xs)
        ax.set_yticks(range(len(ys)), ys)
        ax.set(xlabel=kx, ylabel=ky, title="sweep: runs passed per combination")
        fig.colorbar(image, ax=ax, label="pass rate")
    else:
        # One panel per parameter; without parameters, one for the scenes.
        groups: list[tuple[str, list[str], str | None]] = [
            (key, values_of(key), key) for key in keys] or [
            ("scene", list(dict.fromkeys(str(e["scene"]) for e in entries)), None)]

        def value_of(entry: dict[str, Any], key: str | None) -> str:
            if key is None:
                return str(entry["scene"])
            return value_name(entry["parameters"][key]) if key in entry["parameters"] \
                else _NOT_SET

        fig, axes = plt.subplots(len(groups), 1, figsize=(8, 2.2 * len(groups)), squeeze=False)
        for ax, (label, values, key) in zip(axes[:, 0], groups, strict=True):
            runs_of = [[e for e in ran if value_of(e, key) == v] for v in values]
            rates = [sum(e["status"] == "pass" for e in r) / len(r) if r else 0.0
                     for r in runs_of]
            ax.bar(range(len(values)), rates, color=[plt.cm.RdYlGn(r) for r in rates])
            for i, r in enumerate(runs_of):
                ax.text(i, 0.02, f"{sum(e['status'] == 'pass' for e in r)}/{len(r)}",
                        ha="center", fontsize=7)
            ax.set_xticks(range(len(values)), values, fontsize=7)
            ax.set(ylim=(0, 1.05), ylabel="pass rate", xlabel=label)
        axes[0, 0].set_title("sweep: pass rate per parameter value")
    return _save(fig, Path(path))
