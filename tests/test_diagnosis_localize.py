"""Localisation statistics against a few null replicates: Holm correction and the sampling-spread floors."""

import numpy as np

from fmvmg_sim.diagnosis import localize as loc
from tests.test_diagnosis_helpers import NOMINAL


def _stats(band_value, floor=None):
    st = {"channels": {}, "allan_bands": {"random_walk": band_value}, "regimes": {}}
    if floor is not None:
        st["_sd_floor"] = {"random_walk": (floor, 0.0)}
    return st


def test_allan_band_floor_stops_overconfident_nulls():
    # four null replicates that happen to agree to 0.02 in log ADEV: without a floor a 0.3 excess
    # (well inside the sampling spread of an Allan deviation read from ~10 averages) is "significant"
    nulls = [_stats(v) for v in (-3.00, -3.02, -2.99, -3.01)]
    loose = loc.compare(_stats(-2.70), nulls)["allan_bands"]["random_walk"]
    # 1/sqrt(2 EDF) with EDF ~ 10 averages
    floored = loc.compare(_stats(-2.70, floor=1 / np.sqrt(20)), nulls)["allan_bands"]["random_walk"]
    assert loose["significant"] and loose["z"] > 4
    assert not floored["significant"]
    assert abs(floored["z"] - 0.3 / (np.sqrt(1 / 20) * np.sqrt(1.25))) < 0.05


def test_holm_correction_scales_p_values():
    nulls = [{"channels": {"a": 1.0 + 0.1 * k, "b": 1.0 - 0.05 * k}, "allan_bands": {}, "regimes": {}}
             for k in range(5)]
    meas = {"channels": {"a": 3.0, "b": 1.0}, "allan_bands": {}, "regimes": {}}
    out = loc.compare(meas, nulls)["channels"]
    assert out["a"]["p_holm"] == min(1.0, 2 * out["a"]["p"])  # smallest p times the number of tests
    assert out["b"]["p_holm"] >= out["a"]["p_holm"]



def _located(regime_ms, band_log_adev):
    return {"channels": {}, "allan_bands": {"drift": band_log_adev}, "regimes": {"hold": regime_ms}}


def test_closure_shrink_in_mean_square_units_and_open_remainders():
    # nulls: a regime mean square of 1 (log spread 0.1) and an Allan drift band at log ADEV -3 (spread 0.05)
    nulls = [_located(np.exp(0.1 * e), -3.0 + 0.05 * e) for e in (-1.5, -0.5, 0.5, 1.5)]
    before = loc.compare(_located(10.0, -2.0), nulls)
    assert before["regimes"]["hold"]["significant"] and before["allan_bands"]["drift"]["significant"]
    mu_r = np.log(before["regimes"]["hold"]["null_mean"])
    mu_a = np.log(before["allan_bands"]["drift"]["null_mean"])
    # a model that leaves the regime's excess where it was and removes 90 % of the band's squared deviation
    band_after = 0.5 * np.log(np.exp(2 * mu_a) + 0.1 * (np.exp(-4.0) - np.exp(2 * mu_a)))
    out = loc.closure(before, _located(10.0, band_after), nulls)
    rows = {r["name"]: r for r in out["checked"]}
    assert abs(rows["hold"]["shrink"]) < 1e-12 and rows["hold"]["open"]
    assert abs(rows["drift"]["shrink"] - 0.9) < 1e-9 and not rows["drift"]["open"]
    assert [r["name"] for r in out["open"]] == ["hold"]
    # a regime's excess cut by 60 %: closed (the share of the excess, not the z-score, decides)
    ms_after = np.exp(mu_r) + 0.4 * (10.0 - np.exp(mu_r))
    out = loc.closure(before, _located(ms_after, band_after), nulls)
    hold = next(r for r in out["checked"] if r["name"] == "hold")
    assert abs(hold["shrink"] - 0.6) < 1e-9 and not hold["open"] and out["open"] == []
    # a regime back at the null is closed, the band left where it was is open; nothing located, nothing read
    out = loc.closure(before, _located(np.exp(mu_r) * 1.05, -2.0), nulls)
    assert [r["name"] for r in out["open"]] == ["drift"]
    quiet = loc.compare(_located(1.0, -3.0), nulls)
    assert loc.closure(quiet, _located(10.0, -2.0), nulls) == {"checked": [], "open": []}


