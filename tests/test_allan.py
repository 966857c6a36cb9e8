"""Allan deviation: reference values (NIST / Stable32), closed forms, IEEE 952 term reading, series rules."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from fmvmg_sim.analysis.allan import (BI_IEEE952_FACTOR, allan_deviation, averaging_factors, noise_alpha,
                                      oadev_numpy)
from fmvmg_sim.analysis.series import series_from_record
from fmvmg_sim.errors import InputError
from fmvmg_sim.record import Record

DATA = Path(__file__).resolve().parent / "data"  # copies of outside reference data, with provenance and licence
REF = DATA / "allan-reference"

N_TRUE_DEG_SQRT_H = 1.66  # paper 000's raw ARW


def _nbs14_1000() -> np.ndarray:
    n = [1234567890]
    for _ in range(999):
        n.append(16807 * n[-1] % 2147483647)
    assert n[1:4] == [395529916, 1209410747, 633705974]  # published first values
    return np.array(n, dtype=float) / 2147483647.0


def _stable32(path: Path) -> np.ndarray:
    """Rows of a Stable32 output: AF, Tau, #, Alpha, MinSigma, Sigma, MaxSigma."""
    return np.loadtxt(path, comments="#")


# --- reference values -------------------------------------------------------------------

def test_nbs14_1000_point_oadev():
    y = _nbs14_1000()
    ref = np.array([2.922319e-1, 9.159953e-2, 3.241343e-2])
    res = allan_deviation(y, 1.0, taus=[1, 10, 100], unit="")
    np.testing.assert_array_equal(res.taus_s, [1.0, 10.0, 100.0])
    np.testing.assert_allclose(res.adev, ref, rtol=1e-4)
    np.testing.assert_allclose(oadev_numpy(y, 1.0, [1, 10, 100]), ref, rtol=1e-4)


def test_nbs14_10_point_oadev():
    lines = [s for s in (REF / "nbs14_10point.txt").read_text().splitlines() if s and not s.startswith("#")]
    freq = np.array(lines[1].split(), dtype=float)
    oadev_ref = next(np.array(s.split()[1:], dtype=float) for s in lines if s.startswith("OADEV"))
    assert len(freq) == 9 and oadev_ref.tolist() == [91.22945, 85.95287]
    res = allan_deviation(freq, 1.0, taus=[1, 2], unit="")
    np.testing.assert_allclose(res.adev, oadev_ref, rtol=1e-4)


def test_phasedat_matches_stable32_octave_with_confidence_interval():
    phase = np.loadtxt(REF / "phasedat" / "PHASE.DAT", comments="#")
    s32 = _stable32(REF / "phasedat" / "phase_dat_oadev_octave.txt")
    res = allan_deviation(np.diff(phase), 1.0, unit="s/s")  # phase -> frequency, tau0 = 1 s
    np.testing.assert_array_equal(res.taus_s, s32[:, 1])
    np.testing.assert_array_equal(res.n_pairs, s32[:, 2])
    np.testing.assert_allclose(res.adev, s32[:, 5], rtol=1e-4)
    np.testing.assert_array_equal(res.alpha, s32[:, 3])  # noise ID agrees with Stable32
    # Stable32 prints the interval to 5 digits; Greenhall EDF + chi-square reproduces it.
    np.testing.assert_allclose(res.adev_lo, s32[:, 4], rtol=1e-3)
    np.testing.assert_allclose(res.adev_hi, s32[:, 6], rtol=1e-3)


def test_ocxo_matches_stable32_all_tau():
    f = np.loadtxt(REF / "ocxo" / "ocxo_frequency.txt", comments="#")
    s32 = _stable32(REF / "ocxo" / "stable32_oadev_alltau.txt")
    res = allan_deviation(f / 1e7 - 1.0, 1.0, taus=s32[:, 1], unit="")
    assert len(res.taus_s) == len(s32) == 273
    np.testing.assert_array_equal(res.n_pairs, s32[:, 2])
    np.testing.assert_allclose(res.adev, s32[:, 5], rtol=1e-4)


def test_ocxo_noise_id_matches_stable32_where_averages_suffice():
    f = np.loadtxt(REF / "ocxo" / "ocxo_frequency.txt", comments="#")
    s32 = _stable32(REF / "ocxo" / "oadev_octave.txt")
    y = f / 1e7 - 1.0
    for af, alpha in zip(s32[:, 0].astype(int), s32[:, 3].astype(int)):
        if len(y) // af >= 100:
            assert noise_alpha(y, af) == alpha, af


