"""The learned maps (``hnn.models.maps``: G-SympNet, LA-SympNet, HenonNet) against independent truths:
every layer and every whole map is symplectic, D^T J D = J to round-off (its Jacobian by torch.func, at
random states and random weights far from the identity); every layer has an exact inverse; a map trained
on the pendulum keeps the true energy bounded over 10^5 steps without drift (the same check flags RK4's
drift on the true field); a saved map reloads bit for bit with its step; a request at another step is one
error naming the step; the map kinds train, save, reload and roll out on every task with paths at a
fixed step and refuse the others with the fix."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

import hnn
from hnn.objectives.map import MapObjective, pairs_from_times
from hnn.models.maps import (ActivationShear, GradientShear, GSympNet, HenonLayer, HenonNet, LASympNet, LinearShears,
                             SymplecticMap)


def _J(n: int) -> torch.Tensor:
    eye = torch.eye(n, dtype=torch.float64)
    zero = torch.zeros(n, n, dtype=torch.float64)
    return torch.cat([torch.cat([zero, eye], 1), torch.cat([-eye, zero], 1)])


def _jacobians(step, x: torch.Tensor) -> torch.Tensor:
    """``(batch, 2n, 2n)`` Jacobians of ``step`` ``(batch, 2n) -> (batch, 2n)`` at each row of ``x``."""
    return torch.func.vmap(torch.func.jacrev(lambda row: step(row[None])[0]))(x)


def _symplecticity_error(step, x: torch.Tensor) -> float:
    D = _jacobians(step, x)
    J = _J(x.shape[1] // 2)
    return float((D.transpose(1, 2) @ J @ D - J).abs().max().detach())


def _scrambled(module: torch.nn.Module, seed: int, scale: float = 0.8) -> torch.nn.Module:
    """``module`` in float64 with every weight redrawn N(0, scale^2): far from the near-identity start."""
    module = module.double()
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.copy_(torch.randn(p.shape, generator=gen, dtype=torch.float64) * scale)
    return module


class _Layer(SymplecticMap):
    """One layer as a map of x = [q, p], so that its Jacobian is taken in the same coordinates."""

    def __init__(self, n: int, layer: torch.nn.Module):
        super().__init__(2 * n, [layer], dt=0.1)


LAYERS = {
    "gradient shear of p": lambda n: GradientShear(n, 7, "p", "tanh"),
    "gradient shear of q": lambda n: GradientShear(n, 7, "q", "sigmoid"),
    "activation shear of p": lambda n: ActivationShear(n, "p", "sigmoid"),
    "activation shear of q": lambda n: ActivationShear(n, "q", "tanh"),
    "linear shears": lambda n: LinearShears(n, 3, "q"),
    "henon layer": lambda n: HenonLayer(n, 7, "tanh"),
}
MAPS = {
    "g_sympnet": lambda dim: GSympNet(dim, 9, 5, "sigmoid", dt=0.1),
    "la_sympnet": lambda dim: LASympNet(dim, 3, 2, "tanh", dt=0.1),
    "henon": lambda dim: HenonNet(dim, 9, 2, "tanh", dt=0.1),
}


@pytest.mark.parametrize("n", [1, 3])
@pytest.mark.parametrize("name", sorted(LAYERS))
def test_every_layer_is_symplectic_and_exactly_invertible(name, n):
    layer = _Layer(n, _scrambled(LAYERS[name](n), seed=n))
    x = torch.randn(16, 2 * n, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        moved = layer.step(x)
        assert (moved - x).abs().max() > 0.1            # far from the identity: the check has something to see
    # D^T J D = J: the entries are O(1-10), so round-off in float64 stays near 1e-14
    assert _symplecticity_error(layer.step, x) < 1e-12
    with torch.no_grad():
        torch.testing.assert_close(layer.inverse(moved), x, rtol=0, atol=1e-12)
        torch.testing.assert_close(layer.step(layer.inverse(x)), x, rtol=0, atol=1e-12)


def _round_trip_atol(model: SymplecticMap, forward: torch.Tensor) -> float:
    """The round-off bound of ``forward`` ``(batch, steps + 1, 2n)`` stepped back by ``model.inverse``: each of
    the 2 x steps x len(layers) layers rounds its output to eps of the largest value on the path, and an error
    made k steps from the end reaches the start through the inverse's k steps, so times the largest norm of
    their Jacobian D(F^-k) (measured here: with scale-0.5 weights the LA-SympNet's linear shears reach 4e3
    at 12 dims, where 1e-10 held on one box and not another)."""
    steps = forward.shape[1] - 1
    depth = 2 * steps * len(model.layers)
    size = float(forward.abs().max())

    def back(k):
        def inverse_k(y):
            for _ in range(k):
                y = model.inverse(y)
            return y
        return inverse_k
    growth = max(float(torch.linalg.matrix_norm(_jacobians(back(k), forward[:, k].detach()), ord=2).max())
                 for k in range(1, steps + 1))
    return depth * torch.finfo(forward.dtype).eps * size * growth


@pytest.mark.parametrize("dim", [2, 4, 12])
@pytest.mark.parametrize("kind", sorted(MAPS))
def test_a_whole_map_is_symplectic_and_runs_backwards_by_its_inverse(kind, dim):
    model = _scrambled(MAPS[kind](dim), seed=dim, scale=0.5)
    x = torch.randn(8, dim, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    assert _symplecticity_error(model.step, x) < 1e-11
    t = model.dt * np.arange(4)
    forward = hnn.rollout(model, x, t)
    back = hnn.rollout(model, forward[:, -1], t[::-1] - t[-1])           # the same times, backwards
    atol = _round_trip_atol(model, forward)     # 1e-14 (HenonNet, 2 dims) .. 1.5e-7 (LA-SympNet, 12 dims)
    assert atol < 1e-6 * float(forward.abs().max())     # far below the O(1) miss of a wrong inverse
    torch.testing.assert_close(back[:, -1], x, rtol=0, atol=atol)
    torch.testing.assert_close(back.flip(1), forward, rtol=0, atol=atol)


def test_the_check_sees_a_map_that_is_not_symplectic():
    """A control for the checks above: a shear by a non-symmetric matrix (not a gradient) fails them."""
    A = torch.tensor([[0.0, 0.7], [0.0, 0.0]], dtype=torch.float64)
    x = torch.randn(4, 4, dtype=torch.float64)

    def step(z):
        return torch.cat([z[:, :2], z[:, 2:] + z[:, :2] @ A], 1)
    assert _symplecticity_error(step, x) > 0.1


def test_the_numpy_kernel_of_a_rollout_is_the_torch_step():
    """A rollout's few states step through ``MapKernel`` (numpy); many, and a differentiable rollout, through torch."""
    for kind in sorted(MAPS):
        model = _scrambled(MAPS[kind](4), seed=3, scale=0.5)
        x = torch.randn(5, 4, dtype=torch.float64)
        with torch.no_grad():
            expected = torch.stack([x, model.step(x), model.step(model.step(x))], 1)
        fast = hnn.rollout(model, x, model.dt * np.arange(3))
        torch.testing.assert_close(fast, expected, rtol=1e-12, atol=1e-13)
        slow = hnn.rollout(model, x, model.dt * np.arange(3), differentiable=True)
        assert slow.requires_grad
        torch.testing.assert_close(slow.detach(), expected, rtol=0, atol=0)