def test_window_spread_matches_analytic_for_white_and_correlated_noise():
    # log of a mean square over n samples: spread sqrt(2 / EDF), EDF = n for white noise and
    # n (1 - rho^2) / (1 + rho^2) for an AR(1) series
    rng = np.random.default_rng(3)
    n = 100
    z = rng.standard_normal(200_000)
    sd, windows = loc.window_log_ms_sd(z, n)
    assert abs(sd / np.sqrt(2 / n) - 1) < 0.1 and windows == 2000
    rho = 0.8
    e = rng.standard_normal(400_000)
    x = np.empty_like(e)
    x[0] = e[0]
    for k in range(1, len(e)):
        x[k] = rho * x[k - 1] + np.sqrt(1 - rho ** 2) * e[k]
    sd, _ = loc.window_log_ms_sd(x, n)
    edf = n * (1 - rho ** 2) / (1 + rho ** 2)
    assert abs(sd / np.sqrt(2 / edf) - 1) < 0.15
    assert loc.window_log_ms_sd(z[:150], n) == (0.0, 0.0)  # fewer than two windows: no floor


def test_regime_floor_from_null_windows():
    # four nulls that agree by chance on a short regime: their windows say the spread is 0.35, so a
    # 1.7x excess is not located; a 5x excess still is, on the windows' degrees of freedom
    def st(v, floor=(0.35, 12.0)):
        return {"channels": {}, "allan_bands": {}, "regimes": {"heating": v}, "_sd_floor": {"heating": floor}}
    nulls = [st(v) for v in (3.7, 3.8, 3.9, 3.75)]
    weak = loc.compare(st(6.5), nulls)["regimes"]["heating"]
    strong = loc.compare(st(19.0), nulls)["regimes"]["heating"]
    assert not weak["significant"] and strong["significant"]
    bare = [{k: v for k, v in n.items() if k != "_sd_floor"} for n in nulls]
    assert loc.compare(st(6.5), bare)["regimes"]["heating"]["significant"]  # without the floor: a false alarm


def test_null_replicates_carry_the_calibration_error(tmp_path):
    """A null record whose last heating ramp runs 20 K past the training window's temperatures.

    The calibrated nominal model extrapolates there with its estimation error; the null replicates,
    simulated with knobs drawn from the calibration's posterior and each re-calibrated on the same
    training window, carry the same kind of error. Replicates of the calibrated model itself read against
    it (no estimation error) left the heating regime at z = 3.9 ("unexplained")."""
    from fmvmg_sim.validation.cases import make_case
    from fmvmg_sim.diagnosis.pipeline import diagnose
    label = make_case(28, 4242, tmp_path, str(NOMINAL))
    assert not label["effects"]
    rep = diagnose(label["record"], NOMINAL, n_null=4, progress=False, log=lambda m: None)
    assert rep["verdict"] == "none", rep["remainder"]
    z = rep["localization"]["regimes"]["heating"]["z"]
    assert z < 2.0, z
    # nor does the record-design note read the extrapolation after the training window as a gap there
    assert not rep["design"]["gap_after_training"]["fires"], rep["design"]["gap_after_training"]["tests"]


def _oven_prep():
    from fmvmg_sim.diagnosis.data import prepare
    from fmvmg_sim.record import Record

    t = np.arange(0.0, 10800.0, 1.0)
    # ramp up at 1 K/min, 1 h hold, ramp down at 0.5 K/min, hold
    T = np.interp(t, [0, 2400, 6000, 9600, 10800], [20.0, 60.0, 60.0, 30.0, 30.0])
    rec = Record({"time_s": t, "temperature_C": T, "rate_dps": np.zeros_like(t)})
    return prepare(rec, 0.01)


