"""Rollouts at the extremes: long horizons of untrained models, and blow-ups reported."""
import numpy as np
import pytest
import torch

import hnn


def test_untrained_hnn_long_rollout_stays_finite_and_conserves_its_own_hamiltonian():
    # any HNN conserves its learned H exactly in continuous time: a property of the symplectic field
    torch.manual_seed(1)
    model = hnn.build_model(8, 64).double()
    x0 = torch.randn(4, 8, dtype=torch.float64)
    traj = hnn.rollout(model.time_derivative, x0, np.linspace(0, 500, 201), rtol=1e-10, atol=1e-10)
    assert torch.isfinite(traj).all()
    H = model.hamiltonian(traj.reshape(-1, 8)).reshape(4, -1)
    assert (H - H[:, :1]).abs().max() < 1e-6 * H.abs().max()


def test_untrained_baseline_long_rollout_drifts_but_is_finite():
    torch.manual_seed(1)
    base = hnn.build_model(2, 64, baseline=True).double()
    traj = hnn.rollout(base.time_derivative, torch.ones(3, 2, dtype=torch.float64), np.linspace(0, 1000, 101))
    assert torch.isfinite(traj).all() and traj.shape == (3, 101, 2)


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
    with pytest.raises(hnn.DivergenceError, match="rk4"):
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