def test_numpy_oadev_agrees_with_allantools():
    rng = np.random.default_rng(7)
    y = np.cumsum(rng.standard_normal(5000)) * 0.01 + rng.standard_normal(5000)
    res = allan_deviation(y, 20.0, taus="dense")
    m = np.round(res.taus_s * 20.0).astype(int)
    assert len(m) > 25
    np.testing.assert_allclose(oadev_numpy(y, 20.0, m), res.adev, rtol=1e-10)


def test_averaging_factors_octave_stop_ratio_and_dense():
    np.testing.assert_array_equal(averaging_factors(1000, "octave"), [1, 2, 4, 8, 16, 32, 64, 128])
    dense = averaging_factors(1000, "dense")
    assert dense[0] == 1 and dense[-1] == 250 and len(dense) > 15
    with pytest.raises(InputError):
        averaging_factors(2, "octave")
    with pytest.raises(InputError):
        averaging_factors(100, "weekly")


def test_noise_alpha_identifies_power_laws():
    rng = np.random.default_rng(5)
    w = rng.standard_normal(20000)
    assert noise_alpha(w, 1) == 0             # white FM
    assert noise_alpha(np.cumsum(w), 1) == -2  # random-walk FM
    assert noise_alpha(np.diff(w), 1) == 2     # white PM
    assert noise_alpha(w, 1000) is None        # 20 averages: too few to identify


# --- closed forms -----------------------------------------------------------------------

def _white(n, fs, n_deg_sqrt_h, seed):
    """White rate noise with ARW N: per-sample sigma = N * sqrt(fs) (N in deg/sqrt(s))."""
    return np.random.default_rng(seed).standard_normal(n) * (n_deg_sqrt_h / 60.0) * math.sqrt(fs)


def _ci_tolerance(res, i, k=3.0):
    """k one-sigma interval half-widths in ln(sigma): grows with tau as the EDF falls."""
    return k * 0.5 * math.log(res.adev_hi[i] / res.adev_lo[i])


def test_white_rate_noise_gives_arw():
    fs = 100.0
    res = allan_deviation(_white(100_000, fs, N_TRUE_DEG_SQRT_H, 11), fs)
    assert res.arw_deg_per_sqrt_h == pytest.approx(N_TRUE_DEG_SQRT_H, rel=0.03)
    assert res.white.region_s[0] == pytest.approx(0.01)  # the -1/2 region starts at the first tau
    assert res.N * 60 == pytest.approx(res.arw_deg_per_sqrt_h)
    theory = (N_TRUE_DEG_SQRT_H / 60.0) / np.sqrt(res.taus_s)
    for i in np.flatnonzero(res.n_clusters >= 8):
        assert abs(math.log(res.adev[i] / theory[i])) <= max(0.02, _ci_tolerance(res, i)), res.taus_s[i]
    assert np.all(np.abs(res.slopes[res.n_clusters >= 1000] + 0.5) < 0.03)
    assert res.rrw is None and res.random_walk.reason
    assert res.quantization_deg is None


def test_random_walk_closed_form_and_rrw():
    fs, k_deg_h_sqrt_s = 10.0, 0.5
    k = k_deg_h_sqrt_s / 3600.0  # deg/s/sqrt(s)
    y = np.cumsum(np.random.default_rng(3).standard_normal(100_000)) * k / math.sqrt(fs)
    res = allan_deviation(y, fs)
    theory = k * np.sqrt(res.taus_s / 3.0)
    checked = 0
    for i, m in enumerate(np.round(res.taus_s * fs)):
        if m >= 8 and res.n_clusters[i] >= 8:  # the continuous-time form needs m >> 1
            assert abs(math.log(res.adev[i] / theory[i])) <= max(0.03, _ci_tolerance(res, i)), res.taus_s[i]
            checked += 1
    assert checked >= 8
    for tau, tol in ((12.8, 0.05), (102.4, 0.15)):  # tolerance grows with tau
        i = int(np.argmin(np.abs(res.taus_s - tau)))
        assert res.adev[i] == pytest.approx(theory[i], rel=tol)
    assert res.rrw_deg_per_h_sqrt_s == pytest.approx(k_deg_h_sqrt_s, rel=0.1)
    assert res.rrw == res.rrw_deg_per_h_sqrt_h == pytest.approx(res.K * 216000.0)
    assert res.arw_deg_per_sqrt_h is None and "-0.5" in res.white.reason