def test_flicker_band_ignores_a_leftover_gradient_term():
    # a temperature-rate leftover (an unmodelled gradient term, steps at every ramp end) raises the
    # 10-300 s Allan band of a white residual and reads as extra flicker; the slow templates remove it,
    # while slow noise in the band is still found
    from fmvmg_sim.diagnosis.noise_effects import band_excess

    prep = _oven_prep()
    n = len(prep.t_s)
    rng = np.random.default_rng(7)
    sigma = 0.01  # deg/s per sample

    templates = loc.slow_templates(prep)

    def allan(x, detrend):
        return loc.residual_allan(prep, x, templates=templates if detrend else None)[:2]
    nulls = {d: [allan(sigma * rng.standard_normal(n), d)[1] for _ in range(4)] for d in (False, True)}
    leftover = 0.02 * prep.dTdt_K_per_min  # 0.02 deg/s per K/min: 72 deg/h per K/min
    x = sigma * rng.standard_normal(n) + leftover
    z_raw = band_excess(*allan(x, False), nulls[False], span_s=n)[1]
    z_det = band_excess(*allan(x, True), nulls[True], span_s=n)[1]
    assert z_raw > 3.0 > z_det
    # slow noise (AR(1), 100 s correlation, 3x the white level over the band) is still seen
    a = np.exp(-1.0 / 100.0)
    e = rng.standard_normal(n) * 3 * sigma * np.sqrt(1 - a * a)
    slow = np.zeros(n)
    for k in range(1, n):
        slow[k] = a * slow[k - 1] + e[k]
    assert band_excess(*allan(sigma * rng.standard_normal(n) + slow, True), nulls[True], span_s=n)[1] > 3.0


def test_heating_minus_cooling_floor_is_the_chi_square_spread():
    # the mean of k squared heating-minus-cooling differences of white block residuals: its log spreads by
    # at least sqrt(2 / k) (chi-square with k dof; bins of unequal size spread it more), the floor it now gets
    prep = _oven_prep()
    rng = np.random.default_rng(11)
    rr = np.zeros(len(prep.t_s))
    logs, floors = [], set()
    for _ in range(300):
        Z = rng.standard_normal((prep.n_blocks, 5))
        st = loc.residual_stats(prep, Z, rr)
        logs.append(np.log(st["regimes"]["heating_minus_cooling_rate_V"]))
        floors.add(st["_sd_floor"]["heating_minus_cooling_rate_V"])
    (floor, k), = floors
    assert k >= 5 and abs(floor - np.sqrt(2.0 / k)) < 1e-12
    assert floor * 0.9 < np.std(logs) < floor * 2.0
    # four replicates that agree by chance (log spread 0.14) beside a null record: a 2.9x value is "located"
    # without the floor, and is not with it
    name = "heating_minus_cooling_rate_V"

    def st(v, fl=True):
        return {"channels": {}, "allan_bands": {}, "regimes": {name: v},
                "_sd_floor": {name: (floor, k)} if fl else {}}
    vals = np.exp(np.log(0.053) + 0.14 * np.array([-1.2, -0.4, 0.4, 1.2]) / 0.86)
    assert loc.compare(st(0.1535, False), [st(v, False) for v in vals])["regimes"][name]["z"] > 5
    assert not loc.compare(st(0.1535), [st(v) for v in vals])["regimes"][name]["significant"]
    # a gap twenty times the null's still is
    assert loc.compare(st(20 * 0.053), [st(v) for v in vals])["regimes"][name]["significant"]


def test_a_record_far_below_its_null_is_marked_not_comparable():
    # null replicates whose channel mean square is ~100 times the record's (log spread 0.1): z ~ -44, beyond any
    # sampling spread; the channel "b" sits inside its null and stays comparable
    nulls = [{"channels": {"a": 100.0 * np.exp(0.1 * e), "b": np.exp(0.1 * e)}, "allan_bands": {}, "regimes": {}}
             for e in (-1.5, -0.5, 0.5, 1.5)]
    out = loc.compare({"channels": {"a": 1.0, "b": np.exp(-0.2)}, "allan_bands": {}, "regimes": {}}, nulls)["channels"]
    assert out["a"]["z"] < loc.NOT_COMPARABLE_Z and not out["a"]["comparable"] and not out["a"]["significant"]
    assert out["b"]["comparable"] and -3.0 < out["b"]["z"] < 0.0
