"""The null replicates: what they carry beside the simulated unit's noise."""

import numpy as np

from fmvmg_sim.diagnosis.null import law_errors


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
