"""The Lennard-Jones cluster (experiment-lj): its field is the symplectic gradient of its H, a pair inside the wall
is a WallError (never an overflow), and the radial library recovers 4 (r^-12 - r^-6) from dx/dt to round-off.
With a cutoff: H is the truncated and shifted sum written out over every pair, continuous at r_c; the pair kind
with the exact V reads the same pairs; leapfrog's energy error at a crossing of r_c is the first-order jump the
force's discontinuity predicts."""
import dataclasses
import functools

import numpy as np
import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.kinds import model_from_args
from hnn.models.pair import PairHNN
from hnn.tasks import load_task, task_config

EPS = torch.finfo(torch.float64).eps


def _states(count, rows, seed=0):
    data = load_task("lj")
    rng = np.random.RandomState(seed)
    return torch.tensor(np.stack([data.random_config(rng, count) for _ in range(rows)]))


@pytest.mark.parametrize("cutoff", [None, 2.5])
@pytest.mark.parametrize("count", [2, 8, 19])
def test_the_field_is_the_symplectic_gradient_of_h(count, cutoff):
    data = load_task("lj")
    x = _states(count, 8)
    grad = hnn.interface.gradient_of(functools.partial(data.hamiltonian, cutoff=cutoff), x)
    n = x.shape[1] // 2
    # forces of size up to 24 (2 r^-13 - r^-7) at r >= 1.0: about 24 each, count - 1 pairs a body
    assert torch.allclose(data.dynamics(x, cutoff), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=0,
                          atol=64 * EPS * 24 * count)


def _lennard_jones(r):
    return 4 * (r ** -12 - r ** -6)


def _every_distance(q):
    """|q_i - q_j| of every pair i < j, ``(batch, N (N - 1) / 2)``, of positions ``(batch, N, dim)``."""
    i, j = torch.triu_indices(q.shape[1], q.shape[1], offset=1)
    return torch.linalg.vector_norm(q[:, i] - q[:, j], dim=-1)


def test_the_cutoff_h_is_the_shifted_sum_over_every_pair_and_continuous_at_the_cutoff():
    data = load_task("lj")
    cutoff = 2.5
    x = _states(40, 4, seed=3)
    q, p = data.layout(40).split(x)
    r = _every_distance(q)
    inside = r < cutoff
    assert inside.any() and not inside.all()        # the check can fail: the cluster spans several cutoffs
    written = (p * p).sum(dim=(1, 2)) / 2 + torch.where(inside, _lennard_jones(r) - _lennard_jones(cutoff), 0).sum(1)
    # |V| <= 1 a pair in the cluster, up to 780 pairs: a few eps each
    assert torch.allclose(data.hamiltonian(x, cutoff), written, rtol=0, atol=64 * EPS * 780)
    # two bodies a hair either side of r_c: H moves by V'(r_c) times the hair, not by V(r_c) (no jump)
    hair = 1e-7
    sides = [data.hamiltonian(torch.tensor([[0.0, cutoff + s, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]], dtype=torch.float64),
                              cutoff) for s in (-hair, hair)]
    slope = abs(4 * (-12 * cutoff ** -13 + 6 * cutoff ** -7))
    assert abs(float(sides[0] - sides[1])) <= slope * hair * (1 + 1e-6) + 16 * EPS
    assert abs(_lennard_jones(cutoff)) > 1e4 * slope * hair      # the shift's size: a jump would show


class _ExactLennardJones(torch.nn.Module):
    """V = 4 (r^-12 - r^-6) exactly, on the pair model's inputs (r, 1/r)."""

    def forward(self, features):
        inverse = features[:, 1:2]
        return 4 * (inverse ** 12 - inverse ** 6)


def test_the_pair_kind_with_the_exact_potential_reads_the_same_pairs_as_the_true_forces():
    data = load_task("lj")
    cutoff = 2.5
    x = _states(64, 3, seed=4)
    model = PairHNN(Bodies(8, 2, pairs="cutoff", cutoff=cutoff), hidden_dim=8).double()
    model.radial_net = _ExactLennardJones()
    with torch.no_grad():
        model.log_mass.zero_()
    # forces and energies of size ~ 24 a pair, up to 63 pairs a body and 2016 pairs a state: a few eps each
    assert torch.allclose(model.time_derivative(x), data.dynamics(x, cutoff), rtol=0, atol=64 * EPS * 24 * 63)
    assert torch.allclose(model.hamiltonian(x), data.hamiltonian(x, cutoff), rtol=0, atol=64 * EPS * 2016)