def test_flicker_plateau_and_bias_instability_definitions():
    fs, plateau_deg_h = 10.0, 30.0
    h = (plateau_deg_h / 3600.0) ** 2 / (2.0 * math.log(2.0))  # plateau = sqrt(2 ln2 h_-1)
    n = 2 ** 17
    rng = np.random.default_rng(0)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    shape = np.zeros_like(f)
    shape[1:] = np.sqrt(h / f[1:] * fs / 2.0)  # one-sided S_y = h_-1 / f
    y = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * shape, n)
    res = allan_deviation(y, fs)
    mid = (res.taus_s >= 0.4) & (res.taus_s <= 50.0)
    assert mid.sum() >= 7
    assert np.median(res.adev[mid]) * 3600.0 == pytest.approx(plateau_deg_h, rel=0.05)
    assert np.all(np.abs(res.slopes[mid]) < 0.1)
    bi = res.bias_instability_deg_per_h
    assert bi == pytest.approx(res.adev[res.taus_s == res.tau_min_s][0] * 3600.0)
    assert res.bias_instability_ieee952_deg_per_h == pytest.approx(bi / BI_IEEE952_FACTOR)
    assert 0.6 * plateau_deg_h < bi <= plateau_deg_h * 1.05
    assert res.arw_deg_per_sqrt_h is None  # no -1/2 region in pure flicker noise


def test_heavily_low_pass_filtered_noise_reports_no_arw():
    fs, tc = 10.0, 50.0
    a = math.exp(-1.0 / (fs * tc))
    y = lfilter([1 - a], [1, -a], _white(20_000, fs, N_TRUE_DEG_SQRT_H, 2))
    res = allan_deviation(y, fs)
    assert 0.3 < res.slopes[2] < 0.6 and 0.3 < res.slopes[4] < 0.6  # +1/2 at short tau
    assert res.arw_deg_per_sqrt_h is None
    d = res.to_dict()
    assert d["arw_deg_per_sqrt_h"] is None and "not read outside a valid region" in d["arw_reason"]


def test_arw_is_read_only_on_the_valid_region_after_filtering():
    """Paper A's artefact: sigma(1 s) of a low-passed signal is far below N; the fit is not fooled."""
    fs, tc = 100.0, 0.5
    a = math.exp(-1.0 / (fs * tc))
    y = lfilter([1 - a], [1, -a], _white(200_000, fs, N_TRUE_DEG_SQRT_H, 4))
    res = allan_deviation(y, fs)
    sigma_1s_as_arw = 60.0 * float(np.exp(np.interp(0.0, np.log(res.taus_s), np.log(res.adev))))
    assert sigma_1s_as_arw < 0.75 * N_TRUE_DEG_SQRT_H
    assert res.white.region_s[0] >= 4 * tc
    assert res.arw_deg_per_sqrt_h == pytest.approx(N_TRUE_DEG_SQRT_H, rel=0.1)


