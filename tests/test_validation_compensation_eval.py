"""The honest compensation evaluation: Allan readings, truth figures, bandwidth, CLI."""

import json

import numpy as np
import pytest
from scipy.signal import butter, sosfilt

from fmvmg_sim.cli.main import main
from fmvmg_sim.compensation import get_method
from fmvmg_sim.validation.compensation_eval import (allan_figures, evaluate, filter_time_constant, gain_phase,
                                             markdown_table, sine_windows, truth_figures)
from fmvmg_sim.record import Record

FS = 100.0
N_DPH = 100.0  # white rate noise, deg/h/sqrt(Hz)


def white(n, seed=0):
    return np.random.default_rng(seed).standard_normal(n) * (N_DPH / 3600.0) * np.sqrt(FS)


def test_paper_way_n_of_low_passed_noise_is_not_an_arw():
    """A heavy low-pass 'improves' the paper-way N 100-fold; the honest reading refuses it."""
    y = white(400_000)
    raw = allan_figures(y, FS)
    assert raw["N_paper_dph_rtHz"] == pytest.approx(N_DPH, rel=0.1)
    assert raw["N_valid_deg_rt_h"] == pytest.approx(N_DPH / 60.0, rel=0.1)
    sos = butter(1, 0.016, fs=FS, output="sos")  # the Kalman-like 0.016 Hz corner of compensation.md
    lp = sosfilt(sos, y)
    tau_f = 1.0 / (2 * np.pi * 0.016)
    f = allan_figures(lp, FS, tau_f)
    assert f["N_paper_dph_rtHz"] < 0.1 * raw["N_paper_dph_rtHz"]
    assert f["slope_at_1s"] > 0.3  # read on a rising curve
    # the -1/2 region, if any, lies beyond the filter, so the honest N is either refused or near the raw one
    assert f["N_valid_deg_rt_h"] is None or f["N_valid_deg_rt_h"] > 0.5 * raw["N_valid_deg_rt_h"]
    assert f["B_paper_dph"] < 0.2 * raw["B_paper_dph"]
    assert f["B_valid_dph"] is None or f["B_valid_dph"] > 0.5 * f["B_paper_dph"] * 5
    assert f["B_valid_from_tau_s"] == pytest.approx(10 * tau_f)


def _sine_record(fs=200.0, freqs=(1.0, 10.0, 50.0), amp=10.0):
    t, w = [0.0], [0.0]
    parts_t, parts_w = [], []
    t0 = 0.0
    for f in freqs:
        tt = t0 + np.arange(int(2 * fs)) / fs  # 2 s at rest
        parts_t.append(tt)
        parts_w.append(np.zeros_like(tt))
        t0 = tt[-1] + 1 / fs
        tt = t0 + np.arange(int(10 * fs)) / fs
        parts_t.append(tt)
        parts_w.append(amp * np.sin(2 * np.pi * f * (tt - t0)))
        t0 = tt[-1] + 1 / fs
    t, w = np.concatenate(parts_t), np.concatenate(parts_w)
    return Record({"time_s": t, "temperature_C": np.full(len(t), 25.0), "rate_dps": w, "rate_true_dps": w})


def test_gain_phase_of_a_known_filter():
    rec = _sine_record()
    assert all(len(sine_windows(rec, f)) == 1 for f in (1.0, 10.0, 50.0))
    r = gain_phase(rec, rec["rate_dps"])
    for k in ("1", "10", "50"):
        assert r[k]["gain"] == pytest.approx(1.0, abs=1e-6) and r[k]["phase_deg"] == pytest.approx(0.0, abs=1e-4)
    fc = 10.0
    sos = butter(1, fc, fs=200.0, output="sos")
    r = gain_phase(rec, sosfilt(sos, rec["rate_dps"]))
    # first-order response (bilinear transform: |H| = cos(pi f / fs) / cos-ish; check against the filter itself)
    from scipy.signal import sosfreqz
    for f in (1.0, 10.0, 50.0):
        _, h = sosfreqz(sos, worN=[f], fs=200.0)
        assert r[f"{f:g}"]["gain"] == pytest.approx(abs(h[0]), rel=0.02)
        assert r[f"{f:g}"]["phase_deg"] == pytest.approx(np.degrees(np.angle(h[0])), abs=2.0)


