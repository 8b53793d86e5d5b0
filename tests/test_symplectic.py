"""Symplectic integrators against independent truths: convergence orders on the analytic spring,
J^T Omega J = Omega of one step, time reversibility, bounded energy error, stability limits."""
import dataclasses
import math
import warnings

import numpy as np
import pytest
import torch

import hnn
import hnn.integrators.fixed_step
import hnn.integrators.solvers
from hnn.integrators.stability import StepSizeWarning

SPRING_OMEGA = 2.0          # the repo's spring: H = q^2 + p^2, dq/dt = 2p, dp/dt = -2q
PEND_SEPARATRIX_H = 6.0     # the repo's pendulum: H = 3(1 - cos q) + p^2; H = 6 at the upright rest


def spring_solution(x0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Exact flow of H = q^2 + p^2, a rotation at angular frequency 2: (batch, 2), (T,) -> (batch, T, 2)."""
    q0, p0 = x0[:, :1], x0[:, 1:]
    c, s = np.cos(SPRING_OMEGA * t)[None], np.sin(SPRING_OMEGA * t)[None]
    return np.stack([q0 * c + p0 * s, p0 * c - q0 * s], axis=-1)


def true_field(task: str, method: str):
    """``task``'s true dynamics, carrying its H where ``method`` reads it (``needs_hamiltonian``)."""
    system = hnn.load_task(task)
    if hnn.get_solver(method).needs_hamiltonian:
        return hnn.interface.EnergyField(system.dynamics, system.hamiltonian)
    return system.dynamics


def order_of(method: str, **options) -> float:
    """Slope of log(max error at t = 2) vs log(dt) on the spring, float64, dt from 0.1 to 0.0125.

    By t = 2 even explicit Euler (whose error grows like exp(omega dt t)) is in its asymptotic
    regime at these dt: its slope is 1.06 there, 1.26 by t = 5."""
    field = true_field("spring", method)
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.7]], dtype=torch.float64)
    t = np.linspace(0, 2, 6)
    exact = spring_solution(x0.numpy(), t)
    dts = np.array([0.1, 0.05, 0.025, 0.0125])
    errors = [np.abs(hnn.rollout(field, x0, t, method=method, dt=dt, **options).numpy() - exact).max()
              for dt in dts]
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


def assert_declared_order(method: str, **options) -> None:
    """The fitted order of ``method`` is the one its registry entry declares."""
    slope = order_of(method, **options)
    assert abs(slope - hnn.get_solver(method).order) < 0.3, (method, options, slope)


# the registry read at collection time: a method registered later has to call the checks itself
FIXED_STEP = [name for name, solver in hnn.SOLVERS.items() if not solver.adaptive]
SYMPLECTIC = [name for name, solver in hnn.SOLVERS.items() if solver.symplectic]
# yoshida4 on the midpoint: symplectic for any H (its declared needs_separable is for base='leapfrog').
# The midpoint map is symplectic only as far as its implicit equation is solved: the Jacobian of
# the truncated iteration is off by ~tol, and the default 1e-12 leaves ~9e-12 after the
# composition's large substeps, so this case solves to 1e-14
YOSHIDA_ON_MIDPOINT = ("yoshida4", {"base": "midpoint", "tol": 1e-14})


def _case_id(value) -> str:
    """Test ids like ``yoshida4-base=midpoint,tol=1e-14`` (``-default`` without options)."""
    return value if isinstance(value, str) else ",".join(f"{k}={v}" for k, v in value.items()) or "default"


@pytest.mark.parametrize("method, options", [(m, {}) for m in FIXED_STEP] + [("yoshida4", {"base": "midpoint"})],
                         ids=_case_id)
def test_convergence_order_on_the_analytic_spring_is_the_declared_one(method, options):
    assert_declared_order(method, **options)


def test_a_perturbed_yoshida_weight_fails_the_order_check(monkeypatch):
    # 2 w1 + w0 = 1 still holds, so the composition stays consistent and symmetric (order 2), but
    # 2 w1^3 + w0^3 != 0: the h^3 term no longer cancels. The order check must see it.
    w1 = hnn.integrators.YOSHIDA_WEIGHTS[0] + 0.05
    monkeypatch.setattr(hnn.integrators.fixed_step, "YOSHIDA_WEIGHTS", (w1, 1 - 2 * w1, w1))
    slope = order_of("yoshida4")
    assert abs(slope - 4) > 0.3 and abs(slope - 2) < 0.3, slope


