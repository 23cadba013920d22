"""The stages import only what comes before them (read from the source, nothing is run)."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "rts_scenario"

# (module, prefix it must not import): a stage never reaches into a later stage or into a
# consumer of its own output.
FORBIDDEN = [
    ("kinematics", "rts_scenario.solver"),
    ("kinematics", "rts_scenario.schedule"),
    ("canbus", "rts_scenario.radar"),
    ("canbus", "rts_scenario.check"),
    ("check", "rts_scenario.canbus"),
    ("check", "rts_scenario.radar"),
    ("check", "rts_scenario.outputs"),
    ("detections", "rts_scenario.canbus"),
    ("detections", "rts_scenario.radar"),
    ("rig", "rts_scenario.solver"),
    ("quads", "rts_scenario.solver"),
    ("solver", "rts_scenario.schedule"),
    ("schedule", "rts_scenario.outputs"),
    ("radar", "rts_scenario.canbus"),
    ("radar", "rts_scenario.check"),
    ("peak_search", "rts_scenario.solver"),  # the measuring instrument shares nothing with it
    ("peak_search", "rts_scenario.beamformer"),
]


def imports_of(module: str) -> set[str]:
    """Absolute names of every module imported by a module or package (any depth)."""
    base = PACKAGE / module
    files = sorted(base.rglob("*.py")) if base.is_dir() else [base.with_suffix(".py")]
    out = set()
    for path in files:
        # The package a relative import starts from: the file's folder.
        package = ".".join(("rts_scenario", *path.relative_to(PACKAGE).parent.parts))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                out |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                    name = f"{parent}.{node.module}" if node.module else parent
                else:
                    name = node.module or ""
                out.add(name)
                out |= {f"{name}.{a.name}" for a in node.names}
    return out


@pytest.mark.parametrize("module, prefix", FORBIDDEN)
def test_no_import_runs_back_up(module, prefix):
    bad = sorted(n for n in imports_of(module) if n == prefix or n.startswith(prefix + "."))
    assert not bad, f"rts_scenario.{module} imports {', '.join(bad)}"


def test_the_reader_sees_imports():
    # The check above must be able to fail: the pipeline does import the checker and canbus.
    names = imports_of("pipeline")
    assert "rts_scenario.check" in names and "rts_scenario.canbus" in names
    assert "rts_scenario.detections.Detections" in imports_of("canbus")


def test_the_simulated_radar_runs_without_the_solver():
    # The honest bench must not share the solver's assumptions: loading it loads none of the
    # solver's or the schedule's code (it reads a schedule's arrays, the type only for mypy).
    code = ("import sys, rts_scenario.radar.simulate; print(sorted(m for m in sys.modules if "
            "m.startswith(('rts_scenario.solver', 'rts_scenario.schedule'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout
    assert loaded.strip() == "[]"
