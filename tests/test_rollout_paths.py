"""The rollout's fast paths give today's numbers: the evaluation kernel against autograd's field,
the separable halves against the whole field, no graph unless asked, one thread for a few states."""
import numpy as np
import pytest
import torch

import hnn


def _autograd_field(model):
    """``model``'s dx/dt by plain autograd of its H (the independent reference), ``(batch, 2n)``."""
    def f(x):
        with torch.enable_grad():
            y = x.detach().requires_grad_(True)
            g = torch.autograd.grad(model.hamiltonian(y).sum(), y)[0]
        n = x.shape[1] // 2
        return torch.cat([g[:, n:], -g[:, :n]], dim=1)
    return f


def _models(dtype):
    torch.manual_seed(3)
    return {"hnn": hnn.build_model(4, 32).to(dtype), "separable": hnn.SeparableHNN(4, 32).to(dtype)}


@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-10), (torch.float32, 2e-4)])
@pytest.mark.parametrize("batch", [1, 64])
@pytest.mark.parametrize("method", ["rk4", "leapfrog", "midpoint", "yoshida4", "dopri5", "dop853"])
def test_fast_rollouts_match_the_autograd_field(method, batch, dtype, tol):
    t = np.linspace(0.0, 2.0, 11)
    adaptive = method in ("dopri5", "dop853")
    options = {"rtol": 1e-8, "atol": 1e-8} if adaptive else {"dt": 0.05}
    if adaptive and dtype == torch.float32:
        options = {"rtol": 1e-4, "atol": 1e-6}
    x0 = 0.5 * torch.randn(batch, 4, generator=torch.Generator().manual_seed(batch)).to(dtype)
    for name, model in _models(dtype).items():
        fast = hnn.rollout(model.time_derivative, x0, t, method=method, **options)
        reference = hnn.rollout(_autograd_field(model), x0, t, method=method, **options)
        assert fast.dtype == dtype
        # float32: the two fields round differently (numpy's tanh, another summation order) and
        # the rollouts compound it over 40 steps
        torch.testing.assert_close(fast, reference, rtol=tol, atol=tol, msg=f"{name} {method}")


def test_leapfrog_on_the_separable_halves_is_the_whole_field_leapfrog():
    """One dT/dp and one dV/dq a step give the same states as two whole-field calls a step."""
    model = _models(torch.float64)["separable"]
    x0 = torch.randn(8, 4, dtype=torch.float64)
    t = np.linspace(0.0, 3.0, 7)
    for method in ("leapfrog", "yoshida4"):
        halves, whole = {}, {}
        fast = hnn.rollout(model, x0, t, method=method, dt=0.1, stats=halves)     # its declared SplitField
        slow = hnn.rollout(lambda x: model.time_derivative(x), x0, t, method=method, dt=0.1, stats=whole)
        torch.testing.assert_close(fast, slow, rtol=1e-12, atol=1e-12)
        # a half counts a half: 30 steps (90 for yoshida4) of two halves, plus the first dV/dq
        assert whole["nfev"] == 2 * halves["nfev"] + 1


def test_no_graph_by_default_whatever_the_grad_mode():
    model = _models(torch.float64)["hnn"]
    x0 = torch.randn(3, 4, dtype=torch.float64, requires_grad=True)
    for method in ("rk4", "midpoint", "dopri5", "solve_ivp"):
        out = hnn.rollout(model.time_derivative, x0, [0.0, 0.5, 1.0], method=method)
        assert not out.requires_grad, method
    with pytest.raises(ValueError, match="differentiable"):
        hnn.rollout(model.time_derivative, x0, [0.0, 1.0], method="dopri5", differentiable=True)