def test_yoshida_weights_are_the_derived_ones():
    w1, w0, w1b = hnn.integrators.YOSHIDA_WEIGHTS
    assert w1 == w1b
    assert abs(2 * w1 + w0 - 1) < 1e-15 and abs(2 * w1 ** 3 + w0 ** 3) < 1e-14


# ---------------------------------------------------------------- symplecticity: J^T Omega J = Omega

def _omega(dim: int) -> torch.Tensor:
    n = dim // 2
    eye, zero = torch.eye(n, dtype=torch.float64), torch.zeros(n, n, dtype=torch.float64)
    return torch.cat([torch.cat([zero, eye], 1), torch.cat([-eye, zero], 1)], 0)


def symplectic_defect(f, x: torch.Tensor, method: str, dt: float, **options) -> float:
    """max |J^T Omega J - Omega| of the one-step map of ``method`` at ``x`` (dim,), float64."""
    step = lambda y: hnn.rollout(f, y[None], [0.0, dt], method=method, differentiable=True, **options)[0, -1]  # noqa: E731
    J = torch.autograd.functional.jacobian(step, x)
    omega = _omega(len(x))
    return float((J.T @ omega @ J - omega).abs().max())


def _pendulum_field(x):
    return hnn.load_task("pend").dynamics(x)


def _untrained_hnn(dim=4):
    torch.manual_seed(2)
    return hnn.build_model(dim, 32).double()


_HNN_X = torch.tensor([0.3, -0.5, 0.8, 0.1], dtype=torch.float64)
_PEND_XS = ([1.0, 0.5], [2.9, -0.3], [-0.4, 2.0])


@pytest.mark.parametrize("method, options", [(m, {}) for m in SYMPLECTIC] + [YOSHIDA_ON_MIDPOINT],
                         ids=_case_id)
def test_declared_symplectic_methods_are_symplectic_on_the_separable_pendulum(method, options):
    for x in _PEND_XS:
        defect = symplectic_defect(_pendulum_field, torch.tensor(x, dtype=torch.float64), method, 0.3, **options)
        assert defect < 1e-12, (x, defect)


@pytest.mark.parametrize("method, options", [(m, {}) for m in SYMPLECTIC if not hnn.get_solver(m).needs_separable]
                         + [YOSHIDA_ON_MIDPOINT], ids=_case_id)
def test_methods_not_needing_separability_are_symplectic_on_an_untrained_hnn(method, options):
    model = _untrained_hnn()
    assert symplectic_defect(model.time_derivative, _HNN_X, method, 0.2, **options) < 1e-12


@pytest.mark.parametrize("method", [m for m in SYMPLECTIC if hnn.get_solver(m).needs_separable])
def test_methods_needing_separability_are_not_symplectic_for_a_learned_h(method):
    # the documented limit: leapfrog reads f as if H = T(p) + V(q); an HNN's H mixes q and p
    # (measured: 1.6e-4 leapfrog, 1.0e-3 yoshida4)
    assert symplectic_defect(_untrained_hnn().time_derivative, _HNN_X, method, 0.2) > 1e-6


@pytest.mark.parametrize("method", [m for m in FIXED_STEP if not hnn.get_solver(m).symplectic])
def test_methods_declared_not_symplectic_fail_the_check(method):
    # on the pendulum, whose field is far from linear (rk4's defect there: 4.7e-5); the adaptive
    # methods step outside autograd, so their one-step Jacobian is not taken here
    defect = symplectic_defect(true_field("pend", method), torch.tensor(_PEND_XS[0], dtype=torch.float64), method,
                               0.3)
    assert defect > 1e-5, defect


# ---------------------------------------------------------------- a new stepper is one registration

class _Euler(hnn.integrators.fixed_step.Stepper):
    """Explicit Euler, ``x + h f(x)``: order 1, not symplectic."""

    def step(self, x: torch.Tensor, h: float) -> torch.Tensor:
        self.nfev += 1
        return x + h * self.f(x)


