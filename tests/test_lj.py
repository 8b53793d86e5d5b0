"""The Lennard-Jones cluster (experiment-lj): its field is the symplectic gradient of its H, a pair inside the wall
is a WallError (never an overflow), and the radial library recovers 4 (r^-12 - r^-6) from dx/dt to round-off."""
import numpy as np
import pytest
import torch

import hnn
from hnn.kinds import model_from_args
from hnn.tasks import load_task, task_config

EPS = torch.finfo(torch.float64).eps


def _states(count, rows, seed=0):
    data = load_task("lj")
    rng = np.random.RandomState(seed)
    return torch.tensor(np.stack([data.random_config(rng, count) for _ in range(rows)]))


@pytest.mark.parametrize("count", [2, 8, 19])
def test_the_field_is_the_symplectic_gradient_of_h(count):
    data = load_task("lj")
    x = _states(count, 8)
    grad = hnn.interface.gradient_of(data.hamiltonian, x)
    n = x.shape[1] // 2
    # forces of size up to 24 (2 r^-13 - r^-7) at r >= 1.0: about 24 each, count - 1 pairs a body
    assert torch.allclose(data.dynamics(x), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=0,
                          atol=64 * EPS * 24 * count)


def test_a_pair_inside_the_wall_is_a_named_error():
    data = load_task("lj")
    x = _states(3, 2)
    bodies = data.layout(3)
    q, p = bodies.split(x)
    q[1, 2] = q[1, 0] + torch.tensor([0.5 * data.WALL, 0.0], dtype=torch.float64)
    close = bodies.join(q, p)
    for f in (data.dynamics, data.hamiltonian):
        with pytest.raises(data.WallError):
            f(close)
    q[1, 2] = q[1, 0]       # two bodies at one point: r = 0, whose r^-12 would be inf
    with pytest.raises(data.WallError):
        data.dynamics(bodies.join(q, p))


def test_the_radial_library_recovers_lennard_jones_and_runs_at_any_size():
    data = load_task("lj")
    x = _states(8, 150, seed=1)
    model = model_from_args({**task_config("lj").to_dict(), "kind": "pairwise", "fit": "library"})
    stats = hnn.fits.solve(model, x, data.dynamics(x), fit="library")
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # the refit of two columns, r^-6 and r^-12, nearly collinear over the cluster's r in [0.9, 4] (condition
    # ~1e3): a few eps times that
    assert set(kept) == {"1/r^6", "1/r^12"}
    assert kept["1/r^6"] == pytest.approx(-4.0, rel=1e4 * EPS) and kept["1/r^12"] == pytest.approx(4.0, rel=1e4 * EPS)
    assert stats["fit"]["equation"] == "H = sum p^2/(2 m) - 4 sum 1/r^6 + 4 sum 1/r^12, m = 1"
    big = _states(30, 2, seed=2)
    assert torch.allclose(model.time_derivative(big), data.dynamics(big), rtol=0, atol=1e-9)


def test_the_scene_trains_in_its_own_units():
    # its columns' sizes spread by where each body sits; hnn.units' auto would refuse the pair kind there
    assert task_config("lj").units == "off" and task_config("lattice").units == "off"