@pytest.mark.parametrize("method", ["rk4", "leapfrog", "midpoint"])
def test_a_differentiable_rollout_has_the_finite_difference_gradient(method):
    """d(final state . w)/dx0 and d/d(a weight) by autograd through the rollout against central differences."""
    model = _models(torch.float64)["separable" if method == "leapfrog" else "hnn"]
    x0 = torch.tensor([[0.3, -0.2, 0.5, 0.1]], dtype=torch.float64)
    w = torch.tensor([1.0, -2.0, 0.5, 3.0], dtype=torch.float64)
    t = [0.0, 0.4, 0.8]

    def loss(x):
        return (hnn.rollout(model.time_derivative, x, t, method=method, dt=0.1, differentiable=True)[0, -1] * w).sum()
    x = x0.clone().requires_grad_(True)
    out = loss(x)
    assert out.requires_grad
    weight = next(model.parameters())
    grad_x, grad_w = torch.autograd.grad(out, [x, weight])
    eps = 1e-6
    with torch.no_grad():
        for i in range(4):
            e = torch.zeros_like(x0)
            e[0, i] = eps
            fd = (loss(x0 + e) - loss(x0 - e)) / (2 * eps)
            assert abs(float(fd) - float(grad_x[0, i])) < 1e-7, (i, float(fd), float(grad_x[0, i]))
        idx = (0, 0)
        old = float(weight[idx])
        weight[idx] = old + eps
        up = float(loss(x0))
        weight[idx] = old - eps
        down = float(loss(x0))
        weight[idx] = old
    assert abs((up - down) / (2 * eps) - float(grad_w[idx])) < 1e-7


def test_a_rollout_runs_on_one_thread_unless_told_and_the_callers_setting_returns():
    seen = []

    def f(x):
        seen.append(torch.get_num_threads())
        return torch.cat([x[:, 1:], -x[:, :1]], dim=1)
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        hnn.rollout(f, torch.ones(500, 2), [0.0, 0.1], method="rk4")       # the default: one thread, any batch
        assert set(seen) == {1} and torch.get_num_threads() == 2
        seen.clear()
        hnn.rollout(f, torch.ones(3, 2), [0.0, 0.1], method="rk4", threads=2)
        assert set(seen) == {2}
        seen.clear()
        # None (the library's own calls): the caller's count, but one for a batch of at most 64 states
        hnn.rollout(f, torch.ones(64, 2), [0.0, 0.1], method="rk4", threads=None)
        assert set(seen) == {1}
        seen.clear()
        hnn.rollout(f, torch.ones(65, 2), [0.0, 0.1], method="rk4", threads=None)
        assert set(seen) == {2}
        with pytest.raises(ValueError):
            hnn.rollout(f, torch.ones(3, 2), [0.0, 0.0], method="rk4")
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(threads)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_fused_rk4_increment_is_the_classic_formula(dtype):
    """A float step takes the fused stage arithmetic, a (batch, 1) step the formula as written."""
    model = _models(dtype)["hnn"]
    x = torch.randn(64, 4, dtype=dtype)
    with torch.no_grad():
        fused = hnn.integrators.rk4_step(model.time_derivative, x, 0.1)
        classic = hnn.integrators.rk4_step(model.time_derivative, x, torch.full((64, 1), 0.1, dtype=dtype))
    eps = torch.finfo(dtype).eps
    torch.testing.assert_close(fused, classic, rtol=16 * eps, atol=16 * eps)   # a few roundings apart


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
@pytest.mark.parametrize("max_norm", [1e6, None])
def test_per_row_methods_name_the_rows_that_blow_up(max_norm, method):
    """dx/dt = x^2 blows up at t = 1/x0: rows 1 and 2 before t = 1, row 0 not; with max_norm=None
    the states run to inf/NaN and the finiteness test alone must catch them."""
    x0 = torch.tensor([[0.1, 0.1], [2.0, 0.1], [0.2, 4.0]], dtype=torch.float64)
    with pytest.raises(hnn.DivergenceError) as info:
        hnn.rollout(lambda x: x ** 2, x0, np.linspace(0, 1, 11), method=method, max_norm=max_norm)
    assert info.value.trajectories == [1, 2]
    # the poles are at 1/2 and 1/4; without max_norm, dop853's last accepted step may land just
    # past one (its error estimate catches the inf a step later)
    assert 0.2 < info.value.times[0] <= 0.5 + 1e-4 and 0.1 < info.value.times[1] <= 0.25 + 1e-4
