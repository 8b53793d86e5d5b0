"""Gravity of N bodies (experiment-gravity, hnn.orbits.nbody's softening): the softened field is the symplectic
gradient of the softened H, softening converges to Newton's at second order, the pair kind with the exact softened
V gives the same field at any N, and without softening close encounters are redrawn."""
import numpy as np
import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.models.pair import PairHNN
from hnn.orbits import nbody
from hnn.orbits.encounters import MIN_SEPARATION
from hnn.tasks import load_task

EPS = torch.finfo(torch.float64).eps


def _states(count, rows, seed=0):
    data = load_task("gravity")
    rng = np.random.RandomState(seed)
    return torch.tensor(np.stack([data.random_config(rng, count) for _ in range(rows)]))


@pytest.mark.parametrize("softening", [0.0, 0.1])
def test_the_softened_field_is_the_symplectic_gradient_of_the_softened_h(softening):
    x = _states(8, 6)
    grad = hnn.interface.gradient_of(lambda z: nbody.hamiltonian(z, softening), x)
    n = x.shape[1] // 2
    # accelerations of size up to 7 / 0.2^2 (pairs no closer than the start law's 0.2), each to a few eps
    assert torch.allclose(nbody.dynamics(x, softening), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=0,
                          atol=64 * EPS * 7 / 0.2 ** 2)


def test_softening_converges_to_newton_at_second_order():
    x = _states(5, 4, seed=1)
    newton = nbody.potential_energy(x)
    gaps = [(nbody.potential_energy(x, e) - newton).abs() for e in (0.02, 0.01)]
    # V_e - V_0 = e^2 / (2 r^3) + O(e^4) per pair: halving e quarters the gap
    assert torch.allclose(gaps[0] / gaps[1], torch.full_like(gaps[0], 4.0), rtol=1e-2)
    assert torch.equal(nbody.dynamics(x, 0.0), nbody.dynamics(x))


class _Softened(torch.nn.Module):
    """V = -1 / sqrt(r^2 + e^2) on the pair model's inputs (r, 1/r)."""

    def __init__(self, softening):
        super().__init__()
        self.softening = softening

    def forward(self, features):
        return -(features[:, :1] ** 2 + self.softening ** 2).rsqrt()


@pytest.mark.parametrize("count", [3, 12])
def test_the_pair_kind_with_the_softened_potential_is_the_softened_field(count):
    torch.manual_seed(0)
    model = PairHNN(Bodies(8, 2), hidden_dim=8).double()
    model.radial_net = _Softened(0.1)
    x = _states(count, 4, seed=2)
    assert torch.allclose(model.time_derivative(x), nbody.dynamics(x, 0.1), rtol=0, atol=64 * EPS * count / 0.1 ** 2)
    assert torch.allclose(model.hamiltonian(x), nbody.hamiltonian(x, 0.1), rtol=64 * EPS * count ** 2, atol=0)


def test_without_softening_close_encounters_are_redrawn(tmp_path):
    data = load_task("gravity")
    # a tenth of a time unit: some of the disk's starts meet closer than MIN_SEPARATION, most do not
    d = data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 0.1], softening=0.0)
    x = torch.tensor(np.concatenate([d["x"], d["test_x"]]), dtype=torch.float64)
    assert x.shape == (50, 32) and d["resampled"] > 0
    assert float(nbody.min_separation(x).min()) >= MIN_SEPARATION * (1 - 1e-6)     # float32 rows
    soft = data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 0.1])
    assert soft["resampled"] == 0 and soft["cache_key"] != d["cache_key"]
    # over a whole time unit nearly every unsoftened path meets another body: the generator gives up, by name
    with pytest.raises(RuntimeError, match="redrawing"):
        data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 1.0], softening=0.0)