def _pendulum_pairs(h: float = 0.1, steps: int = 40) -> tuple[torch.Tensor, torch.Tensor]:
    """The SympNets pendulum H = p^2/2 - cos q at its step h = 0.1 and its 40 training steps, here from q = 0,
    p = 1 (an orbit of H = -0.5, where the protocol's starts at q = 1, p = 0: analysis/benchmarks/maps.py)."""
    def dynamics(x):
        return torch.cat([x[:, 1:], -torch.sin(x[:, :1])], 1)
    x0 = torch.tensor([[0.0, 1.0]], dtype=torch.float64)
    path = hnn.rollout(dynamics, x0, h * np.arange(steps + 1), method="dop853", rtol=1e-12, atol=1e-12)[0]
    return torch.cat([path[:-1], path[1:]], 1), x0


def _pendulum_energy(x):
    return x[..., 1] ** 2 / 2 - np.cos(x[..., 0])


def _drift_ratio(error: np.ndarray) -> float:
    """The largest |energy error| over the last tenth of a path over that of its first half: about 1 for
    an error that oscillates within a bound, about 2 for one that grows linearly."""
    n = len(error)
    return float(error[-n // 10:].max() / error[:n // 2].max())


def test_a_map_trained_on_the_pendulum_keeps_the_true_energy_bounded_without_drift_over_1e5_steps():
    pairs, x0 = _pendulum_pairs()
    torch.manual_seed(0)
    model = GSympNet(2, 16, 4, "tanh", dt=0.1).double()
    stats = hnn.train(model, pairs, pairs, total_steps=2000, learn_rate=3e-3, weight_decay=0.0,
                      loss=MapObjective().loss_for(model), print_every=10 ** 9)
    assert stats["train_loss"][-1] < 1e-4
    path = hnn.rollout(model, x0, model.dt * np.arange(100_001))[0].numpy()
    error = np.abs(_pendulum_energy(path) - _pendulum_energy(path[0]))
    # bounded: within a few percent of |H| = 0.5 after 10^4 time units (measured 2e-2 for this seed)
    assert error.max() < 0.05
    assert _drift_ratio(error) < 1.2
    half = len(error) // 2
    assert error[half:].mean() < 1.1 * error[:half].mean()

    # the control: RK4, not symplectic, on the true field at the same step drifts, and the check sees it
    q, p = 0.0, 1.0
    rk4 = np.empty(100_001)
    rk4[0] = 0.0
    h = 0.1
    for i in range(1, len(rk4)):
        k1q, k1p = p, -np.sin(q)
        k2q, k2p = p + h / 2 * k1p, -np.sin(q + h / 2 * k1q)
        k3q, k3p = p + h / 2 * k2p, -np.sin(q + h / 2 * k2q)
        k4q, k4p = p + h * k3p, -np.sin(q + h * k3q)
        q, p = q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q), p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
        rk4[i] = abs(p * p / 2 - np.cos(q) + 0.5)
    assert _drift_ratio(rk4) > 1.8


def _small_run(task: str, kind: str, save_dir, **extra):
    return hnn.tasks.task_config(task, {"model": kind, "total_steps": 5, "hidden_dim": 8, "map_layers": 2,
                                        "save_dir": str(save_dir), **extra})


def test_a_saved_map_reloads_bit_for_bit_with_its_step(tmp_path):
    config = _small_run("spring", "g_sympnet", tmp_path)
    data = config.dataset()
    folder = hnn.run_experiment(config)
    model, args, metrics = hnn.load_run(folder)
    assert args["dt"] == data["dt"] and model.dt == data["dt"] and args["map_layers"] == 2 and len(model.layers) == 2
    torch.manual_seed(config.seed)
    again = hnn.kinds.model_from_args(args)
    again.load_state_dict(torch.load(folder / "model.tar", weights_only=True)["state_dict"])
    x0 = torch.as_tensor(data["test_x"][:3])
    t = model.dt * np.arange(50)
    assert torch.equal(hnn.rollout(model, x0, t), hnn.rollout(again, x0, t))
    for name, w in model.state_dict().items():
        assert torch.equal(w, again.state_dict()[name])
    assert np.isfinite(metrics["test_loss"])


def test_a_request_at_another_step_is_one_error_naming_the_step():
    model = GSympNet(2, 8, 2, dt=0.25)
    x0 = torch.zeros(1, 2)
    with pytest.raises(ValueError, match=r"t_eval\[1\] - t_eval\[0\] = 0.1 is 0.4 steps .* step dt=0.25"):
        hnn.rollout(model, x0, [0.0, 0.1, 0.2])
    with pytest.raises(ValueError, match=r"dt=0.1 is not this learned map's step dt=0.25"):
        hnn.rollout(model, x0, [0.0, 0.25], dt=0.1)
    with pytest.raises(ValueError, match=r"steps itself \(dt=0.25\): no integrator applies, drop method='rk4'"):
        hnn.rollout(model, x0, [0.0, 0.25], method="rk4")
    with pytest.raises(ValueError, match="takes the options dt, max_norm, stats; got rtol"):
        hnn.rollout(model, x0, [0.0, 0.25], rtol=1e-6)
    with pytest.raises(ValueError, match="has no step dt"):
        hnn.rollout(GSympNet(2, 8, 2), x0, [0.0, 0.25])
    with pytest.raises(TypeError, match="no field dx/dt"):
        model.field(x0)
    with pytest.raises(ValueError, match="positive finite"):
        GSympNet(2, 8, 2, dt=0.0)
    # its own step, gaps of whole steps, dt given as its own: fine; the step count is its nfev
    stats = {}
    assert hnn.rollout(model, x0, [0.0, 0.25, 1.0], dt=0.25, stats=stats).shape == (1, 3, 2) and stats["nfev"] == 4
    # training at another step than the data's is refused, a field kind by the map objective too
    with pytest.raises(ValueError, match=r"step is dt=0.25 but its data are dt=0.1 apart"):
        MapObjective(dt=0.1).loss_for(model)
    with pytest.raises(ValueError, match="fits a learned map's step, and HNN is a field"):
        MapObjective(dt=0.1).loss_for(hnn.build_model(2, 8, "tanh", False))


def test_timed_rows_pair_only_across_one_step():
    rows = np.arange(12.0).reshape(6, 2)
    t = np.array([0.0, 1 / 6, 2 / 6, 4 / 6, 5 / 6, 20.0])          # a gap of two steps, then a jump
    pairs = pairs_from_times(rows, t, 1 / 6)
    np.testing.assert_array_equal(pairs, [[0, 1, 2, 3], [2, 3, 4, 5], [6, 7, 8, 9]])


@pytest.mark.parametrize("task", ["spring", "pend", "real", "2body", "3body"])
def test_the_map_kinds_train_save_reload_and_roll_out_on_every_task_with_paths(task, tmp_path):
    for kind in ("g_sympnet", "la_sympnet", "henon"):
        config = _small_run(task, kind, tmp_path)
        folder = hnn.run_experiment(config)
        model, args, _ = hnn.load_run(folder)
        assert model.steps and model.dt == pytest.approx(config.dataset()["dt"]) and args["kind"] == kind
        x0 = torch.as_tensor(config.dataset()["test_x"][:2])
        path = hnn.rollout(model, x0, model.dt * np.arange(5))
        assert path.shape == (2, 5, x0.shape[1]) and torch.isfinite(path).all()


@pytest.mark.parametrize("task, extra, fix", [
    ("chain", {"n_train": 4, "n_test": 2, "objective": "map"}, "reads neither the chain's angles"),
    ("arm", {}, "needs paths at a fixed step"),
])
def test_the_map_kinds_refuse_a_task_without_canonical_paths_with_the_fix(task, extra, fix, tmp_path):
    with pytest.raises(ValueError, match=fix):
        hnn.run_experiment(_small_run(task, "g_sympnet", tmp_path, **extra))


def test_an_energy_protocol_scores_a_map_at_its_own_step_and_says_where_it_does_not_apply(tmp_path):
    folder = hnn.run_experiment(_small_run("spring", "henon", tmp_path))
    model = hnn.load_run(folder)[0]
    spring = hnn.load_task("spring")
    protocol = dataclasses.replace(hnn.tasks.get_protocol("spring", "corrected"), num_trials=5)
    out = hnn.evaluate_energy(spring, {"map": model, "group": [model, model]}, protocol)
    steps = int(np.floor(20.0 / model.dt + 1e-9))
    assert out["map"]["traj"].shape == (5, steps + 1, 2) and np.isfinite(out["map"]["mse"])
    np.testing.assert_allclose(out["map"]["times"], model.dt * np.arange(steps + 1))
    assert [g["mse"] for g in out["group"]] == [out["map"]["mse"]] * 2
    paper = dataclasses.replace(hnn.tasks.get_protocol("spring", "paper"), num_trials=5)
    assert hnn.evaluate_energy(spring, {"map": model}, paper)["map"]["mse"] is None


def test_a_group_of_maps_trains_as_one_program_as_each_alone(tmp_path):
    """The map kinds are group-safe (``hnn.trainers.vmap``: vmap over stacked weights; tests/test_stacked.py holds
    a G-SympNet group's weights to its lone runs'). A HenonNet's zero-started shifts and biases get gradients
    near Adam's eps, where float rounding in another summation order moves a weight by 1e-7 absolute: its
    group is held to its lone runs by what they predict, a step from the test states."""
    configs = [_small_run("real", "henon", tmp_path / "group", seed=s, total_steps=20, batch_size=64, hidden_dim=32)
               for s in range(3)]
    assert hnn.sweeps.group_runs.unit_key(configs[0])[0] == "vmap"
    folders = hnn.sweeps.group_runs.train_group(configs)
    for config, folder in zip(configs, folders):
        alone = hnn.run_experiment(dataclasses.replace(config, save_dir=str(tmp_path / "alone")))
        (a, args, ma), (b, _, mb) = hnn.load_run(folder), hnn.load_run(alone)
        assert a.dt == b.dt == args["dt"]
        x = torch.as_tensor(config.dataset()["test_x"])
        with torch.no_grad():
            torch.testing.assert_close(a.step(x), b.step(x), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(ma["test_loss"], mb["test_loss"], rtol=1e-4)