@pytest.fixture
def euler():
    """``'euler'`` in the registry for one test."""
    solver = hnn.register_solver(hnn.integrators.solvers.fixed_step_solver("euler", _Euler, order=1))
    yield solver
    del hnn.SOLVERS["euler"]


def test_a_new_stepper_is_one_registration_and_the_generic_checks_find_its_properties(euler, spring):
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.7]], dtype=torch.float64)
    stats = {}
    traj = hnn.rollout(spring.dynamics, x0, [0.0, 0.1, 0.2], method="euler", dt=0.05, stats=stats)
    x = x0
    for _ in range(4):                                    # four Euler steps by hand
        x = x + 0.05 * spring.dynamics(x)
    torch.testing.assert_close(traj[:, -1], x, rtol=1e-15, atol=1e-15)
    assert stats == {"nfev": 4}
    assert_declared_order("euler")
    defect = symplectic_defect(_pendulum_field, torch.tensor(_PEND_XS[0], dtype=torch.float64), "euler", 0.3)
    assert defect > 1e-3, defect                            # not symplectic, as declared
    with pytest.raises(hnn.DivergenceError, match="euler .*diverged"):    # the driver's blow-up report
        hnn.rollout(lambda x: x ** 2, torch.tensor([[5.0, 0.0]]), [0.0, 1.0], method="euler", dt=0.01)
    with pytest.raises(ValueError, match="already registered"):
        hnn.register_solver(euler)


def test_the_declared_order_check_can_fail(euler):
    # declared order 2 for Euler: the generic check must refuse it
    hnn.SOLVERS["euler"] = dataclasses.replace(euler, order=2)
    with pytest.raises(AssertionError):
        assert_declared_order("euler")


# ---------------------------------------------------------------- time reversibility

@pytest.mark.parametrize("method, options, reversible", [
    # the midpoint map is symmetric only as far as its implicit equation is solved: at the default
    # tol 1e-12 a round trip of 200 steps misses by ~1e-10, so these solve to 1e-14
    ("leapfrog", {}, True), ("midpoint", {"tol": 1e-14}, True), ("yoshida4", {}, True),
    ("yoshida4", {"base": "midpoint", "tol": 1e-14}, True), ("rk4", {}, False)])
def test_forward_then_backward_returns_to_the_start(pend, method, options, reversible):
    x0 = torch.tensor([[1.0, 0.5], [2.0, -1.0], [-0.5, 1.5]], dtype=torch.float64)
    steps, dt = 100, 0.1
    t = np.linspace(0, steps * dt, 11)
    fwd = hnn.rollout(pend.dynamics, x0, t, method=method, dt=dt, **options)
    back = hnn.rollout(pend.dynamics, fwd[:, -1], t[::-1].copy(), method=method, dt=dt, **options)
    error = float((back[:, -1] - x0).abs().max())
    if reversible:
        assert error < 1e-12, error
    else:
        assert error > 1e-6, error       # RK4 is not symmetric: the round trip misses by its local errors


# ---------------------------------------------------------------- energy over many steps

def _energy_errors(system, method, x0, dt, steps, samples=201):
    t = np.linspace(0, steps * dt, samples)
    with torch.no_grad():
        traj = hnn.rollout(system.dynamics, x0, t, method=method, dt=dt)
    H = system.hamiltonian(traj)
    return (H - H[:, :1]).abs()                          # (batch, samples)


