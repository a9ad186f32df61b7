"""The house rules the code keeps (docs/architecture.md): one home for the store, for the
errors and for the walk's vocabulary, the 2-D half free of the 3-D one, code laid out by
ruff."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("sim", "algorithms", "workers", "orchestrator", "hardware")


def sources() -> list[Path]:
    """Every Python file of the package."""
    return sorted(p for layer in LAYERS for p in (ROOT / layer).rglob("*.py"))


def test_ruff_lays_the_code_out_but_for_a_few_kernels_argument_lists():
    marked = [p for p in sources() for line in p.read_text().splitlines() if "fmt: skip" in line]
    assert len(marked) <= 10, marked
    assert {p.parent.name for p in marked} <= {"kernels"}


def test_no_mlflow_client_is_built_outside_the_store():
    outside = [
        p.relative_to(ROOT)
        for p in sources()
        if "MlflowClient(" in p.read_text() and p.parent != ROOT / "workers" / "store"
    ]
    assert outside == []


def test_the_store_keeps_its_client_private():
    calls = [
        (p.relative_to(ROOT), m.group(0))
        for p in sources()
        for m in re.finditer(r"\bstore\.client\b|\b_client\.", p.read_text())
        if p.parent != ROOT / "workers" / "store"
    ]
    assert calls == []


@pytest.mark.parametrize(
    "module", ["linkevo.sim.robot.walk_features", "linkevo.sim.robot.walk_rows", "linkevo.sim"]
)
def test_the_walks_vocabulary_and_features_load_no_physics(module: str):
    code = f"import sys, {module}; print(any(m.split('.')[0] == 'mujoco' for m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"


def test_the_2d_linkage_never_imports_the_3d_robot():
    found = [
        p.relative_to(ROOT)
        for p in (ROOT / "sim" / "linkage").rglob("*.py")
        if "linkevo.sim.robot" in p.read_text()
    ]
    assert found == []


def test_every_exception_the_package_defines_is_a_linkevo_error():
    from linkevo.sim.errors import LinkevoError

    outside = []
    for layer in LAYERS:
        package = importlib.import_module(f"linkevo.{layer}")
        for info in pkgutil.walk_packages(package.__path__, f"linkevo.{layer}."):
            if info.name.rsplit(".", 1)[-1] in ("__main__", "ui_app"):  # they run on import
                continue
            module = importlib.import_module(info.name)
            for name, value in vars(module).items():
                if (
                    inspect.isclass(value)
                    and issubclass(value, BaseException)
                    and value.__module__ == info.name
                    and not issubclass(value, LinkevoError)
                ):
                    outside.append(f"{info.name}.{name}")
    assert outside == []


def test_a_floor_is_spelled_once():
    spelled = [
        (p.relative_to(ROOT), line.strip())
        for p in sources()
        for line in p.read_text().splitlines()
        if '"carpet"' in line or "'carpet'" in line
    ]
    assert len(spelled) == 1, spelled
