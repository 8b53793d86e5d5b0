"""``method='dop853'``: Hairer's 8(5,3) pair with one step size per trajectory, against the
analytic harmonic oscillator (its convergence order and dense output) and scipy's DOP853."""
import numpy as np
import torch
from scipy.integrate import solve_ivp

import hnn


def _spring_solution(x0, t):
    """Exact flow of H = q^2 + p^2 (angular frequency 2): (batch, 2), (T,) -> (batch, T, 2)."""
    q0, p0 = x0[:, :1], x0[:, 1:]
    c, s = np.cos(2 * t)[None], np.sin(2 * t)[None]
    return np.stack([q0 * c + p0 * s, p0 * c - q0 * s], axis=-1)


def test_dop853_converges_at_its_declared_order(spring):
    """Error at the end against steps taken, over tolerances: the slope is the order (8), far
    from dopri5's 5. Only the end is asked for, so every step is a controller's step."""
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.7]], dtype=torch.float64)
    t = np.array([0.0, 10.0])
    exact = _spring_solution(x0.numpy(), t)[:, -1]
    steps, errors = [], []
    for tol in (1e-6, 1e-8, 1e-10, 1e-12):
        stats = {}
        traj = hnn.rollout(spring.dynamics, x0, t, method="dop853", rtol=tol, atol=tol, stats=stats)
        # 2 calls for the first step size, 12 a step, 3 for the dense output of the end
        steps.append((stats["nfev"] - 5) / 12)
        errors.append(np.abs(traj[:, -1].numpy() - exact).max())
    order = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    # an adaptive method's fitted order wanders around the true one with the controller's choices
    assert abs(order - hnn.get_solver("dop853").order) < 1.0, (order, steps, errors)


def test_dop853_dense_output_is_as_accurate_as_its_steps(spring):
    """Hundreds of outputs inside the steps (7th-order interpolation) meet the tolerance as the
    steps do; in a batch and backwards in time too."""
    x0 = torch.tensor([[1.0, 0.0], [0.2, 0.9], [-0.5, 0.4]], dtype=torch.float64)
    t = np.linspace(0, 30, 601)
    traj = hnn.rollout(spring.dynamics, x0, t, method="dop853", rtol=1e-11, atol=1e-12).numpy()
    np.testing.assert_allclose(traj, _spring_solution(x0.numpy(), t), atol=1e-9)
    back = hnn.rollout(spring.dynamics, torch.as_tensor(traj[:, -1]), t[::-1].copy(), method="dop853",
                       rtol=1e-11, atol=1e-12).numpy()
    np.testing.assert_allclose(back[:, ::-1], _spring_solution(x0.numpy(), t), atol=1e-9)


def test_dop853_agrees_with_scipys_dop853_row_by_row(pend):
    """Each row as its own scipy DOP853 call at a tight tolerance; a row's result does not depend
    on the other rows, to the last bit."""
    rng = np.random.RandomState(5)
    x0 = rng.uniform(-2.5, 2.5, size=(6, 2))
    x0[0] = [3.1, 0.0]                                   # near the separatrix: the hard one
    t = np.linspace(0, 8, 33)
    ours = hnn.rollout(pend.dynamics, torch.as_tensor(x0), t, method="dop853", rtol=1e-11, atol=1e-12).numpy()

    def f(_, y):
        return [2 * y[1], -3 * np.sin(y[0])]
    for i in range(len(x0)):
        scipy = solve_ivp(f, (0, 8), x0[i], t_eval=t, method="DOP853", rtol=1e-11, atol=1e-12).y.T
        exact = solve_ivp(f, (0, 8), x0[i], t_eval=t, method="DOP853", rtol=1e-13, atol=1e-13).y.T
        # the same method: the same accuracy (within a factor), and the two within both errors
        assert np.abs(ours[i] - exact).max() <= 3 * np.abs(scipy - exact).max() + 1e-12
        np.testing.assert_allclose(ours[i], scipy, atol=1e-8)
    alone = hnn.rollout(pend.dynamics, torch.as_tensor(x0[1:2]), t, method="dop853", rtol=1e-11, atol=1e-12).numpy()
    np.testing.assert_array_equal(alone[0], ours[1])


def test_dop853_takes_fewer_field_calls_than_dopri5_at_tight_tolerances(spring):
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    t = np.linspace(0, 30, 31)
    calls = {}
    for method in ("dopri5", "dop853"):
        stats = {}
        traj = hnn.rollout(spring.dynamics, x0, t, method=method, rtol=1e-10, atol=1e-10, stats=stats)
        np.testing.assert_allclose(traj.numpy(), _spring_solution(x0.numpy(), t), atol=1e-8)
        calls[method] = stats["nfev"]
    assert calls["dop853"] < calls["dopri5"] / 2, calls


def test_a_field_tied_to_row_positions_gets_every_row_in_every_call_dense_stages_too():
    # two oscillators 30x apart in frequency take different steps, so only some rows have an output time in a
    # step: with drop_finished=False the dense stages are evaluated on every row as well (a group's field, a
    # per-row time scale), and each row's path is the one it takes alone
    omega = torch.tensor([[1.0], [30.0]], dtype=torch.float64)
    sizes = []

    def f(x):
        sizes.append(len(x))
        return omega[:len(x)] * torch.stack([x[:, 1], -x[:, 0]], 1)
    x0 = torch.tensor([[1.0, 0.0], [1.0, 0.0]], dtype=torch.float64)
    t = np.linspace(0.0, 2.0, 7)
    together = hnn.rollout(f, x0, t, method="dop853", rtol=1e-9, atol=1e-9, drop_finished=False)
    assert set(sizes) == {2}, sorted(set(sizes))
    exact = torch.stack([torch.cos(omega * torch.as_tensor(t)), -torch.sin(omega * torch.as_tensor(t))], -1)
    torch.testing.assert_close(together, exact, rtol=0, atol=1e-6)
