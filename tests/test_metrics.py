"""The paper's error bars, computed by hand; the rollout error against a closed-form phase error."""
import numpy as np
import pytest
import torch

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
    class Exact(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.w = torch.nn.Parameter(torch.zeros((), dtype=torch.float64))

        def time_derivative(self, x):
            return spring.dynamics(x)
    x = torch.randn(20, 2, dtype=torch.float64)
    assert hnn.derivative_mse(Exact(), x, spring.dynamics(x)) == (0.0, 0.0)


def test_the_rollout_error_of_a_known_phase_error_on_a_harmonic_oscillator():
    # the oscillator x = r (cos w t, -sin w t) predicted at w (1 + d): |pred - true| / (|pred| + |true|)
    # = |sin(w d t / 2)| exactly, whatever the radius; its geometric mean over t > 0 and the time it
    # first exceeds 0.1, 2 asin(0.1) / (w d), are known in closed form
    w, t = 1.5, np.linspace(0.0, 40.0, 4001)
    radii, detune = np.array([1.0, 0.3]), np.array([0.01, 0.04])
    true = radii[:, None, None] * np.stack([np.cos(w * t), -np.sin(w * t)], -1)[None]
    phase = w * (1 + detune[:, None]) * t[None]
    pred = radii[:, None, None] * np.stack([np.cos(phase), -np.sin(phase)], -1)
    out = hnn.metrics.path_errors(torch.as_tensor(pred), torch.as_tensor(true), t)
    e = np.abs(np.sin(w * detune[:, None] * t[None, 1:] / 2))
    exact = np.exp(np.log(e).mean(axis=1))
    np.testing.assert_allclose(out["error_per_trajectory"], exact, rtol=1e-10)
    assert out["error"] == pytest.approx(exact.mean(), rel=1e-10)
    first = 2 * np.arcsin(hnn.metrics.VALID_ERROR) / (w * detune)         # in (grid step) of the first sample over 0.1
    assert all(f < v <= f + (t[1] - t[0]) for f, v in zip(first, out["valid_times"]))
    assert out["valid_time"] == pytest.approx(np.median(out["valid_times"]))
    assert hnn.metrics.ROLLOUT_METRICS["error"] is hnn.metrics.rollout_error     # the cards' two numbers
    # a phase error that stays under 0.1 over the horizon: valid for all of it
    assert hnn.metrics.path_errors(torch.as_tensor(pred[:1, :100]), torch.as_tensor(true[:1, :100]),
                                   t[:100])["valid_time"] == t[99]