@pytest.mark.parametrize("steps", [1000, pytest.param(100_000, marks=pytest.mark.slow)])
def test_energy_error_is_bounded_for_symplectic_methods_and_drifts_for_rk4(pend, steps):
    # dt = 0.2 is coarse for the pendulum (small-oscillation omega = sqrt(6), omega dt = 0.49):
    # RK4 then loses ~2e-4 of the energy per step, a visible secular drift
    x0 = torch.tensor([[1.0, 0.5], [2.0, 0.0], [0.0, 2.7]], dtype=torch.float64)
    H0 = pend.hamiltonian(x0)[:, None]
    # empirical bounds with headroom: the order-2 methods' error is O((omega dt)^2) ~ 0.05 here
    bounds = {"leapfrog": 0.1, "midpoint": 0.1, "yoshida4": 0.01}
    for method, bound in bounds.items():
        err = _energy_errors(pend, method, x0, 0.2, steps) / H0
        half = err.shape[1] // 2
        assert err.max() < bound, (method, float(err.max()))
        # bounded, not growing: the second half is no worse than the first (1.5x for sampling)
        assert err[:, half:].max() <= 1.5 * err[:, :half].max(), method
    rk4 = _energy_errors(pend, "rk4", x0, 0.2, steps) / H0
    assert rk4[:, -1].max() > 0.1, float(rk4[:, -1].max())
    assert rk4[:, -1].max() > 3 * rk4[:, rk4.shape[1] // 4].max()     # secular: it keeps growing


@pytest.mark.parametrize("periods", [300, pytest.param(10_000, marks=pytest.mark.slow)])
def test_spring_long_horizon_energy_and_phase_errors_match_theory(spring, periods):
    # leapfrog on dq/dt = 2p, dp/dt = -2q at step h: the map has eigenvalues exp(+-i theta) with
    # cos(theta) = 1 - (omega h)^2 / 2, so its phase runs at theta/h instead of omega, and it
    # conserves q^2 + p^2 (1 - (omega h / 2)^2)^-1 exactly: the energy error stays below
    # (omega h / 2)^2 / (1 - (omega h / 2)^2) at every time
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64)
    T, samples = periods * math.pi, 400
    steps = samples * math.ceil(T / 0.1 / samples)          # a whole number of steps per sample
    h = T / steps                                            # ~0.1
    t = np.linspace(0, T, samples + 1)
    with torch.no_grad():
        traj = hnn.rollout(spring.dynamics, x0, t, method="leapfrog", dt=h)
    a = (SPRING_OMEGA * h / 2) ** 2
    rel = (spring.hamiltonian(traj) / spring.hamiltonian(x0)[:, None] - 1).abs()
    assert rel.max() <= a / (1 - a) * (1 + 1e-6), float(rel.max())
    assert rel.max() > 0.5 * a                            # the bound is sharp: the test can fail
    # position: from (1, 0) the map gives q_n = cos(n theta) exactly; the true q is cos(omega t)
    theta = math.acos(1 - (SPRING_OMEGA * h) ** 2 / 2)
    assert abs(float(traj[0, -1, 0]) - math.cos(steps * theta)) < 1e-8 * periods
    assert abs(steps * theta - SPRING_OMEGA * T) > 0.5     # the phase error is real (and predicted)


def test_midpoint_conserves_the_quadratic_spring_energy_to_rounding(spring):
    # the implicit midpoint rule preserves every quadratic invariant exactly
    x0 = torch.tensor([[1.0, 0.0], [0.3, -0.7]], dtype=torch.float64)
    with torch.no_grad():
        traj = hnn.rollout(spring.dynamics, x0, np.linspace(0, 200, 101), method="midpoint", dt=0.2)
    H = spring.hamiltonian(traj)
    assert (H - H[:, :1]).abs().max() < 1e-10


@pytest.mark.parametrize("p0, label", [(math.sqrt(PEND_SEPARATRIX_H) * (1 - 1e-4), "separatrix"), (3.0, "rotating")])
def test_pendulum_near_the_separatrix_and_over_the_top(pend, p0, label):
    x0 = torch.tensor([[0.0, p0]], dtype=torch.float64)
    t = np.linspace(0, 20, 201)
    ref = hnn.rollout(pend.dynamics, x0, t, scipy_method="DOP853", rtol=1e-12, atol=1e-12)
    H0 = float(pend.hamiltonian(x0))
    # measured: 3e-3 (leapfrog), 1.7e-3 (midpoint), 1.5e-5 (yoshida4) at dt = 0.05. Near the
    # separatrix that is enough to tip leapfrog over the top where the truth turns back: the
    # path is not comparable there, the energy is
    for method, dt, bound in (("leapfrog", 0.05, 1e-2), ("midpoint", 0.05, 1e-2), ("yoshida4", 0.05, 1e-4)):
        with torch.no_grad():
            traj = hnn.rollout(pend.dynamics, x0, t, method=method, dt=dt)
        dH = float((pend.hamiltonian(traj) - H0).abs().max()) / H0
        assert dH < bound, (label, method, dH)
        if label == "rotating":     # away from the separatrix the path itself stays close to DOP853's
            assert float((traj[:, :, 1] - ref[:, :, 1]).abs().max()) < 100 * bound, (method, label)
    if label == "rotating":
        assert float(traj[0, -1, 0]) > 2 * math.pi        # it went over the top, more than once