def test_arw_is_the_white_level_whatever_the_output_rate():
    """One physical noise (white behind a two-pole 100 Hz low-pass, plus a flicker floor) recorded at 1 kHz and
    averaged to 100, 50 and 10 Hz: the ARW reading is the white level at every rate (measured within 0.4 %),
    though the filter lowers sigma by 9 % at 10 ms and the flicker floor lifts it by 6 % at 1 s."""
    from scipy.signal import butter

    from fmvmg_sim.noise import flicker
    rng = np.random.default_rng(7)
    fs_hi, T = 8000.0, 1200.0
    n_dps = N_TRUE_DEG_SQRT_H / 60.0
    b, a = butter(2, 100.0, fs=fs_hi)
    y = lfilter(b, a, rng.standard_normal(int(T * fs_hi)) * n_dps * math.sqrt(fs_hi)).reshape(-1, 8).mean(axis=1)
    y += flicker(len(y), 1000.0, (30.0 / 3600.0) ** 2 / (2 * math.log(2)), rng)  # a 30 deg/h plateau
    readings = {}
    for fs in (1000, 100, 50, 10):
        res = allan_deviation(y.reshape(-1, 1000 // fs).mean(axis=1), float(fs))
        readings[fs] = res.arw_deg_per_sqrt_h
        assert res.arw_deg_per_sqrt_h == pytest.approx(N_TRUE_DEG_SQRT_H, rel=0.015), fs
        assert res.power_law["tau_first_s"] >= 1.0 / fs
        if fs == 1000:  # the filter-shaped taus are left out
            assert res.power_law["tau_first_s"] >= 0.008
            i = int(np.argmin(np.abs(res.taus_s - 0.008)))
            assert res.adev[i] * math.sqrt(res.taus_s[i]) * 60 < 0.95 * N_TRUE_DEG_SQRT_H
    assert max(readings.values()) / min(readings.values()) < 1.03


def test_other_units_keep_generic_terms_only():
    fs = 50.0
    res = allan_deviation(_white(20_000, fs, 60.0, 8), fs, unit="V")  # N = 1 V*sqrt(s)
    assert res.N == pytest.approx(1.0, rel=0.05)
    d = res.to_dict()
    assert d["unit"] == "V" and d["N_unit_sqrt_s"] == pytest.approx(res.N)
    assert d["arw_deg_per_sqrt_h"] is None and "not deg/s" in d["arw_reason"]
    assert d["bias_instability_deg_per_h"] is None and d["allan_minimum_unit"] > 0


def test_to_dict_is_strict_json_and_plot_writes_png(tmp_path):
    res = allan_deviation(_white(4000, 10.0, 1.0, 1), 10.0, column="rate_dps")
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    for key in ("taus_s", "adev", "adev_lo", "adev_hi", "n_clusters", "slopes", "arw_deg_per_sqrt_h",
                "bias_instability_deg_per_h", "bias_instability_ieee952_deg_per_h", "tau_min_s",
                "rrw_deg_per_h_sqrt_h", "rrw", "bias_instability_definition", "fs_Hz", "column"):
        assert key in d, key
    assert len(d["taus_s"]) == len(d["adev"]) == len(d["adev_lo"]) == len(d["n_clusters"])
    assert all(lo <= s <= hi for lo, s, hi in zip(d["adev_lo"], d["adev"], d["adev_hi"]))
    png = tmp_path / "sub" / "allan.png"
    res.plot(png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert [p.name for p in png.parent.iterdir()] == ["allan.png"]  # no temporary file left


def test_constant_and_bad_input():
    res = allan_deviation(np.ones(100), 1.0)
    assert res.allan_minimum is None and res.arw_deg_per_sqrt_h is None
    json.dumps(res.to_dict(), allow_nan=False)
    with pytest.raises(InputError, match="not finite"):
        allan_deviation(np.array([1.0, np.nan, 2.0, 3.0, 4.0]), 1.0)
    with pytest.raises(InputError, match="sample rate"):
        allan_deviation(np.ones(100), 0.0)


# --- series preparation -----------------------------------------------------------------

def _rec(t, y, path=None):
    return Record({"time_s": np.asarray(t, float), "rate_dps": np.asarray(y, float)}, path=path)


def test_series_accepts_jitter_within_one_percent_and_uses_mean_step():
    t = np.arange(1001) * 0.01 + np.append(np.tile([0.0, 0.00009], 500), 0.0)  # steps 0.01009 / 0.00991 s
    s = series_from_record(_rec(t, np.arange(1001.0)))
    assert s.fs_Hz == 100.0 and not s.resampled and len(s.values) == 1001
    t[500] += 0.0002  # one step 2 % long
    with pytest.raises(InputError, match="by more than 1 %"):
        series_from_record(_rec(t, np.arange(1001.0)))


def test_series_gap_refused_names_line_and_resample_bridges_it(tmp_path):
    t = np.arange(100) * 0.1
    t[50:] += 0.3  # 3 missing samples
    y = 2.0 * t
    p = tmp_path / "r.csv"
    p.write_text("# source: test\ntime_s,rate_dps\n" + "".join(f"{a:.12g},{b:.12g}\n" for a, b in zip(t, y)))
    rec = _rec(t, y, str(p))
    with pytest.raises(InputError) as e:
        series_from_record(rec)
    assert e.value.where == f"{p} line 53"  # data row 50 is file line 53
    s = series_from_record(rec, resample=True)
    assert s.resampled and len(s.values) == 103 and s.n_filled == 3
    np.testing.assert_allclose(s.values, 2.0 * np.arange(103) * 0.1, atol=1e-9)  # linear data survives
    t2 = t.copy()
    t2[50:] += 1.0  # gap of 14 steps > 10
    with pytest.raises(InputError, match="exceeds the --resample limit of 10 steps"):
        series_from_record(_rec(t2, y), resample=True)


def test_series_nan_rules():
    t = np.arange(50) * 0.5
    y = np.arange(50.0)
    y[[0, 1, 49]] = np.nan         # trimmed
    y[10:13] = np.nan              # 3 in a row: filled
    s = series_from_record(_rec(t, y))
    assert len(s.values) == 47 and s.n_filled == 3
    np.testing.assert_allclose(s.values, np.arange(2.0, 49.0))
    y[20:24] = np.nan              # 4 in a row: refused, names the first missing row
    with pytest.raises(InputError, match="4 missing rate_dps samples") as e:
        series_from_record(_rec(t, y))
    assert e.value.where.endswith("row 20")
    s = series_from_record(_rec(t, y), resample=True)
    assert len(s.values) == 47 and s.resampled
