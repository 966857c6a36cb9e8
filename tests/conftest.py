"""Shared fixtures: scenario files written on the fly."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def scenario_text(name: str = "t", duration_s: float = 0.5, output_rate_Hz: float = 1000.0, state: str = "steady",
                  temperature: str = "start_C = 25.0", fidelity: str = "carrier", noise: bool = False,
                  seed: int = 1) -> str:
    """A config-A scenario's TOML up to its [noise] table (append profile tables after it)."""
    return f"""
[scenario]
name = "{name}"
device_file = "{REPO / 'scenarios' / 'devices' / 'fmvmg_a.toml'}"
duration_s = {duration_s}
output_rate_Hz = {output_rate_Hz}
seed = {seed}
fidelity = "{fidelity}"
[initial]
state = "{state}"
[temperature]
{temperature}
[noise]
brownian = {str(noise).lower()}
electronic = {str(noise).lower()}
flicker = {str(noise).lower()}
quantization = {str(noise).lower()}
rate_random_walk = {str(noise).lower()}
"""


@pytest.fixture
def make_scenario(tmp_path):
    """Write a scenario TOML (device config A by default) and return its path."""
    def _make(body: str = "", name: str = "t", duration_s: float = 0.5, output_rate_Hz: float = 1000.0,
              state: str = "steady", temperature_C: float = 25.0, fidelity: str = "carrier", noise: bool = False,
              seed: int = 1):
        text = scenario_text(name, duration_s, output_rate_Hz, state, f"start_C = {temperature_C}", fidelity, noise,
                             seed) + body
        p = tmp_path / f"{name}.toml"
        p.write_text(text)
        return p
    return _make