# ---------------------------------------------------------------- stability limits, non-convergence

@pytest.mark.parametrize("method, stable_dt, unstable_dt", [
    # spring omega = 2: leapfrog is stable for omega dt < 2, Yoshida's composition of it for
    # omega dt < ~1.57 (its substeps reach 1.70 dt), RK4 for omega dt < 2.83 (imaginary axis)
    ("leapfrog", 0.95, 1.05), ("yoshida4", 0.75, 0.85), ("rk4", 1.38, 1.45)])
def test_steps_past_the_stability_limit_are_reported_not_returned_as_nan(spring, method, stable_dt, unstable_dt):
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.0], [0.5, 0.5]], dtype=torch.float64)
    t = np.linspace(0, 1000 * unstable_dt, 101)
    with torch.no_grad():
        with warnings.catch_warnings():         # inside the limit: no StepSizeWarning (hnn.integrators.stability)
            warnings.simplefilter("error", StepSizeWarning)
            fine = hnn.rollout(spring.dynamics, x0, np.linspace(0, 1000 * stable_dt, 101), method=method,
                               dt=stable_dt)
        # near the limit the invariant ellipse is long: leapfrog's modified energy allows
        # excursions of a / (1 - a) = 9.3 at omega dt = 1.9 (a = (omega dt / 2)^2); bounded is the point
        assert spring.hamiltonian(fine).max() < 20
        # past it: warned before the rollout starts, stopped once the state leaves max_norm
        with pytest.raises(hnn.DivergenceError, match="diverged") as info, pytest.warns(StepSizeWarning, match=method):
            hnn.rollout(spring.dynamics, x0, t, method=method, dt=unstable_dt)
    assert info.value.trajectories == [0, 2]            # the resting row 1 never moves
    assert all(0 < s <= t[-1] for s in info.value.times)


def test_midpoint_non_convergence_is_reported(spring):
    # the fixed-point iteration contracts by omega dt / 2 per iteration: dt = 1.5 gives 1.5 > 1
    x0 = torch.tensor([[0.0, 0.0], [1.0, 0.0]], dtype=torch.float64)
    with pytest.raises(hnn.ConvergenceError, match="did not converge") as info:
        hnn.rollout(spring.dynamics, x0, np.linspace(0, 15, 11), method="midpoint", dt=1.5)
    assert info.value.trajectories == [1] and info.value.times == [1.5]
    assert isinstance(info.value, hnn.DivergenceError)
    stats = {}
    hnn.rollout(spring.dynamics, x0, np.linspace(0, 15, 11), method="midpoint", dt=0.5, stats=stats)
    assert stats["max_step_iterations"] < 100 and stats["nfev"] == stats["iterations"] + 1   # one Euler guess, then the last increments


@pytest.mark.parametrize("method, options, fewer", [("midpoint", {}, 0.5), ("yoshida4", {"base": "midpoint"}, 0.7)])
@pytest.mark.parametrize("field", ["pendulum", "hnn"])
def test_midpoint_extrapolated_guess_converges_to_the_old_guesss_result_in_fewer_iterations(pend, field, method,
                                                                                          options, fewer, monkeypatch):
    """The first iterate extrapolated from the last MIDPOINT_HISTORY increments (of the same
    substep, in yoshida4) reaches the same fixed point as the last increment alone (history 1,
    the midpoint rule's guess before) to the iteration's tolerance a step, in fewer iterations at
    a small step (at most half for the midpoint rule; yoshida4's substeps are larger and its
    middle one runs backwards)."""
    torch.manual_seed(0)
    model = hnn.build_model(2, 32).double()
    f = pend.dynamics if field == "pendulum" else model.time_derivative
    x0 = 1.5 * (2 * torch.rand(8, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64) - 1)
    t = np.linspace(0, 10, 11)
    runs = {}
    for history in (1, hnn.integrators.fixed_step.MIDPOINT_HISTORY):
        monkeypatch.setattr(hnn.integrators.fixed_step, "MIDPOINT_HISTORY", history)
        stats = {}
        runs[history] = hnn.rollout(f, x0, t, method=method, dt=0.01, stats=stats, **options), stats["iterations"]
    (old, old_iterations), (new, new_iterations) = runs[1], runs[hnn.integrators.fixed_step.MIDPOINT_HISTORY]
    # each solve's two results lie within about tol (1e-12, relative to max(|x|, 1)) of the fixed
    # point; 1000 steps (of three solves in yoshida4) carry the differences along
    torch.testing.assert_close(new, old, rtol=0, atol=3000 * 1e-12 * 1.5)
    assert new_iterations <= fewer * old_iterations, (new_iterations, old_iterations)


