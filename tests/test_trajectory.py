"""The trajectory objective (``--objective trajectory``) on every task's paths, against known fields."""
import numpy as np
import pytest
import torch

import hnn

spring = hnn.load_task("spring")
SpringConfig = hnn.load_task("spring", "train").Config


class _TrueSpring(hnn.Model):
    """The spring's true field as a model (for the noise floor of the snippet loss)."""
    input_dim = 2

    def __init__(self):
        super().__init__()
        self.unused = torch.nn.Parameter(torch.zeros(()))     # final_loss reads the model's dtype from it

    def time_derivative(self, x, t=None):
        return spring.dynamics(x)


def test_spring_trains_on_its_paths_from_the_command_line(tmp_path):
    """``train.py --objective trajectory``: the snippet loss falls to the floor the data's noise
    sets (the true field's own loss), and the learned dx/dt is the spring's."""
    main = hnn.load_task("spring", "train").main
    run = main(["--objective", "trajectory", "--snippet_steps", "4", "--total_steps", "200", "--hidden_dim", "32",
                "--learn_rate", "1e-2", "--save_dir", str(tmp_path)])
    model, args, metrics = hnn.load_run(run)
    assert args["objective"] == "trajectory" and args["snippet_steps"] == 4
    data = spring.get_dataset(seed=0)
    objective = hnn.objectives.trajectory.TrajectoryObjective(dt=data["dt"], steps=4)
    floor, _ = objective.final_loss(_TrueSpring(), *[objective.prepare(data)["test_snippets"]] * 2)
    assert metrics["history"]["test_loss"][0] > 1.5 * floor
    assert metrics["test_loss"] < 1.1 * floor     # measured 1.03x at 100 steps
    x, dxdt = torch.tensor(data["test_x"][:400]), torch.tensor(data["test_dxdt"][:400])
    relative = (model.time_derivative(x) - dxdt).pow(2).mean() / dxdt.pow(2).mean()
    assert relative < 0.1                         # measured 0.05: the noise (std 0.1) on the paths limits it


def test_snippets_are_cut_from_whole_paths():
    paths = np.arange(2 * 11 * 3, dtype=float).reshape(22, 3)          # two paths of 11 states, width 3
    cut = hnn.objectives.trajectory.snippets_from_paths(paths, 11, 4)               # 2 snippets of 5 states per path
    assert cut.shape == (4, 15)
    np.testing.assert_array_equal(cut[:, 0], [0, 15, 33, 48])            # path 2 starts at row 11 (value 33)
    np.testing.assert_array_equal(np.diff(cut[0].reshape(5, 3)[:, 0]), [3, 3, 3, 3])
    with pytest.raises(ValueError, match="not whole paths of 11"):
        hnn.objectives.trajectory.snippets_from_paths(paths[:-1], 11, 4)
    with pytest.raises(ValueError, match="snippet_steps must be an integer in \\[1, 10\\]"):
        hnn.objectives.trajectory.snippets_from_paths(paths, 11, 11)
    # the objective cuts a dataset's x and test_x paths, and names what it needs where there are none
    objective = hnn.objectives.trajectory.TrajectoryObjective(steps=4)
    data = objective.prepare({"x": paths, "test_x": paths[:11], "dt": 0.1, "t_eval": np.arange(11) * 0.1})
    assert data["snippets"].shape == (4, 15) and data["test_snippets"].shape == (2, 15)
    np.testing.assert_array_equal(data["snippets"], cut)
    assert objective.prepare(data) is data
    with pytest.raises(ValueError, match="trajectory training needs paths.*'snippets'.*--objective derivative"):
        objective.prepare({"x": paths, "test_x": paths})


def test_unknown_or_unfit_objective_is_refused(tmp_path, capsys):
    with pytest.raises(ValueError, match="objective='energy': choose one of derivative, trajectory"):
        hnn.run_experiment(SpringConfig(objective="energy", save_dir=str(tmp_path)))
    with pytest.raises(SystemExit):
        hnn.cli.parse(SpringConfig, ["--objective", "energy"])
    assert "invalid choice: 'energy'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="on pairs of frames; use objective=.derivative."):
        hnn.load_task("pixels", "train").Config(objective="trajectory").make_objective()
    with pytest.raises(ValueError, match="no 'snippets' and no 'dt' and 't_eval'"):
        hnn.objectives.trajectory.TrajectoryObjective().prepare({"x": np.zeros((4, 2)), "test_x": np.zeros((4, 2))})


class _Linear(hnn.Model):
    """dx/dt = A x, A learned: a black-box linear field of canonical states."""

    def __init__(self):
        super().__init__()
        self.input_dim = 2
        self.A = torch.nn.Parameter(torch.zeros(2, 2, dtype=torch.float64))

    def time_derivative(self, x, t=None):
        return x @ self.A.T


def test_trajectory_training_recovers_a_linear_oscillator():
    """Snippets of q'' = -omega^2 q (exact solutions) determine A = [[0, 1], [-omega^2, 0]]."""
    omega, dt, points = 2.0, 0.1, 5
    gen = torch.Generator().manual_seed(0)
    amplitude = 0.5 + torch.rand(64, generator=gen, dtype=torch.float64)
    phase = 2 * np.pi * torch.rand(64, generator=gen, dtype=torch.float64)
    t = dt * torch.arange(points, dtype=torch.float64)
    angle = omega * t[None] + phase[:, None]
    snippets = torch.stack([amplitude[:, None] * torch.cos(angle), -omega * amplitude[:, None] * torch.sin(angle)], -1)
    flat = snippets.reshape(64, -1)
    model = _Linear()
    loss = hnn.objectives.trajectory.TrajectoryObjective(dt=dt, loss="l2").loss_for(model)
    stats = hnn.train(model, flat, flat, total_steps=1500, learn_rate=3e-2, weight_decay=0.0, loss=loss, progress=False)
    # RK4's one-step error at omega dt = 0.2 biases A by about (omega dt)^4 / 120 relative: 1e-5
    torch.testing.assert_close(model.A.detach(), torch.tensor([[0.0, 1.0], [-omega ** 2, 0.0]], dtype=torch.float64),
                               rtol=0, atol=1e-3)
    assert stats["train_loss"][-1] < 1e-8
    with torch.no_grad():
        assert float(loss(flat, flat).max()) < 1e-8
