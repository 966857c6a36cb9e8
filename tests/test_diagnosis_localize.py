"""Localisation statistics against a few null replicates: Holm correction and the Allan sampling floor."""

import numpy as np

from fmvmg_sim.diagnosis import localize as loc


def _stats(band_value, floor=None):
    st = {"channels": {}, "allan_bands": {"random_walk": band_value}, "regimes": {}}
    if floor is not None:
        st["_sd_floor"] = {"random_walk": floor}
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

