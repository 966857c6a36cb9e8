"""Noise-level effects: the flicker band's excess, and its shape (flat for flicker, rising as tau^2 for a wander)."""

import numpy as np

from fmvmg_sim.analysis.allan import allan_deviation
from fmvmg_sim.diagnosis.noise_effects import WANDER_RISE_OVER_FLAT, WANDER_Z_RISE, band_excess, band_shape

N, FS = 40000, 1.0
WHITE_DPS = 0.01


def _adev(x):
    ad = allan_deviation(x, FS)
    return np.asarray(ad.taus_s), np.asarray(ad.adev)


def _pink(rng, level):
    # 1/f power: shape white noise by f^-1/2 in amplitude
    X = np.fft.rfft(rng.standard_normal(N))
    f = np.fft.rfftfreq(N, 1 / FS)
    X[1:] /= np.sqrt(f[1:] / f[1])
    X[0] = 0.0
    x = np.fft.irfft(X, N)
    return level * x / x.std()


def _curves(extra):
    rng = np.random.default_rng(7)
    nulls = [_adev(WHITE_DPS * rng.standard_normal(N))[1] for _ in range(4)]
    taus, meas = _adev(WHITE_DPS * rng.standard_normal(N) + extra(rng))
    return taus, meas, nulls


def test_flicker_excess_is_flat_and_a_wander_rises():
    # flicker: its Allan variance is flat in tau, so the band's excess is all in the flat part
    # (a weak one, a band z of about 6 against the white nulls)
    taus, meas, nulls = _curves(lambda rng: _pink(rng, 0.003))
    assert band_excess(taus, meas, nulls, span_s=N)[1] > 3
    z_flat, z_rise = band_shape(taus, meas, nulls, span_s=N)
    assert z_flat > 5 and z_rise < WANDER_Z_RISE and z_rise < z_flat / WANDER_RISE_OVER_FLAT
    # a 50 min sine: its Allan variance grows as tau^2 up to a quarter period; it lifts the band's mean
    # as flicker does, but its excess is read as rising
    t = np.arange(N) / FS
    taus, meas, nulls = _curves(lambda rng: 0.01 * np.sin(2 * np.pi * t / 3000.0))
    assert band_excess(taus, meas, nulls, span_s=N)[1] > 3
    z_flat, z_rise = band_shape(taus, meas, nulls, span_s=N)
    assert z_rise > WANDER_Z_RISE and z_rise > WANDER_RISE_OVER_FLAT * z_flat
    # white noise alone: nothing in either part
    taus, meas, nulls = _curves(lambda rng: 0.0)
    z_flat, z_rise = band_shape(taus, meas, nulls, span_s=N)
    assert abs(z_flat) < 3 and abs(z_rise) < 3


def test_band_shape_needs_three_taus_and_two_nulls():
    taus = np.array([16.0, 32.0, 64.0, 128.0])
    assert band_shape(taus, np.ones(4), [np.ones(4)]) == (0.0, 0.0)
    assert band_shape(taus[:2], np.ones(2), [np.ones(2), np.ones(2)]) == (0.0, 0.0)


def test_a_null_frozen_on_one_converter_level_is_not_judged():
    # every null replicate's output on one converter level: Allan deviation 0 at every tau, no spread to
    # judge the record's against, and no error either
    rng = np.random.default_rng(5)
    taus, meas = _adev(WHITE_DPS * rng.standard_normal(N))
    frozen = [np.zeros_like(meas) for _ in range(4)]
    assert band_excess(taus, meas, frozen, span_s=N)[1] == 0.0
    assert band_shape(taus, meas, frozen, span_s=N) == (0.0, 0.0)
