"""The drive-loop comparison's readings (start-up times, hold means) on records whose answers are known."""

import numpy as np
import pytest

from fmvmg_sim.validation.drive_loops import hold_means, startup_figures


class _Rec:
    def __init__(self, t, **ch):
        self.time_s, self.ch = t, ch

    def __getitem__(self, k):
        return self.ch[k]


def test_startup_figures_read_a_first_order_rise_and_a_frequency_glitch():
    t = np.arange(1, 2001) / 2000.0
    a = 0.45 * (1 - np.exp(-t / 0.01))
    f = np.full_like(t, 30740.0)
    f[(t > 0.2) & (t < 0.25)] += 1.0  # a 50 ms excursion of 1 Hz ends at 0.25 s
    fig = startup_figures(_Rec(t, drive_amplitude_V=a, drive_frequency_Hz=f), 0.45)
    assert fig["t90_s"] == pytest.approx(0.01 * np.log(10), abs=1e-3)
    assert fig["settled_s"] == pytest.approx(0.255, abs=0.006)  # the 10 ms moving mean


def test_hold_means_take_the_second_half_of_each_long_hold():
    t = np.arange(0, 3000.0, 1.0)
    T = np.where(t < 1000, 25.0, np.where(t < 1100, 25 + (t - 1000) * 0.35, 60.0))
    r = np.where(t <= 1000, 0.01, np.where(t < 1100, 5.0, 0.02)) + np.where(t % 2 == 0, 1e-3, -1e-3)
    Ts, bs = hold_means(_Rec(t, temperature_C=T, rate_dps=r))
    assert Ts == pytest.approx([25.0, 60.0])
    assert bs == pytest.approx([36.0, 72.0], abs=0.01)