@pytest.mark.parametrize("method", hnn.integrators.SYMPLECTIC_METHODS)
def test_symplectic_methods_report_blow_ups_with_trajectory_and_time(method):
    # H = 10 (p^2 - q^2), separable as leapfrog needs: q' = 20 p, p' = 20 q. q + p grows like
    # exp(20 t) and passes 1e6 near t = 0.7; q - p decays. Rows 0 and 2 blow up, row 1 decays
    x0 = torch.tensor([[1.0, 1.0], [1.0, -1.0], [0.5, 0.5]], dtype=torch.float64)
    f = lambda x: 20 * x.flip(1)  # noqa: E731
    with pytest.raises(hnn.DivergenceError, match="diverged") as info:
        # to t = 1 only: rounding seeds the growing mode in row 1 too, and by t = 2 it has grown e^40-fold
        hnn.rollout(f, x0, np.linspace(0, 1, 21), method=method, dt=0.005)
    assert info.value.trajectories == [0, 2]
    assert all(0.65 < s < 0.8 for s in info.value.times), info.value.times


@pytest.mark.parametrize("method", hnn.integrators.SYMPLECTIC_METHODS)
def test_shapes_dtypes_and_default_dt(spring, method):
    x0 = torch.randn(5, 2)
    stats = {}
    out = hnn.rollout(spring.dynamics, x0, np.linspace(0, 1, 21), method=method, stats=stats)
    assert out.shape == (5, 21, 2) and out.dtype == torch.float32 and stats["nfev"] > 0
    torch.testing.assert_close(out[:, 0], x0)
    with pytest.raises(ValueError, match="positive finite dt"):
        hnn.rollout(spring.dynamics, x0, [0, 1], method=method, dt=0.0)


def test_leapfrog_rejects_odd_dimensions():
    with pytest.raises(ValueError, match="even dimension"):
        hnn.rollout(lambda x: -x, torch.zeros(1, 3), [0, 1], method="leapfrog")


# ---------------------------------------------------------------- float32 vs float64 tolerances

def test_tolerances_tighter_than_the_dtype_warn(spring):
    x32 = torch.tensor([[1.0, 0.0]])
    t = np.linspace(0, 1, 5)
    with pytest.warns(UserWarning, match="tighter than torch.float32"):
        hnn.rollout(spring.dynamics, x32, t, rtol=1e-9, atol=1e-9)
    with pytest.warns(UserWarning, match="tighter than torch.float32"):
        hnn.rollout(spring.dynamics, x32, t, method="dopri5", rtol=1e-9)
    with pytest.warns(UserWarning, match="below the machine epsilon"):
        hnn.rollout(spring.dynamics, x32, t, method="midpoint", dt=0.1, tol=1e-9)
    with warnings.catch_warnings():             # the same tolerances are fine in float64
        warnings.simplefilter("error")
        x64 = x32.double()
        hnn.rollout(spring.dynamics, x64, t, rtol=1e-9, atol=1e-9)
        hnn.rollout(spring.dynamics, x64, t, method="dopri5", rtol=1e-9)
        hnn.rollout(spring.dynamics, x64, t, method="midpoint", dt=0.1, tol=1e-9)
        hnn.rollout(spring.dynamics, x32, t, method="midpoint", dt=0.1)     # float32's default tol