def test_truth_figures_bias_per_degree():
    n = 36_000
    t = np.arange(n) / 10.0
    T = 25 + 20 * t / t[-1]
    rec = Record({"time_s": t, "temperature_C": T, "rate_dps": np.zeros(n), "rate_true_dps": np.zeros(n)})
    out = (3.0 / 3600.0) * (T - 25)  # 3 deg/h per degC
    f = truth_figures(rec, out)
    assert f["bias_per_C_dph"] == pytest.approx(3.0, rel=1e-3)
    assert f["max_dph"] == pytest.approx(60.0, rel=1e-3)


def test_filter_time_constant_sources():
    assert filter_time_constant("raw", None)[0] == 0.0
    comp = get_method("emd-rbf-ga-kf")()
    comp.fit_diagnostics_ = {"fs_Hz": 100.0, "kf": {"cutoff_Hz": 0.016}}
    diag = {"classes": ["noise", "mixed", "drift"], "mean_period_s": [0.1, 5.0, 100.0], "rbf_applied": True}
    tc, src = comp._filter_time_constant(diag, 100.0)  # what the pipeline publishes after transform
    assert tc == pytest.approx(1 / (2 * np.pi * 0.016)) and "Kalman" in src
    comp.transform_diagnostics_ = {**diag, "filter_time_constant_s": tc}
    assert filter_time_constant("emd-rbf-ga-kf", comp)[0] == tc
    plain = get_method("emd-rbf")()
    tc2, src2 = plain._filter_time_constant(diag, 100.0)  # no KF: the RBF window (9 samples) or the noise IMF
    assert tc2 == pytest.approx(max(0.1, 9 / 100.0) / (2 * np.pi)) and "Kalman" not in src2


@pytest.fixture(scope="module")
def quick_eval():
    return evaluate(["raw", "line", "poly-baseline", "physics"], seeds=1, quick=True, progress=False)


def test_held_out_poly_beats_raw_and_physics_beats_poly(quick_eval):
    S = quick_eval.summary
    assert not any(S[m]["errors"] for m in S)
    assert S["poly-baseline"]["rms_dph"]["mean"] < S["raw"]["rms_dph"]["mean"]
    # the thermal lag needs dT/dt: the selected polynomial beats a line in T
    assert S["poly-baseline"]["drift_rms_dph"]["mean"] < 0.7 * S["line"]["drift_rms_dph"]["mean"]
    assert all(r["diagnostics"]["chosen"] for r in quick_eval.runs if r["method"] != "raw")
    assert S["physics"]["drift_rms_dph"]["mean"] < 0.5 * S["poly-baseline"]["drift_rms_dph"]["mean"]
    assert S["physics"]["drift_max_dph"]["mean"] < S["poly-baseline"]["drift_max_dph"]["mean"]
    # subtraction keeps the bandwidth: gain at 1 and 10 Hz equals the raw output's
    for f in ("1", "10"):
        assert S["physics"][f"gain_{f}Hz"]["mean"] == pytest.approx(S["raw"][f"gain_{f}Hz"]["mean"], abs=0.01)
    runs = [r for r in quick_eval.runs if r["method"] == "physics"]
    assert {r["direction"] for r in runs} == {"oven_000->oven_004", "oven_004->oven_000"}
    md = markdown_table(quick_eval)
    assert "| physics |" in md and "Paper's way" in md and "Honest" in md


def test_cli(tmp_path, capsys):
    rc = main(["compensate-eval", "--quick", "--seeds", "1", "--methods", "raw,poly-baseline", "--no-bandwidth",
               "--no-progress", "-o", str(tmp_path), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["summary"]) == {"raw", "poly-baseline"}
    for name in ("compensation_eval.md", "compensation_eval.json", "compensation_eval_allan.png",
                 "compensation_eval_traces.png", "compensation_eval_summary.png"):
        assert (tmp_path / name).stat().st_size > 0
    data = json.loads((tmp_path / "compensation_eval.json").read_text())
    assert len(data["runs"]) == 4


@pytest.mark.parametrize("argv", [["--seeds", "0"], ["--methods", "no-such-method"], ["--param", "nonsense"]])
def test_cli_bad_input(tmp_path, argv):
    assert main(["compensate-eval", "--quick", "--no-progress", "-o", str(tmp_path)] + argv) == 2
