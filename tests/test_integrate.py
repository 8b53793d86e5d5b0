"""Rollouts against analytic solutions, per-trajectory scipy, and conservation laws; the solver
registry; energy protocols that choose their integrator."""
import dataclasses

import numpy as np
import pytest
import torch
from scipy.integrate import solve_ivp

import hnn


def spring_solution(x0, t):
    """Exact flow of H = q^2 + p^2 (angular frequency 2): (batch, 2), (T,) -> (batch, T, 2)."""
    q0, p0 = x0[:, :1], x0[:, 1:]
    c, s = np.cos(2 * t)[None], np.sin(2 * t)[None]
    return np.stack([q0 * c + p0 * s, p0 * c - q0 * s], axis=-1)


def test_rk4_converges_at_its_declared_order(spring):
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.7]], dtype=torch.float64)
    t = np.linspace(0, 5, 6)
    exact = spring_solution(x0.numpy(), t)
    errors = []
    dts = [0.1, 0.05, 0.025, 0.0125]
    for dt in dts:
        traj = hnn.rollout(spring.dynamics, x0, t, method="rk4", dt=dt).numpy()
        errors.append(np.abs(traj - exact).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - hnn.get_solver("rk4").order) < 0.15), orders


def test_solve_ivp_batched_equals_per_trajectory_scipy(pend):
    rng = np.random.RandomState(3)
    x0 = rng.uniform(-2, 2, size=(7, 2))
    t = np.linspace(0, 10, 50)
    batched = hnn.rollout(pend.dynamics, torch.as_tensor(x0), t, rtol=1e-10, atol=1e-10).numpy()

    def f(_, y):
        return [2 * y[1], -3 * np.sin(y[0])]
    for i in range(len(x0)):
        single = solve_ivp(f, (0, 10), x0[i], t_eval=t, rtol=1e-10, atol=1e-10).y.T
        np.testing.assert_allclose(batched[i], single, atol=1e-7)
    # and both agree with the analytic spring flow where there is one
    sp = hnn.rollout(hnn.load_task("spring").dynamics, torch.as_tensor(x0), t, rtol=1e-10, atol=1e-12).numpy()
    np.testing.assert_allclose(sp, spring_solution(x0, t), atol=1e-8)


@pytest.mark.parametrize("task", ["spring", "pend"])
def test_true_dynamics_conserve_energy_over_long_times(task):
    system = hnn.load_task(task)
    x0 = torch.tensor([[0.5, 0.5], [1.0, -1.5], [2.0, 0.3]], dtype=torch.float64)
    t = np.linspace(0, 200, 2001)                          # ~60 spring periods
    traj = hnn.rollout(system.dynamics, x0, t, rtol=1e-12, atol=1e-12, scipy_method="DOP853")
    H = system.hamiltonian(traj)
    drift = (H - H[:, :1]).abs().max()
    assert drift < 1e-7, float(drift)


def test_rollout_shapes_and_both_methods_agree(spring):
    x0 = torch.randn(4, 2, dtype=torch.float64)
    t = np.linspace(0, 1, 11)
    a = hnn.rollout(spring.dynamics, x0, t, rtol=1e-12, atol=1e-12)
    b = hnn.rollout(spring.dynamics, x0, t, method="rk4", dt=1e-3)
    assert a.shape == b.shape == (4, 11, 2)
    torch.testing.assert_close(a[:, 0], x0)
    torch.testing.assert_close(a, b, atol=1e-10, rtol=0)
    single = hnn.rollout(spring.dynamics, x0[0], t)
    assert single.shape == (1, 11, 2)


