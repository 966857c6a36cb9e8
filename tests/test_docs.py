"""The user documentation: its example runs, and its generated pages match the code."""

import re

import pytest

from .conftest import REPO

DOCS = REPO / "docs"


def _python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


@pytest.mark.slow
def test_the_python_api_example_runs(tmp_path, monkeypatch):
    blocks = [b for b in _python_blocks(DOCS / "python_api.md") if not b.startswith("# not run in the tests")]
    assert len(blocks) >= 4
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for block in blocks:
        exec(compile(block, str(DOCS / "python_api.md"), "exec"), namespace)
    assert (tmp_path / "startup.csv").is_file() and (tmp_path / "allan.png").is_file()


def test_the_scenario_page_matches_the_schemas():
    from fmvmg_sim.schema_doc import markdown
    assert (DOCS / "scenarios.md").read_text() == markdown(), \
        "docs/scenarios.md is stale: python -m fmvmg_sim.schema_doc > docs/scenarios.md"


def test_every_scenario_and_device_key_has_a_meaning():
    from fmvmg_sim.schema_doc import MEANINGS, all_keys
    keys = all_keys()
    assert set(keys) == set(MEANINGS), (sorted(set(keys) - set(MEANINGS)), sorted(set(MEANINGS) - set(keys)))


def test_units_are_read_from_the_key_names():
    from fmvmg_sim.schema_doc import unit_of
    assert unit_of("circuit.pi.ki_per_s") == "1/s"
    assert unit_of("noise.rate_random_walk_dps_per_sqrt_s") == "deg/s/sqrt(s)"
    assert unit_of("mechanics.duffing_k3_drive_N_per_m3") == "N/m^3"
    assert unit_of("mechanics.q_drive") == "1"


def test_the_formats_page_names_every_command_column_and_effect():
    from fmvmg_sim.cli.main import SUBCOMMANDS
    from fmvmg_sim.effects import EFFECT_NAMES
    from fmvmg_sim.record import KNOWN_COLUMNS
    text = (DOCS / "formats.md").read_text()
    for command in SUBCOMMANDS:
        assert f"`fmvmg {command}" in text, command
    for column in KNOWN_COLUMNS:
        assert f"| `{column}` |" in text, column
    for effect in EFFECT_NAMES:
        assert f"`{effect}`" in text, effect
    for key in ('"verdict"', '"accepted"', '"ambiguous_with"', '"ranked"', '"localization"', '"in_sample"',
                "arw_deg_per_sqrt_h", "bias_instability_deg_per_h", "truth_rms_dps"):
        assert key in text, key


def test_links_between_the_docs_resolve():
    for page in [REPO / "README.md", *DOCS.glob("*.md")]:
        for target in re.findall(r"\]\(([^)#\s]+)\)", page.read_text()):
            if "://" in target:
                continue
            assert (page.parent / target).exists(), f"{page.name}: {target}"


def test_the_readme_is_a_short_guide_that_starts_with_the_two_commands():
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    block = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1).splitlines()
    assert block[0].startswith("pip install . && fmvmg run ")
    assert block[1] == "pip install '.[test]' && python -m pytest -n 2 -q"  # .ci/run runs this
    for picture in re.findall(r"!\[[^]]*\]\(([^)]+)\)", text):
        assert (REPO / picture).is_file(), picture


def test_the_shipped_scenario_table_lists_every_shipped_scenario():
    from fmvmg_sim.paths import shipped_scenarios
    text = (DOCS / "model.md").read_text()
    for name in shipped_scenarios():
        assert f"`{name}`" in text, name


def test_the_bias_tc_table_matches_the_devices():
    """docs/model.md states each shipped device's bias TC and its die and board shares as the averaged model gives them."""
    from fmvmg_sim.averaged import bias_temperature_coefficients_dph_per_K
    from fmvmg_sim.device import DEVICES_DIR, load_device
    text = (DOCS / "model.md").read_text()
    rows = {m.group(1): [float(x) for x in m.group(2, 3, 4)]
            for m in re.finditer(r"^\| `(\w+)` \| ([-+]\d+) \| ([-+]\d+) \| ([-+]\d+) \|$", text, flags=re.M)}
    assert set(rows) == {p.stem for p in DEVICES_DIR.glob("*.toml")}
    for name, stated in rows.items():
        tc = bias_temperature_coefficients_dph_per_K(load_device(name))
        assert stated == pytest.approx([tc["total"], tc["die"], tc["board"]], abs=1.0), name
