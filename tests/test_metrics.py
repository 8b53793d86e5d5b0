"""The paper's error bars, computed by hand."""
import numpy as np
import pytest

import hnn


def test_mean_and_se_uses_elements_for_std_and_rows_for_sqrt():
    v = np.array([[1.0, 2.0], [3.0, 5.0], [8.0, 13.0]])
    mean, se = hnn.metrics.mean_and_se(v)
    assert mean == pytest.approx(32 / 6)
    elems = v.flatten()
    std = np.sqrt(((elems - elems.mean()) ** 2).sum() / 5)     # unbiased, over the 6 elements
    assert se == pytest.approx(std / np.sqrt(3))                # / sqrt(rows), not sqrt(elements)


def test_batch_means_se_is_std_of_contiguous_group_means():
    v = np.arange(15, dtype=float) ** 2
    groups = v.reshape(5, 3).mean(1)
    assert hnn.metrics.batch_means_se(v) == pytest.approx(groups.std() / np.sqrt(5))
    with pytest.raises(ValueError, match="divisible"):
        hnn.metrics.batch_means_se(np.ones(14))


def test_energy_mse_trials_and_single_trajectory():
    rng = np.random.RandomState(0)
    e_true, e_pred = rng.rand(15, 100), rng.rand(15, 100)
    mean, se = hnn.energy_mse(e_true, e_pred)
    per_trial = ((e_true - e_pred) ** 2).mean(1)
    assert mean == pytest.approx(per_trial.mean())
    assert se == pytest.approx(per_trial.reshape(5, 3).mean(1).std() / np.sqrt(5))
    mean1, se1 = hnn.energy_mse(e_true[0, :100], e_pred[0, :100])      # 5 chunks of 20 steps
    d = (e_true[0] - e_pred[0]) ** 2
    assert (mean1, se1) == pytest.approx((d.mean(), d.reshape(5, 20).mean(1).std() / np.sqrt(5)))
    with pytest.raises(ValueError, match="differ in shape"):
        hnn.energy_mse(e_true, e_pred[:, :50])


def test_derivative_mse_of_a_perfect_model_is_zero(spring):
    import torch

    class Exact(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.w = torch.nn.Parameter(torch.zeros((), dtype=torch.float64))

        def time_derivative(self, x):
            return spring.dynamics(x)
    x = torch.randn(20, 2, dtype=torch.float64)
    assert hnn.derivative_mse(Exact(), x, spring.dynamics(x)) == (0.0, 0.0)
