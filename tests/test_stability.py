"""Rollouts at the extremes: long horizons of untrained models, and blow-ups reported."""
import numpy as np
import pytest
import torch
from scipy.integrate import solve_ivp

import hnn
from hnn.integrators.stability import StepSizeWarning


def test_untrained_hnn_long_rollout_stays_finite_and_conserves_its_own_hamiltonian():
    # any HNN conserves its learned H exactly in continuous time: a property of the symplectic field
    torch.manual_seed(1)
    model = hnn.build_model(8, 64).double()
    x0 = torch.randn(4, 8, dtype=torch.float64)
    traj = hnn.rollout(model.time_derivative, x0, np.linspace(0, 500, 201), rtol=1e-10, atol=1e-10)
    assert torch.isfinite(traj).all()
    H = model.hamiltonian(traj.reshape(-1, 8)).reshape(4, -1)
    assert (H - H[:, :1]).abs().max() < 1e-6 * H.abs().max()


def _numpy_baseline_field(model):
    """dx/dt of a baseline's tanh MLP, W3 tanh(W2 tanh(W1 x + b1) + b2), from its weights in numpy:
    ``(t, x (dim,)) -> (dim,)`` for scipy's ``solve_ivp``."""
    W1, b1, W2, b2, W3 = (p.detach().numpy() for p in model.differentiable_model.parameters())
    return lambda _, x: W3 @ np.tanh(W2 @ np.tanh(W1 @ x + b1) + b2)


def test_untrained_baseline_long_rollout_drifts_off_where_an_independent_solver_puts_it():
    # a baseline field is no symplectic gradient: nothing keeps its states on a closed orbit, and
    # where its tanh layers saturate the field is nearly constant, so states run off at a steady pace
    torch.manual_seed(1)
    base = hnn.build_model(2, 64, baseline=True).double()
    x0 = np.array([[1.0, 1.0], [-2.0, 0.5], [0.3, -3.0]])
    t = np.linspace(0, 1000, 101)
    field = _numpy_baseline_field(base)
    truth = np.stack([solve_ivp(field, (0, 1000), row, method="DOP853", t_eval=t, rtol=1e-12, atol=1e-12).y.T
                      for row in x0])
    tight = hnn.rollout(base.time_derivative, torch.tensor(x0), t, rtol=1e-10, atol=1e-10).numpy()
    np.testing.assert_allclose(tight, truth, rtol=0, atol=1e-6)
    loose = hnn.rollout(base.time_derivative, torch.tensor(x0), t).numpy()        # the default rtol 1e-3
    assert np.isfinite(loose).all() and np.abs(loose - truth).max() < 1e-3 * np.abs(truth).max()
    # the drift: hundreds of units away by t = 1000, as far in the last quarter as in the one before
    assert (np.linalg.norm(truth[:, -1] - x0, axis=1) > 200).all()
    last, before = (np.linalg.norm(truth[:, b] - truth[:, a], axis=1) for a, b in ((75, 100), (50, 75)))
    np.testing.assert_allclose(last, before, rtol=0.01)


@pytest.mark.parametrize("dt", [0.05, 0.1, 0.2])
def test_rk4_energy_drifts_secularly_by_its_amplification_factor(spring, dt):
    # the spring in z = q + ip is dz/dt = -2iz, and H = |z|^2. One RK4 step multiplies z by
    # R(-2i dt), R(w) = 1 + w + w^2/2 + w^3/6 + w^4/24, so every step scales H by exactly
    # |R(iy)|^2 = 1 - y^6/72 + y^8/576 (y = 2 dt): a loss growing with the number of steps,
    # where the true flow keeps H and a symplectic method's error stays bounded
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.4]], dtype=torch.float64)
    steps = np.array([0, 100, 1000, 10000])
    traj = hnn.rollout(spring.dynamics, x0, steps * dt, method="rk4", dt=dt)
    ratio = (spring.hamiltonian(traj) / spring.hamiltonian(x0)[:, None]).numpy()
    y = 2 * dt
    per_step = 1 - y ** 6 / 72 + y ** 8 / 576
    np.testing.assert_allclose(ratio, np.tile(per_step ** steps, (2, 1)), rtol=1e-10, atol=0)
    # secular: log H falls in proportion to the steps, 100 times as far in 10000 steps as in 100
    assert (ratio[:, 1:] < 1).all()
    np.testing.assert_allclose(np.log(ratio[:, 3]) / np.log(ratio[:, 1]), 100, rtol=1e-6)


