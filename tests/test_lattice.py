"""The chain of springs (experiment-lattice): its field is the symplectic gradient of its H, its paths keep H, and
the pair kind's radial library recovers its spring, V = (r - 1)^2 / 2, from dx/dt to round-off."""
import numpy as np
import pytest
import torch

import hnn
from hnn.kinds import model_from_args
from hnn.tasks import load_task, task_config

EPS = torch.finfo(torch.float64).eps


def _states(count, rows, seed=0):
    data = load_task("lattice")
    rng = np.random.RandomState(seed)
    return torch.tensor(np.stack([data.random_config(rng, count) for _ in range(rows)]))


@pytest.mark.parametrize("count", [2, 8, 33])
def test_the_field_is_the_symplectic_gradient_of_h(count):
    data = load_task("lattice")
    x = _states(count, 16)
    grad = hnn.interface.gradient_of(data.hamiltonian, x)
    n = x.shape[1] // 2
    assert torch.allclose(data.dynamics(x), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=0,
                          atol=64 * EPS * count)


def test_a_path_keeps_its_energy():
    data = load_task("lattice")
    x0 = _states(8, 4, seed=3)
    path = hnn.rollout(data.dynamics, x0, np.linspace(0, 10, 11), method="dop853", rtol=1e-12, atol=1e-12)
    H = data.hamiltonian(path.reshape(-1, path.shape[-1])).reshape(path.shape[:2])
    # dop853 at rtol 1e-12 over 10 time units: the energy error is of the tolerance's size, far below the
    # springs' energy (~0.5 a body)
    assert (H - H[:, :1]).abs().max() < 1e-9


def test_the_task_declares_a_chain_of_bodies():
    bodies = hnn.bodies.Bodies.from_dict(task_config("lattice").model_facts()["bodies"])
    assert bodies.pairs == "neighbours" and bodies.width == task_config("lattice").input_dim


def test_the_radial_library_recovers_the_spring_and_runs_at_any_length():
    data = load_task("lattice")
    x = _states(8, 200, seed=1)
    model = model_from_args({**task_config("lattice").to_dict(), "kind": "pairwise", "fit": "library"})
    stats = hnn.fits.solve(model, x, data.dynamics(x), fit="library")
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # V = r^2 / 2 - r (+ 1/2, which no force sees): the refit of two columns, r and r^2, whose condition over
    # r in [0.3, 2] is about 10: a few eps times that
    assert set(kept) == {"r", "r^2"}
    assert kept["r"] == pytest.approx(-1.0, rel=1e3 * EPS) and kept["r^2"] == pytest.approx(0.5, rel=1e3 * EPS)
    assert stats["fit"]["equation"] == "H = sum p^2/(2 m) - 1 sum r + 0.5 sum r^2, m = 1"
    long = _states(300, 2, seed=2)
    assert torch.allclose(model.time_derivative(long), data.dynamics(long), rtol=0, atol=1e-10)


def test_the_pair_kind_refuses_scales_per_column():
    model = model_from_args({**task_config("lattice").to_dict(), "kind": "pairwise"})
    assert "distances between bodies" in hnn.units.refusal(model)
    with pytest.raises(ValueError, match="units off"):
        hnn.units.check_supported(model)