def test_rollout_backwards_in_time_returns_to_start(pend):
    x0 = torch.tensor([[1.0, 0.2]], dtype=torch.float64)
    fwd = hnn.rollout(pend.dynamics, x0, np.linspace(0, 5, 20), rtol=1e-12, atol=1e-12)
    back = hnn.rollout(pend.dynamics, fwd[:, -1], np.linspace(5, 0, 20), rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(back[:, -1], x0, atol=1e-9, rtol=0)


def test_blow_up_is_reported_not_returned_as_nan():
    def f(x):                       # dx/dt = x^2 blows up at t = 1/x0
        return x ** 2
    x0 = torch.tensor([[0.1, 0.1], [2.0, 0.1], [0.2, 4.0]], dtype=torch.float64)
    with pytest.raises(hnn.DivergenceError, match="diverged") as info:
        hnn.rollout(f, x0, np.linspace(0, 1, 11), method="rk4", dt=0.01)
    assert info.value.trajectories == [1, 2]
    assert all(0 < t <= 1 for t in info.value.times)
    with pytest.raises(hnn.DivergenceError):
        hnn.rollout(f, x0, np.linspace(0, 1, 11))


def test_bad_rollout_input():
    f = lambda x: -x  # noqa: E731
    with pytest.raises(ValueError, match="unknown method"):
        hnn.rollout(f, torch.zeros(1, 2), [0, 1], method="euler9")
    with pytest.raises(ValueError, match="t_eval must be strictly"):
        hnn.rollout(f, torch.zeros(1, 2), [0, 1, 1])
    with pytest.raises(ValueError, match="non-finite"):
        hnn.rollout(f, torch.tensor([[float("nan"), 0.0]]), [0, 1])
    with pytest.raises(ValueError, match="positive finite dt"):
        hnn.rollout(f, torch.zeros(1, 2), [0, 1], method="rk4", dt=-1.0)


def test_dopri5_controls_each_trajectory_like_its_own_scipy_call(pend):
    rng = np.random.RandomState(5)
    x0 = rng.uniform(-2.5, 2.5, size=(6, 2))
    x0[0] = [3.1, 0.0]                                   # near the separatrix: the hard one
    t = np.linspace(0, 8, 33)
    ours = hnn.rollout(pend.dynamics, torch.as_tensor(x0), t, method="dopri5", rtol=1e-8, atol=1e-10).numpy()

    def f(_, y):
        return [2 * y[1], -3 * np.sin(y[0])]
    for i in range(len(x0)):
        exact = solve_ivp(f, (0, 8), x0[i], t_eval=t, method="DOP853", rtol=1e-13, atol=1e-13).y.T
        scipy_rk45 = solve_ivp(f, (0, 8), x0[i], t_eval=t, rtol=1e-8, atol=1e-10).y.T
        # the same method and norm as scipy's RK45: errors of the same size, never much larger
        assert np.abs(ours[i] - exact).max() <= 3 * np.abs(scipy_rk45 - exact).max() + 1e-9
    # a row's result does not depend on the other rows (its own step sizes): a step shared with the others would
    # move it by the local error, ~1e-9 here. Not bit for bit: torch's sin may round an element in a SIMD lane 1 ulp
    # apart from the same element in the loop's scalar tail, and where an element lands depends on the batch's size
    # and alignment (seen: 1.8e-15 at one output, once, on a 6-row batch). The bitwise claim, on a field of + and *
    # alone, is test_one_trajectory_takes_the_steps_it_takes_in_a_batch's.
    alone = hnn.rollout(pend.dynamics, torch.as_tensor(x0[1:2]), t, method="dopri5", rtol=1e-8, atol=1e-10).numpy()
    np.testing.assert_allclose(alone[0], ours[1], rtol=1e-12, atol=1e-12)


def test_dopri5_matches_the_analytic_spring_and_runs_backwards(spring):
    x0 = torch.tensor([[1.0, 0.0], [0.2, 0.9]], dtype=torch.float64)
    t = np.linspace(0, 30, 61)
    traj = hnn.rollout(spring.dynamics, x0, t, method="dopri5", rtol=1e-11, atol=1e-12).numpy()
    np.testing.assert_allclose(traj, spring_solution(x0.numpy(), t), atol=1e-8)
    back = hnn.rollout(spring.dynamics, torch.as_tensor(traj[:, -1]), t[::-1].copy(), method="dopri5",
                       rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(back[:, -1].numpy(), x0.numpy(), atol=1e-8)


# ---------------------------------------------------------------- the registry of solvers

def test_the_registry_names_every_method_and_refuses_unknown_and_duplicate_ones():
    assert set(hnn.SOLVERS) == {"solve_ivp", "dopri5", "dop853", "rk4", "leapfrog", "midpoint", "yoshida4",
                                 "discrete_gradient"}
    assert hnn.integrators.SYMPLECTIC_METHODS == ("leapfrog", "midpoint", "yoshida4")
    assert [n for n, s in hnn.SOLVERS.items() if s.adaptive] == ["solve_ivp", "dopri5", "dop853"]
    with pytest.raises(ValueError, match=r"unknown method 'euler9'; choose one of \['discrete_gradient', 'dop853', 'dopri5'"):
        hnn.get_solver("euler9")
    with pytest.raises(ValueError, match="already registered"):
        hnn.register_solver(hnn.get_solver("rk4"))
    with pytest.raises(TypeError, match="needs a hnn.Solver"):
        hnn.register_solver("rk4")
    assert set(hnn.SOLVERS) == {"solve_ivp", "dopri5", "dop853", "rk4", "leapfrog", "midpoint", "yoshida4",
                                 "discrete_gradient"}


def test_solvers_describe_themselves_for_reports():
    assert hnn.get_solver("solve_ivp").describe({}) == "RK45"
    assert hnn.get_solver("solve_ivp").describe({"scipy_method": "DOP853"}) == "DOP853"
    assert hnn.get_solver("dopri5").describe({}) == "dopri5"
    assert hnn.get_solver("yoshida4").describe({"base": "midpoint", "dt": 0.01}) == "yoshida4 base midpoint dt 0.01"


# ---------------------------------------------------------------- the energy protocol's integrator

def test_the_default_protocols_describe_their_integrator_word_for_word_as_before():
    # generated tables quote these
    assert hnn.tasks.get_protocol("spring", "paper").describe() == (
        "paper: 15 trials (box), t in [0, 21.8], 100 points, RK45 rtol 1e-12 atol 1e-06, energy = q2+p2, "
        "model time x1.09 compounding per trial")
    assert hnn.tasks.get_protocol("real", "paper").describe() == (
        "paper: the measured test segment, its own times, RK45 rtol 0.001 atol 1e-06, energy = hamiltonian")
    assert all(p.method == "solve_ivp" and p.options == () for ps in hnn.PROTOCOLS.values() for p in ps.values())


def test_an_energy_protocol_swaps_its_integrator_in_one_field(spring):
    torch.manual_seed(0)
    model = hnn.build_model(2, 16)
    rk45 = dataclasses.replace(hnn.tasks.get_protocol("spring", "corrected"), num_trials=5)
    dopri5 = dataclasses.replace(rk45, method="dopri5")
    a, b = (hnn.evaluate_energy(spring, {"hnn": model}, p) for p in (rk45, dopri5))
    # the same Dormand-Prince pair, controlled per trajectory: measured 8e-6 apart on the true
    # energies (atol 1e-6 dominates) and 1.3e-7 relative on the model's MSE
    np.testing.assert_allclose(b["energy_truth"], a["energy_truth"], atol=1e-4, rtol=0)
    assert b["hnn"]["mse"] == pytest.approx(a["hnn"]["mse"], rel=1e-5)
    assert b["protocol"]["method"] == "dopri5"
    assert dopri5.describe() == rk45.describe().replace("RK45", "dopri5")
    assert hash(dopri5) != hash(rk45) and dopri5 == dataclasses.replace(rk45, method="dopri5")


def test_protocol_options_and_fixed_step_methods(spring):
    base = dataclasses.replace(hnn.tasks.get_protocol("spring", "corrected"), num_trials=5)
    dop853 = dataclasses.replace(base, options={"scipy_method": "DOP853"})
    assert dop853.options == (("scipy_method", "DOP853"),) and "DOP853 rtol 1e-12 atol 1e-06" in dop853.describe()
    # a fixed-step method gets no rtol/atol; dt is in the rescaled time s = t / 20 here
    rk4 = dataclasses.replace(base, method="rk4", options={"dt": 1e-3})
    assert rk4.rollout_options() == {"method": "rk4", "dt": 1e-3} and ", rk4 dt 0.001, " in rk4.describe()
    a, b = (hnn.evaluate_energy(spring, {}, p)["truth"] for p in (dop853, rk4))
    np.testing.assert_allclose(b, a, atol=1e-5)      # measured 4e-6: DOP853 at the protocol's atol 1e-6
    with pytest.raises(ValueError, match="unknown method 'rk5'"):
        dataclasses.replace(base, method="rk5")
    # per-trial time scales need every row in every call of f: dopri5 keeps its finished rows for them
    paper = dataclasses.replace(hnn.tasks.get_protocol("spring", "paper"), num_trials=5)
    a, b = (hnn.evaluate_energy(spring, {}, p)["truth"] for p in (paper, dataclasses.replace(paper, method="dopri5")))
    # both at the protocol's atol 1e-6 over spans to 21.8 x 1.09^4, rows controlled alone or by the batch's
    # RMS: measured 1.6e-5 apart
    np.testing.assert_allclose(b, a, atol=5e-5)


def test_an_option_the_method_does_not_take_is_one_error_naming_its_options():
    x0, t = torch.ones(1, 2, dtype=torch.float64), [0.0, 0.1]
    f = lambda x: torch.cat([x[:, 1:], -x[:, :1]], 1)      # noqa: E731
    with pytest.raises(ValueError, match=r"method 'rk4' takes the options dt, max_norm, stats; got rtol"):
        hnn.rollout(f, x0, t, method="rk4", rtol=1e-6)
    with pytest.raises(ValueError, match="'leapfrog' takes .*got tol"):       # it would ignore a tolerance
        hnn.rollout(f, x0, t, method="leapfrog", tol=1e-9)
    with pytest.raises(ValueError, match="'dopri5' takes the options rtol, atol.*got dt"):
        hnn.rollout(f, x0, t, method="dopri5", dt=0.01)
    for name, solver in hnn.SOLVERS.items():      # what each declares is what its run accepts
        if not solver.needs_hamiltonian:
            assert "max_norm" in solver.accepts() and "stats" in solver.accepts(), name
            hnn.rollout(f, x0, t, method=name, stats={}, max_norm=1e3)


def test_a_model_s_bound_field_rolls_out_as_the_model():
    """Given ``model.time_derivative``, a separable model's leapfrog still steps its halves one at a time."""
    torch.manual_seed(0)
    model = hnn.models.SeparableHNN(2, 16).double()
    x0, t = torch.tensor([[0.5, 0.1]], dtype=torch.float64), np.linspace(0, 1, 5)
    by_model, by_field = {}, {}
    a = hnn.rollout(model, x0, t, method="leapfrog", dt=0.1, stats=by_model)
    b = hnn.rollout(model.time_derivative, x0, t, method="leapfrog", dt=0.1, stats=by_field)
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    assert by_field == by_model


def test_solve_ivp_stops_past_max_calls_on_a_stiff_field_and_a_protocol_gives_its_rollouts_a_budget(monkeypatch):
    """A field stiff along its path makes scipy's RK45 shrink its step without end (here dx/dt = -1e5 x: about
    3e4 calls over t in [0, 1]); ``max_calls`` stops it with a DivergenceError naming the budget, and an energy
    protocol's solve_ivp rollouts get ``MAX_FIELD_CALLS`` (a model that fails it scores no energy, and why)."""
    x0, t = torch.ones(1, 2, dtype=torch.float64), np.linspace(0, 1, 5)
    with pytest.raises(hnn.DivergenceError, match="over 1000 calls of the field"):
        hnn.rollout(lambda x: -1e5 * x, x0, t, method="solve_ivp", max_calls=1000)
    stats = {}
    hnn.rollout(lambda x: -1e5 * x, x0, t, method="solve_ivp", stats=stats)
    assert stats["nfev"] > 1000
    protocol = hnn.tasks.get_protocol("spring", "paper")
    assert protocol.method == "solve_ivp"
    monkeypatch.setattr(hnn.evaluation, "MAX_FIELD_CALLS", 1000)
    with pytest.raises(hnn.DivergenceError, match="over 1000 calls"):
        hnn.evaluation._protocol_rollout(lambda x: -1e5 * x, x0, t, protocol)


def test_a_rollout_budget_stops_a_stiff_models_rollout_and_its_score_says_so():
    """Within ``hnn.evaluation.rollout_budget``, a model's rollout stops at the field calls its seconds buy at the
    rollout's own rate (a ``BudgetError``, a ``DivergenceError``), and its score says "stopped: over its budget"
    instead of a number; a healthy model's score equals its score outside the budget, and the truth is not bounded.
    Here dx/dt = -1e5 x makes RK45 shrink its step to its stability limit, about 3e4 calls over t in [0, 1]."""
    stiff = _Stiff()
    spring = hnn.load_task("spring")
    protocol = dataclasses.replace(hnn.tasks.get_protocol("spring", "corrected"), num_trials=5, t_span=(0.0, 1.0))
    healthy = hnn.evaluate_energy(spring, {"true": _True(spring)}, protocol, progress=False)
    with hnn.evaluation.rollout_budget(0.05, "a test's"):
        out = hnn.evaluate_energy(spring, {"stiff": stiff}, protocol, progress=False)
        paths = hnn.evaluation.rollout_errors(stiff.time_derivative, torch.ones(2, 5, 2, dtype=torch.float64),
                                              np.linspace(0, 1, 5))
    assert out["stiff"]["mse"] is None and out["stiff"]["stopped"].startswith("stopped: over its budget of ")
    assert "a test's" in out["stiff"]["stopped"] and "rollout failed" in out["stiff"]["why"]
    # the truth's rollout is not bounded, and a model within its budget scores as without one (the same path)
    np.testing.assert_array_equal(out["truth"], healthy["truth"])
    with hnn.evaluation.rollout_budget(60.0):
        within = hnn.evaluate_energy(spring, {"true": _True(spring)}, protocol, progress=False)
    assert within["true"]["mse"] == healthy["true"]["mse"] and "stopped" not in within["true"]
    np.testing.assert_array_equal(within["true"]["traj"], healthy["true"]["traj"])
    # the rollout error's paths share one budget: the batch stops, and then each path at once
    assert paths["stopped"] == 2 and paths["blew_up"] == 0
    # the budget is the rollout's share at its own rate: far fewer calls than the stiff field needs unbounded
    assert stiff.calls < 30_000
    with pytest.raises(hnn.BudgetError, match="over its budget of") as err:
        with hnn.evaluation.rollout_budget(0.01):
            hnn.evaluation._protocol_rollout(stiff, torch.ones(1, 2, dtype=torch.float64), np.linspace(0, 1, 5),
                                             protocol, share=1)
    assert isinstance(err.value, hnn.DivergenceError) and err.value.calls >= hnn.evaluation.RATE_CALLS


@pytest.mark.parametrize("seconds", [0, -1.0, float("inf"), float("nan"), True, "2"])
def test_a_rollout_budget_refuses_a_budget_that_is_not_a_positive_number_of_seconds(seconds):
    with pytest.raises(ValueError, match="positive finite number"):
        with hnn.evaluation.rollout_budget(seconds):
            pass


class _Stiff(hnn.Model):
    """A model whose field dx/dt = -1e5 x is stiff everywhere; counts its calls."""

    def __init__(self):
        super().__init__()
        self.w = torch.nn.Parameter(torch.ones(1, dtype=torch.float64))
        self.calls = 0

    def time_derivative(self, x, t=None):
        self.calls += 1
        return -1e5 * self.w * x


class _True(hnn.Model):
    """The spring's true field as a model (float64)."""

    def __init__(self, system):
        super().__init__()
        self.system = system
        self.w = torch.nn.Parameter(torch.ones(1, dtype=torch.float64))

    def time_derivative(self, x, t=None):
        return self.system.dynamics(x)


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_one_trajectory_takes_the_steps_it_takes_in_a_batch(method):
    """One state steps through hnn.integrators.one_row (its bookkeeping in Python floats): the same
    bits, calls, rejected steps and blow-up times as the same row beside another in the general driver,
    forward and backward, with several output times in a step and with none in most."""
    def duffing(x):                     # stiffening with the amplitude: rejected steps at loose tolerances
        return torch.stack([x[:, 1], -x[:, 0] - 4 * x[:, 0] ** 3], dim=1)
    x0 = torch.tensor([[1.3, -0.4], [0.2, 0.1]], dtype=torch.float64)
    rejected = 0
    for t in (np.linspace(0, 6, 301), np.linspace(0, -6, 4), np.array([0.0, 6.0])):
        for rtol in (1e-3, 1e-9):
            stats = {}
            alone = hnn.rollout(duffing, x0[:1], t, method=method, rtol=rtol, atol=rtol, stats=stats)
            both = hnn.rollout(duffing, x0, t, method=method, rtol=rtol, atol=rtol, drop_finished=False)
            assert torch.equal(alone[0], both[0])
            alone_again = hnn.rollout(duffing, x0[1:], t, method=method, rtol=rtol, atol=rtol)
            assert torch.equal(alone_again[0], both[1])
            rejected += stats["rejected"]
    assert rejected > 0         # the rejected-step branch was taken
    # a blow-up (dx/dt = x^2 reaches infinity at t = 1/x0): the row is named at the same time
    times = []
    for x in (x0[:1].abs() + 1, (x0.abs() + 1)):
        with pytest.raises(hnn.DivergenceError) as caught:
            hnn.rollout(lambda x: x * x, x, np.linspace(0, 2, 5), method=method, rtol=1e-6, atol=1e-8)
        times.append(str(caught.value).split("#0 at t=")[1].split(",")[0].split(".")[0:2])
    assert times[0] == times[1]


# our method, scipy's, and the calls scipy makes past ours on these paths: DOP853's first step computes its
# dense output for t0 too (3 calls), where ours starts the outputs at t[1]; RK45's dense output makes no call
SCIPY_TWINS = {"dopri5": ("RK45", 0), "dop853": ("DOP853", 3)}


@pytest.mark.parametrize("method", sorted(SCIPY_TWINS))
@pytest.mark.parametrize("batch", [8, 1])
def test_shared_steps_step_the_batch_as_scipy_steps_it(pend, method, batch):
    """steps='shared': the batch as one system, one step size and one error norm over every component, under
    scipy's step rule (its clause that no step grows right after a rejection too), as solve_ivp steps its
    flattened batch: the same calls and, to round-off, the same states, against scipy called directly (a
    batch of one state too: steps='shared' is scipy's terms on any batch)."""
    rng = np.random.RandomState(3)
    x0 = rng.uniform(-2.0, 2.0, size=(batch, 2))
    t = np.linspace(0, 6, 25)
    scipy_method, extra = SCIPY_TWINS[method]
    stats = {}
    ours = hnn.rollout(pend.dynamics, torch.as_tensor(x0), t, method=method, rtol=1e-7, atol=1e-9,
                       steps="shared", stats=stats).numpy()

    def f(_, y):
        q, p = y.reshape(batch, 2).T
        return np.stack([2 * p, -3 * np.sin(q)], 1).reshape(-1)
    theirs = solve_ivp(f, (0, 6), x0.reshape(-1), t_eval=t, method=scipy_method, rtol=1e-7, atol=1e-9)
    if batch > 1:
        assert stats["rejected"] > 0             # the rejection branch was met, and still the same calls
    gap = np.abs(ours - theirs.y.T.reshape(len(t), batch, 2).transpose(1, 0, 2)).max()
    if stats["nfev"] + extra == theirs.nfev:
        # the same decisions, so the same states to the round-off of the same sums: some 10 eps |y| (|y| ~ 3) a
        # step over a few hundred steps is under 1e-11 (a rule without scipy's clause parts them by 1e-10 .. 1e-7)
        assert gap < 1e-11
    else:
        # an error norm within round-off of 1 flipped one step (its calls) on this box: one tolerance's worth apart
        assert abs(stats["nfev"] + extra - theirs.nfev) <= (6 if method == "dopri5" else 15) and gap < 3e-6
    if batch > 1:
        per_row = hnn.rollout(pend.dynamics, torch.as_tensor(x0), t, method=method, rtol=1e-7, atol=1e-9).numpy()
        assert not np.array_equal(ours, per_row)        # the option took effect: another step sequence


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_shared_steps_converge_and_name_every_row(method, spring):
    x0 = torch.tensor([[1.0, 0.0], [0.2, 0.9], [-0.5, 0.3]], dtype=torch.float64)
    t = np.linspace(0, 20, 41)
    exact = spring_solution(x0.numpy(), t)
    errors = [np.abs(hnn.rollout(spring.dynamics, x0, t, method=method, rtol=r, atol=r, steps="shared").numpy()
                     - exact).max() for r in (1e-5, 1e-9)]
    assert errors[1] < errors[0] / 100 and errors[1] < 1e-7      # 4 decades of tolerance: at least 2 of error
    with pytest.raises(hnn.DivergenceError) as caught:      # dx/dt = x^2 blows up at t = 1/x0: the batch stops
        hnn.rollout(lambda x: x * x, x0.abs() + 1, np.linspace(0, 2, 5), method=method, rtol=1e-6, atol=1e-8,
                    steps="shared")
    assert caught.value.trajectories == [0, 1, 2] and len(caught.value.times) == 3
    with pytest.raises(ValueError, match="'row', 'shared'"):
        hnn.rollout(spring.dynamics, x0, t, method=method, steps="batch")
