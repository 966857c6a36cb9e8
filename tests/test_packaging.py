"""Packaging: every sub-package is installed, and the shipped scenarios travel with the built wheel.

The wheel test builds the wheel, unpacks it into a folder outside the source tree and imports
the package from there in a fresh interpreter whose working directory is elsewhere, so a path
that only exists in a checkout makes it fail (the editable install the suite runs on cannot).
"""

import ast
import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

import pytest

from fmvmg_sim.paths import devices_dir, resolve_device, resolve_scenario, scenarios_dir, shipped_scenarios

from .conftest import REPO


def test_every_package_is_listed_in_pyproject():
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = set()
    for top in ("blocks", "fmvmg_sim"):
        for init in (REPO / top).rglob("__init__.py"):
            found.add(".".join(init.parent.relative_to(REPO).parts))
    assert found <= listed, sorted(found - listed)
    assert "fmvmg_sim.scenarios" in listed


def test_the_product_never_imports_the_validation_harness():
    # the harnesses measure the product; a user's command path (everything but the validation package itself
    # and the command-line faces of its harness commands) must not depend on them
    offenders = []
    for path in (REPO / "fmvmg_sim").rglob("*.py"):
        rel = path.relative_to(REPO / "fmvmg_sim")
        if rel.parts[0] == "validation" or rel.as_posix() in ("cli/diagnose_benchmark.py", "cli/diagnose_independent.py",
                                                                       "cli/compensate_eval.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                mod = "." * node.level + (node.module or "")
                names = [a.name for a in node.names]
                ours = node.level > 0 or mod.split(".")[0] == "fmvmg_sim"
                if ours and ("validation" in mod.split(".") or "validation" in names):
                    offenders.append(f"{rel}: from {mod} import {', '.join(names)}")
            elif isinstance(node, ast.Import):
                offenders += [f"{rel}: import {a.name}" for a in node.names if a.name.startswith("fmvmg_sim.validation")]
    assert not offenders, offenders


def test_shipped_scenarios_and_devices_are_real_files():
    assert (scenarios_dir() / "startup.toml").is_file()
    assert (devices_dir() / "fmvmg_a.toml").is_file()
    assert {"startup", "nominal_a", "oven_004"} <= set(shipped_scenarios())


def test_a_scenario_name_resolves_to_the_shipped_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_scenario("startup") == scenarios_dir() / "startup.toml"
    assert resolve_scenario("startup.toml") == scenarios_dir() / "startup.toml"
    (tmp_path / "oven_000").mkdir()  # an earlier run's output folder of that name is not the scenario
    assert resolve_scenario("oven_000") == scenarios_dir() / "oven_000.toml"
    (tmp_path / "startup.toml").write_text("")  # a file of that name in the working folder wins
    assert resolve_scenario("startup.toml").resolve() == (tmp_path / "startup.toml").resolve()
    assert resolve_scenario("elsewhere/startup.toml") == tmp_path.joinpath("elsewhere/startup.toml").relative_to(tmp_path)


@pytest.mark.parametrize("device_file", ["fmvmg_a", "fmvmg_a.toml", "devices/fmvmg_a.toml"])
def test_a_scenario_copied_out_of_the_tree_finds_the_shipped_device(tmp_path, device_file):
    from fmvmg_sim.scenario import load_scenario
    p = tmp_path / "mine.toml"
    p.write_text(f'[scenario]\ndevice_file = "{device_file}"\nduration_s = 0.1\n')
    assert resolve_device(device_file, tmp_path) == devices_dir() / "fmvmg_a.toml"
    assert load_scenario(p).device.name == "fmvmg-a"


def test_a_device_beside_the_scenario_wins_over_the_shipped_one(tmp_path):
    (tmp_path / "devices").mkdir()
    local = tmp_path / "devices" / "fmvmg_a.toml"
    local.write_text((devices_dir() / "fmvmg_a.toml").read_text())
    assert resolve_device("devices/fmvmg_a.toml", tmp_path) == local


@pytest.fixture(scope="module")
def unpacked_wheel(tmp_path_factory):
    """The project's wheel, built from the source tree and unpacked into a folder outside it."""
    src = tmp_path_factory.mktemp("src") / "fmvmg-sim"
    # a clean copy: a build/ folder left in the tree by an earlier build would be packed instead of the sources
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(".*", "build", "dist", "*.egg-info", "__pycache__",
                                                             "out", "docs", "tests", "benchmarks"))
    wheels = tmp_path_factory.mktemp("wheel")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(src)],
                           capture_output=True, text=True)
    if build.returncode != 0 and "No matching distribution" in build.stderr:
        pytest.skip("the build backend cannot be installed here (no package index)")
    assert build.returncode == 0, build.stderr
    (wheel,) = wheels.glob("fmvmg_sim-*.whl")
    site = tmp_path_factory.mktemp("site")
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    return site


def test_the_built_wheel_finds_every_shipped_scenario_and_device(unpacked_wheel, tmp_path):
    code = """
import json, fmvmg_sim
from fmvmg_sim import paths
from fmvmg_sim.scenario import load_scenario
names = paths.shipped_scenarios()
loaded = {n: load_scenario(n).device.name for n in names}
print(json.dumps({"package": fmvmg_sim.__file__, "scenarios_dir": str(paths.scenarios_dir()),
                  "loaded": loaded, "devices": paths.shipped_devices()}))
"""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(unpacked_wheel)
    run = subprocess.run([sys.executable, "-P", "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["package"].startswith(str(unpacked_wheel)), out["package"]  # the wheel's copy, not the checkout
    assert out["scenarios_dir"].startswith(str(unpacked_wheel))
    shipped = sorted(p.stem for p in (REPO / "scenarios").glob("*.toml"))
    assert sorted(out["loaded"]) == shipped
    assert out["devices"] == sorted(p.stem for p in (REPO / "scenarios" / "devices").glob("*.toml"))
