"""Packaging: every sub-package is installed, and the shipped scenarios travel with the package."""

import tomllib

from .conftest import REPO


def test_every_package_is_listed_in_pyproject():
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = set()
    for top in ("blocks", "fmvmg_sim"):
        for init in (REPO / top).rglob("__init__.py"):
            found.add(".".join(init.parent.relative_to(REPO).parts))
    assert found <= listed, sorted(found - listed)
    assert "fmvmg_sim.scenarios" in listed


def test_scenarios_are_found():
    from fmvmg_sim.device import DEVICES_DIR
    from fmvmg_sim.paths import scenarios_dir
    assert (scenarios_dir() / "startup.toml").is_file()
    assert (DEVICES_DIR / "fmvmg_a.toml").is_file()
