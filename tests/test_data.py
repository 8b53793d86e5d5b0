"""Datasets: shapes, the split, seeding, and the physics inside them."""
import numpy as np
import pytest
import torch

import hnn

CASES = [("spring", 30, 750), ("pend", 45, 1125)]


@pytest.mark.parametrize("task, points, rows", CASES)
def test_shapes_split_and_seed(task, points, rows):
    data = hnn.load_task(task)
    a, b, c = data.get_dataset(seed=0), data.get_dataset(seed=0), data.get_dataset(seed=1)
    for key in ("x", "dxdt", "test_x", "test_dxdt"):
        assert a[key].shape == (rows, 2) and a[key].dtype == np.float32
        np.testing.assert_array_equal(a[key], b[key])
        assert not np.allclose(a[key], c[key])
    assert len(a["t_eval"]) == points and a["dt"] == pytest.approx(3 / (points - 1))


@pytest.mark.parametrize("task, points, rows", CASES)
def test_targets_are_clean_trajectories_inputs_carry_the_noise(task, points, rows):
    data = hnn.load_task(task)
    noisy, clean = data.get_dataset(seed=0), data.get_dataset(seed=0, noise_std=0.0)
    x = torch.as_tensor(np.concatenate([clean["x"], clean["test_x"]]), dtype=torch.float64)
    dxdt = np.concatenate([clean["dxdt"], clean["test_dxdt"]])
    np.testing.assert_array_equal(dxdt, np.concatenate([noisy["dxdt"], noisy["test_dxdt"]]))
    np.testing.assert_allclose(data.dynamics(x).numpy(), dxdt, atol=1e-6)
    H = data.hamiltonian(x).reshape(50, points)
    # each trajectory keeps its energy, to the generator's tolerance (solve_ivp's default atol 1e-6,
    # as the original) and float32 storage
    assert (H - H[:, :1]).abs().max() < 1e-5 * H.abs().max()
    radius = x.reshape(50, points, 2)[:, 0].norm(dim=1)
    low, high = data.RADIUS_RANGE
    assert radius.min() >= low - 1e-6 and radius.max() <= high + 1e-6
    noise = np.concatenate([noisy["x"], noisy["test_x"]]) - x.numpy()
    assert noise.std() == pytest.approx(0.1, rel=0.05) and abs(noise.mean()) < 0.01