@pytest.mark.parametrize("method, options", [("solve_ivp", {}), ("dopri5", {}), ("rk4", {"dt": 0.01})])
def test_exploding_states_are_reported_with_trajectory_and_time(method, options):
    # positive components grow like exp(20 t) and pass 1e6 near t = 0.69; negative ones decay to 0.
    # Rows 0 and 2 blow up, row 1 must not be named (f treats rows independently, as required)
    x0 = torch.tensor([[1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]], dtype=torch.float64)
    f = lambda x: torch.where(x > 0, 20 * x, -x)  # noqa: E731
    with pytest.raises(hnn.DivergenceError, match="diverged") as info:
        hnn.rollout(f, x0, np.linspace(0, 2, 41), method=method, **options)
    assert 0 in info.value.trajectories and 1 not in info.value.trajectories
    assert all(0.5 < t < 1.0 for t in info.value.times)
    # the same rollout is fine when the caller allows larger states
    out = hnn.rollout(f, x0, np.linspace(0, 1, 11), method=method,
                      max_norm=None, **options)
    assert torch.isfinite(out).all()


def test_step_size_past_rk4_stability_limit_is_reported(spring):
    # RK4 on the spring (eigenvalues +-2i) is stable for dt * 2 < 2.83; dt = 1.6 gives 3.2: growth
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    fine = hnn.rollout(spring.dynamics, x0, np.linspace(0, 200, 2001), method="rk4", dt=0.01)
    assert (spring.hamiltonian(fine[0]) - 1).abs().max() < 1e-6
    # warned before it starts (hnn.integrators.stability), and stopped once the state leaves max_norm
    with pytest.raises(hnn.DivergenceError, match="rk4"), pytest.warns(StepSizeWarning, match="Use dt below 1.41"):
        hnn.rollout(spring.dynamics, x0, np.linspace(0, 2000, 1251), method="rk4", dt=1.6)


class _AutogradMLP(hnn.MLP):
    """The same network, but not ``type(...) is MLP``: the HNN then takes autograd's input gradient."""


@pytest.mark.parametrize("scale", [1e-8, 1.0, 1e3, 1e6])
def test_time_derivative_is_finite_and_correct_for_huge_and_tiny_states(scale):
    torch.manual_seed(4)
    model = hnn.build_model(4, 32).double()
    reference = hnn.HNN(4, _AutogradMLP(4, 32, 2)).double()
    reference.differentiable_model.load_state_dict(model.differentiable_model.state_dict())
    x = scale * torch.tensor([[1.0, -0.5, 0.3, 2.0], [-0.7, 0.2, 1.0, -1.5]], dtype=torch.float64)
    with torch.no_grad():
        ours = model.time_derivative(x)
    assert torch.isfinite(ours).all()
    torch.testing.assert_close(ours, reference.time_derivative(x).detach(), rtol=1e-10, atol=1e-14)
    # an independent truth: central differences of the learned H, dx/dt = (dH/dp, -dH/dq)
    h = 1e-6 * max(scale, 1e-3)          # a step that resolves H's curvature at this scale
    grad = torch.zeros_like(x)
    for i in range(4):
        e = torch.zeros(4, dtype=torch.float64)
        e[i] = h
        grad[:, i] = (model.hamiltonian(x + e) - model.hamiltonian(x - e)).detach() / (2 * h)
    fd = torch.cat([grad[:, 2:], -grad[:, :2]], dim=1)
    torch.testing.assert_close(ours, fd, rtol=1e-5, atol=1e-8)
    # and training through such states gives finite parameter gradients (the closed-form backward)
    model.time_derivative(x).pow(2).sum().backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters())