def test_leapfrog_across_the_cutoff_makes_the_first_order_error_of_the_force_jump():
    # two bodies head on, each at speed v, cross r_c inside a step at fraction theta of it. KDK kicks with the force
    # at the step's ends, so where the exact motion takes the impulse V'(r_c) (1 - theta) dt, leapfrog takes
    # V'(r_c) dt / 2: an energy error J |dr/dt| dt (theta - 1/2), J = |V'(r_c)|, first order in dt; the rest of the
    # error is leapfrog's own, second order. Written out at 64 phases theta and two steps:
    data = load_task("lj")
    cutoff, v = 2.5, 0.5
    jump = abs(4 * (-12 * cutoff ** -13 + 6 * cutoff ** -7))
    theta = (torch.arange(64, dtype=torch.float64) + 0.5) / 64
    residual, mean = [], []
    for dt in (0.02, 0.01):
        start = cutoff + 2 * v * dt * (3 + theta)        # crossing in the fourth step, at fraction theta
        zero = torch.zeros_like(theta)
        x0 = torch.stack([-start / 2, start / 2, zero, zero, zero + v, zero - v, zero, zero], dim=1)
        path = hnn.rollout(functools.partial(data.dynamics, cutoff=cutoff), x0, np.arange(7) * dt, method="leapfrog")
        error = data.hamiltonian(path[:, -1], cutoff) - data.hamiltonian(x0, cutoff)
        predicted = jump * 2 * v * dt * (theta - 0.5)
        residual.append(float((error - predicted).abs().max()))
        mean.append(float(error.abs().mean()) / (jump * 2 * v * dt))
        # the phases' mean of |theta - 1/2| is 1/4 exactly (the midpoint rule on each linear half)
        assert abs(mean[-1] - 0.25) <= residual[-1] / (jump * 2 * v * dt)
    # the residual is second order: halving dt divides it by 4 (4.2 measured; O(dt) more or less at these steps)
    assert 3 < residual[0] / residual[1] < 5.5
    # and the first-order term dominates it: without the cutoff's jump the error would be of the residual's size
    assert residual[1] < 0.05 * jump * 2 * v * 0.01 * 0.25


def test_the_cutoff_is_a_setting_of_the_task_whose_default_is_every_pair():
    config = task_config("lj")
    assert config.cutoff == 0 and "cutoff" not in config.identity()
    assert config.model_facts()["bodies"] == Bodies(8, 2).to_dict()
    cut = dataclasses.replace(config, cutoff=2.5)
    assert "cutoff" in cut.identity() and cut.key() != config.key()
    model = model_from_args({**cut.to_dict(), "kind": "pairwise"})
    assert model.bodies == Bodies(8, 2, pairs="cutoff", cutoff=2.5)
    data = load_task("lj")
    with pytest.raises(ValueError, match="wall"):
        data.get_dataset(cutoff=0.5)


def test_the_radial_library_recovers_lennard_jones_from_the_cutoff_field_where_every_pair_is_inside():
    # the library reads every pair (its layout has no cutoff): on the task's clusters of 8, whose pairs all lie within
    # r_c = 4, the cutoff's field is Lennard-Jones' and its shift one constant, so the same two terms come back
    data = load_task("lj")
    x = _states(8, 150, seed=1)
    q, _ = data.layout(8).split(x)
    assert float(torch.cdist(q, q).max()) < 4.0
    model = model_from_args({**task_config("lj").to_dict(), "kind": "pairwise", "fit": "library"})
    hnn.fits.solve(model, x, data.dynamics(x, 4.0), fit="library")
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # as the all-pairs test below: two nearly collinear columns, condition ~1e3
    assert set(kept) == {"1/r^6", "1/r^12"}
    assert kept["1/r^6"] == pytest.approx(-4.0, rel=1e4 * EPS) and kept["1/r^12"] == pytest.approx(4.0, rel=1e4 * EPS)


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
        with pytest.raises(data.WallError):       # the cell list finds the pair inside the wall too
            f(close, 2.5)
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


