"""The original code's way, re-enacted for the benchmark to time against ours on the same data and
weights (never imported by the package): its spring data generator (one ``solve_ivp`` per
trajectory), its training loop (the field by autograd through ``torch.tanh``, plain Adam) and its
energy-MSE evaluation (``solve_ivp`` around a per-call numpy/torch round trip)."""
from __future__ import annotations

import copy

import numpy as np
import torch
from scipy.integrate import solve_ivp

import hnn
from hnn.evaluation import start_states
from hnn_analysis.benchmarks.floor_job import HIDDEN, LEARN_RATE, WEIGHT_DECAY

def spring_dynamics(t, y):
    """The true spring field in numpy: (dq/dt, dp/dt) = (2p, -2q)."""
    return np.array([2 * y[1], -2 * y[0]])


class OriginalMLP(torch.nn.Module):
    """The original's network (its nn_models.MLP): ``hnn.MLP``'s layers and weights, and ``torch.tanh``
    (``hnn.MLP`` computes a large tanh as 2 sigmoid(2a) - 1, which the original did not)."""

    def __init__(self, mlp: hnn.MLP):
        super().__init__()
        self.linear1, self.linear2, self.linear3 = (copy.deepcopy(layer) for layer in
                                                    (mlp.linear1, mlp.linear2, mlp.linear3))

    def forward(self, x):
        h = torch.tanh(self.linear1(x))
        h = torch.tanh(self.linear2(h))
        return self.linear3(h)


def original_model(model: hnn.HNN) -> hnn.HNN:
    """An HNN of the original's network with ``model``'s weights (its field is taken by autograd)."""
    return hnn.HNN(model.input_dim, OriginalMLP(model.differentiable_model))


def original_time_derivative(model: hnn.HNN, x: torch.Tensor) -> torch.Tensor:
    """The original HNN's field: ``grad F2 @ M.T`` by autograd with ``create_graph=True`` (x requires grad)."""
    F = model.differentiable_model(x)
    dF2 = torch.autograd.grad(F[:, 1].sum(), x, create_graph=True)[0]
    return dF2 @ model.M.T

def original_data(seed: int = 0, samples: int = 50, test_split: float = 0.5, noise_std: float = 0.1) -> dict:
    """One ``solve_ivp`` per trajectory, targets point by point, noise after, concatenate, split."""
    rng = np.random.RandomState(seed)
    t_eval = np.linspace(0, 3, 30)
    xs, dxs = [], []
    for _ in range(samples):
        y0 = rng.rand(2) * 2 - 1
        radius = rng.rand() * 0.9 + 0.1
        y0 = y0 / np.sqrt((y0 ** 2).sum()) * radius
        sol = solve_ivp(spring_dynamics, (0, 3), y0, t_eval=t_eval, rtol=1e-10)
        q, p = sol.y[0], sol.y[1]
        dydt = np.stack([spring_dynamics(None, y) for y in sol.y.T]).T
        q = q + rng.randn(*q.shape) * noise_std
        p = p + rng.randn(*p.shape) * noise_std
        xs.append(np.stack([q, p]).T)
        dxs.append(dydt.T)
    x, dx = np.concatenate(xs), np.concatenate(dxs)
    split = int(len(x) * (1 - test_split))
    return {"x": x[:split], "dxdt": dx[:split], "test_x": x[split:], "test_dxdt": dx[split:]}

def original_train(d: dict, steps: int):
    """The original loop: autograd double backprop, default Adam, full test loss with its graph every step."""
    torch.manual_seed(0)
    model = original_model(hnn.build_model(2, HIDDEN))
    optim = torch.optim.Adam(model.parameters(), LEARN_RATE, weight_decay=WEIGHT_DECAY)
    x = torch.tensor(d["x"], requires_grad=True, dtype=torch.float32)
    test_x = torch.tensor(d["test_x"], requires_grad=True, dtype=torch.float32)
    dxdt = torch.tensor(d["dxdt"], dtype=torch.float32)
    test_dxdt = torch.tensor(d["test_dxdt"], dtype=torch.float32)
    stats = {"train_loss": [], "test_loss": []}
    for _ in range(steps + 1):
        loss = ((dxdt - original_time_derivative(model, x)) ** 2).mean()
        loss.backward()
        optim.step()
        optim.zero_grad()
        test_loss = ((test_dxdt - original_time_derivative(model, test_x)) ** 2).mean()
        stats["train_loss"].append(loss.item())
        stats["test_loss"].append(test_loss.item())
    return model, stats

def original_eval(model, protocol) -> tuple[float, int]:
    """Per trial: truth by ``solve_ivp`` in numpy, model by ``solve_ivp`` one [1, 2] state per call."""
    calls = 0
    model = original_model(model)

    def fun(t, y):
        nonlocal calls
        calls += 1
        x = torch.tensor(y, requires_grad=True, dtype=torch.float32).view(1, 2)
        return original_time_derivative(model, x).data.numpy().reshape(-1)

    t_span = list(protocol.t_span)
    t_eval = np.linspace(t_span[0], t_span[1], protocol.num_points)
    per_trial = []
    for x0 in start_states(protocol):
        truth = solve_ivp(spring_dynamics, t_span, x0, t_eval=t_eval, rtol=protocol.rtol).y
        pred = solve_ivp(fun, t_span, x0, t_eval=t_eval, rtol=protocol.rtol).y
        e_true, e_pred = (truth ** 2).sum(0), (pred ** 2).sum(0)
        per_trial.append(np.mean((e_true - e_pred) ** 2))
    return float(np.mean(per_trial)), calls
