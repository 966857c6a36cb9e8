"""The null replicates: what they carry beside the simulated unit's noise."""

import numpy as np

from fmvmg_sim.diagnosis.null import accuracy_floored, law_errors


class _Fitter:
    """A fitter whose laws are off by 1e-3 of a channel's level per K^2 beyond 10 blocks of training."""

    def __init__(self):
        d = np.maximum(np.arange(40.0) - 9.0, 0.0)  # K beyond the training temperatures
        self.sd = 1e-3 * np.outer(d ** 2, [1.0, 0.0, 5.0])

    def law_sd(self, train):
        assert train.sum() == 10
        return self.sd


def test_replicates_carry_the_law_error_at_its_stated_accuracy():
    f, train = _Fitter(), np.arange(40) < 10
    laws = law_errors(f, train, 4000, seed=3)
    assert all(np.all(e[:10] == 0.0) for e in laws)  # none inside the training temperatures
    assert all(np.all(e[:, 1] == 0.0) for e in laws)  # nor on a channel that states none
    # each replicate's error is the accuracy curve scaled by one amplitude per channel, normal with unit spread
    amp = np.array([e[-1, [0, 2]] / f.sd[-1, [0, 2]] for e in laws])
    assert np.allclose(laws[0][20:, 2] / f.sd[20:, 2], amp[0, 1])
    assert abs(np.std(amp[:, 0]) - 1.0) < 0.05 and abs(np.mean(amp[:, 0])) < 0.06
    assert abs(np.corrcoef(amp[:, 0], amp[:, 1])[0, 1]) < 0.06  # channels drawn independently
    # deterministic for a seed
    assert np.array_equal(law_errors(f, train, 3, seed=3)[2], laws[2])


def test_auxiliary_noise_is_floored_at_what_the_calibration_leaves_on_the_record():
    """A channel whose calibrated residual carries more one-step innovation than the null's is scored at the record's
    level (white residual: its sd; AR(1)-filtered: the filtered sd); one the null already holds noisier, the rate
    output (judged by the flicker band) and a channel with too few blocks keep the null's."""
    rng = np.random.default_rng(3)
    n = 4000
    Z = np.column_stack([0.8 * rng.standard_normal(n),          # rate: not floored here
                         0.3 * rng.standard_normal(n),          # white, sd 0.3 over a null of 0.05
                         0.3 * rng.standard_normal(n),          # the same through an AR(1) filter (rho 0.9, K 1)
                         0.02 * rng.standard_normal(n),         # quieter than the null's 0.05
                         np.full(n, np.nan)])
    Z[:5, 4] = 1.0
    null = [(0.0, 1.0, 0.05), (0.0, 1.0, 0.05), (0.9, 1.0, 0.05), (0.0, 1.0, 0.05), (0.0, 1.0, 0.05)]
    out = accuracy_floored(null, Z)
    assert out[0] == null[0] and out[3] == null[3] and out[4] == null[4]
    assert abs(out[1][2] / 0.3 - 1) < 0.05 and out[1][:2] == (0.0, 1.0)
    assert abs(out[2][2] / (0.3 * np.sqrt(1 + 0.9 ** 2)) - 1) < 0.05