def _cutoff_fit(fit, x, cutoff, hidden_dim=16):
    data = load_task("lj")
    config = dataclasses.replace(task_config("lj"), cutoff=cutoff)
    torch.manual_seed(0)
    model = model_from_args({**config.to_dict(), "kind": "pairwise", "fit": fit, "hidden_dim": hidden_dim})
    stats = hnn.fits.solve(model, x, data.dynamics(x, cutoff), fit=fit, seed=0)
    return model, stats


def test_the_radial_library_recovers_the_truncated_and_shifted_lennard_jones_under_a_cutoff():
    # the task's clusters of 8, some of whose pairs lie beyond r_c = 2.5: the field there is the cut one, which no sum
    # of the library's terms over every pair gives, so the two terms come back exactly only where the fit reads the
    # cutoff
    data = load_task("lj")
    cutoff = 2.5
    x = _states(8, 150, seed=1)
    q, _ = data.layout(8).split(x)
    r = _every_distance(q)
    inside = r < cutoff
    assert 0.05 < float((~inside).double().mean()) < 0.5
    model, stats = _cutoff_fit("library", x, cutoff)
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # as the all-pairs test: two nearly collinear columns (condition ~1e3), a few eps times that
    assert set(kept) == {"1/r^6", "1/r^12"}
    assert kept["1/r^6"] == pytest.approx(-4.0, rel=1e4 * EPS) and kept["1/r^12"] == pytest.approx(4.0, rel=1e4 * EPS)
    assert float(model.inverse_mass[0]) == pytest.approx(1.0, rel=1e4 * EPS)
    assert stats["fit"]["equation"] == ("H = sum p^2/(2 m) + sum over r < 2.5 of [V(r) - V(2.5)], "
                                        "V = - 4 1/r^6 + 4 1/r^12, m = 1")
    # H is the task's own cut H (the shift V(r_c) the model's, not a constant of the fit's): the coefficients' error
    # (at most 4e4 eps each, above) times each term's sum over the pairs inside, plus a few eps a pair of summing
    terms = torch.where(inside, r ** -6 + r ** -12, 0).sum(dim=1) + 2 * cutoff ** -6
    bound = 4e4 * EPS * terms + 64 * EPS * inside.sum(dim=1) + 64 * EPS * (x[:, 16:] ** 2).sum(dim=1)
    assert bool(((model.hamiltonian(x) - model.offset - data.hamiltonian(x, cutoff)).abs() <= bound).all())
    # the same model on a cluster of 200 (the pairs by the cell list): the cut forces, each a sum of up to ~20 pairs'
    # of size up to ~24 r^-13 at r >= 0.9, with 4e4 eps relative error in its coefficients
    big = _states(200, 2, seed=2)
    assert torch.allclose(model.time_derivative(big), data.dynamics(big, cutoff), rtol=0, atol=4e4 * EPS * 24 * 4 * 20)


def test_a_sampled_pair_fit_under_a_cutoff_reads_no_pair_beyond_it():
    data = load_task("lj")
    cutoff = 2.5
    x = _states(8, 150, seed=1)
    model, _ = _cutoff_fit("swim", x, cutoff, hidden_dim=64)
    # its neurons are drawn from distances inside the cutoff alone, and the fitted field is the cut one's to the
    # neurons' accuracy: a relative error of 1.3e-5 measured at 64 neurons (2e-2 at 16), asserted at 1e-3, a
    # fit's accuracy not round-off's
    assert float(model._distances(x).max()) < cutoff
    with torch.no_grad():
        truth = data.dynamics(x, cutoff)
        assert float((model.time_derivative(x) - truth).norm() / truth.norm()) < 1e-3
    # two bodies beyond the cutoff: no energy (V(r) - V(r_c) is not read there) and no force, exactly; inside it,
    # the energy is V(r) - V(r_c): zero at r_c itself
    apart = torch.tensor([[0.0, cutoff + 0.1, 0.0, 0.0, 0.3, -0.3, 0.0, 0.0]], dtype=torch.float64)
    with torch.no_grad():
        assert float(model.potential(apart[:, :4])) == 0.0
        assert torch.equal(model.potential_gradient(apart[:, :4]), torch.zeros(1, 4, dtype=torch.float64))
        near = model.potential(torch.tensor([[0.0, cutoff * (1 - 1e-9), 0.0, 0.0]], dtype=torch.float64))
        assert abs(float(near)) < 1e-6
