"""The discrete-gradient solver against truths: the defining identity of its discrete gradients,
the learned H constant along its rollout for random weights (where the midpoint's oscillates), its
order on the analytic pendulum, and clear errors where it cannot apply or does not converge."""
import numpy as np
import pytest
import torch

import hnn
from hnn.integrators.discrete_gradient import gonzalez
from hnn.interface import EnergyField


def _model(kind: str, seed: int = 0):
    torch.manual_seed(seed)
    return hnn.kinds.model_from_args({"kind": kind, "input_dim": 4, "hidden_dim": 16, "nonlinearity": "tanh",
                                      "field_type": "solenoidal", "dtype": "float64"})


def _grad(hamiltonian, x):
    x = x.clone().requires_grad_(True)
    return torch.autograd.grad(hamiltonian(x).sum(), x)[0]


@pytest.mark.parametrize("which", ["closed_form", "gonzalez"])
def test_a_discrete_gradient_is_exact_in_difference_and_the_gradient_on_the_diagonal(which):
    model = _model("hnn")
    dg = model.exact_discrete_gradient() if which == "closed_form" else (
        lambda a, b: gonzalez(model.hamiltonian, a, b))
    gen = torch.Generator().manual_seed(1)
    x0 = torch.randn(50, 4, dtype=torch.float64, generator=gen)
    for scale in (1.0, 1e-3, 1e-7):     # down to differences where a naive quotient cancels
        x1 = x0 + scale * torch.randn(50, 4, dtype=torch.float64, generator=gen)
        with torch.no_grad():
            g = dg(x0, x1)
            H0, H1 = model.hamiltonian(x0), model.hamiltonian(x1)
        # exact in exact arithmetic; in float64 the two sides differ by the rounding of H itself (dg evaluates H
        # in its own batch, which a BLAS kernel may sum in another order: a few eps of H's scale, the batch's
        # largest |H|, whatever the step, measured 1.9 eps here) and of the dot product g . dx (its terms' eps):
        # 8 eps of both, where the former fixed 1e-15 was 3.4 eps of this H's scale
        scale = torch.maximum(H0.abs(), H1.abs()).max() + (g * (x1 - x0)).abs().sum(1)
        gap = ((g * (x1 - x0)).sum(1) - (H1 - H0)).abs()
        assert (gap <= 8 * torch.finfo(torch.float64).eps * scale).all(), (gap / scale).max()
        torch.testing.assert_close(dg(x1, x0), g, rtol=1e-9, atol=1e-12)        # symmetric: order 2
    torch.testing.assert_close(dg(x0, x0), _grad(model.hamiltonian, x0), rtol=1e-12, atol=1e-14)


def _pendulum_plus(offset: float):
    """The pendulum's H plus a constant, which moves no state: its discrete gradient is the pendulum's."""
    pend = hnn.load_task("pend")
    return lambda x: pend.hamiltonian(x) + offset


@pytest.mark.parametrize("offset", [1e2, 1e4])
def test_gonzalez_in_float32_sees_no_large_constant_in_h_at_any_step(offset):
    gen = torch.Generator().manual_seed(0)
    x0 = torch.tensor([[2.5, 0.0], [0.5, 1.5], [1.0, 0.3], [-0.2, -0.9]])
    v = torch.randn(4, 2, generator=gen)
    for scale in (1e-1, 1e-2, 1e-3, 1e-4, 1e-5):
        x1 = x0 + scale * v
        with torch.no_grad():
            ours = gonzalez(_pendulum_plus(offset), x0, x1).double()
        truth = gonzalez(_pendulum_plus(0.0), x0.double(), x1.double())       # the same float32 points, in float64
        # a few float32 ulps of |grad H| <= 3.4 (2e-7 measured at most); the numerator as a difference of H's
        # float32 values rounds at eps |H| / |d|: 0.07 off at c = 100 and |d| = 1e-4, 7.8 at c = 1e4
        assert float((ours - truth).abs().max()) < 2e-6, (scale, float((ours - truth).abs().max()))


@pytest.mark.parametrize("offset", [0.0, 1e4])
@pytest.mark.parametrize("dt", [0.1, 1e-3])
def test_a_float32_rollout_converges_and_keeps_h_whatever_its_constant_and_step(offset, dt):
    pend = hnn.load_task("pend")
    x0 = torch.tensor([[2.5, 0.0], [0.5, 1.5], [1.0, 0.3], [-0.2, -0.9]], dtype=torch.float64)
    t = np.linspace(0.0, 400 * dt, 401)
    truth = hnn.rollout(EnergyField(pend.dynamics, pend.hamiltonian), x0, t, method="discrete_gradient")
    # where H's rounding moved a step's x1 by more than tol the fixed point was noise: it did not converge
    # at c = 100 or 1e4 at these steps; at c = 0 the difference of H's values is kept (it moves x1 by less)
    path = hnn.rollout(EnergyField(pend.dynamics, _pendulum_plus(offset)), x0.float(), t,
                       method="discrete_gradient").double()
    energy = float((pend.hamiltonian(path) - pend.hamiltonian(x0)[:, None]).abs().max())
    gap = float((path - truth).abs().max())
    # float32 rounding over 400 steps: measured at most 2.4e-5 in energy, 4.3e-4 and 5.9e-6 off the path
    # (dt = 0.1, 1e-3); 4x and more of margin
    assert energy < 1e-4, energy
    assert gap < (2e-3 if dt == 0.1 else 5e-5), gap

def test_the_closed_form_is_dgnets_chain_rule_not_gonzalez():
    # two different discrete gradients of one H: both exact in difference, distinct off the diagonal
    model = _model("hnn")
    x0 = torch.randn(8, 4, dtype=torch.float64)
    x1 = x0 + 0.5 * torch.randn(8, 4, dtype=torch.float64)
    with torch.no_grad():
        gap = (model.exact_discrete_gradient()(x0, x1) - gonzalez(model.hamiltonian, x0, x1)).abs().max()
    assert gap > 1e-4, gap


@pytest.mark.parametrize("kind", ["hnn", "separable", "mechanical"])
def test_the_learned_h_is_constant_along_a_discrete_gradient_rollout_for_random_weights(kind):
    model = _model(kind, seed=3)
    x0 = torch.randn(6, 4, dtype=torch.float64)
    t = np.linspace(0.0, 20.0, 201)
    H = {}
    for method in ("discrete_gradient", "midpoint"):
        traj = hnn.rollout(model, x0, t, method=method, dt=0.1)
        with torch.no_grad():
            H[method] = model.hamiltonian(traj.reshape(-1, 4)).reshape(6, -1)
    drift = {m: float((h - h[:, :1]).abs().max() / (1 + h.abs().max())) for m, h in H.items()}
    # the iteration is solved to tol = 1e-12 relative; the energy identity leaves ~ grad H . residual a step
    assert drift["discrete_gradient"] < 1e-11, drift
    assert drift["midpoint"] > 100 * drift["discrete_gradient"], drift      # a symplectic method oscillates


def test_a_true_h_is_kept_at_steps_where_the_midpoint_visibly_oscillates():
    pend = hnn.load_task("pend")
    field = EnergyField(pend.dynamics, pend.hamiltonian)
    x0 = torch.tensor([[2.5, 0.0], [0.5, 1.5]], dtype=torch.float64)
    t = np.linspace(0.0, 200.0, 401)        # 400 steps of 0.5, about a quarter of a small oscillation each
    dg = hnn.rollout(field, x0, t, method="discrete_gradient")
    mid = hnn.rollout(pend.dynamics, x0, t, method="midpoint")
    error = {name: float((pend.hamiltonian(tr) - pend.hamiltonian(x0)[:, None]).abs().max())
             for name, tr in (("dg", dg), ("midpoint", mid))}
    # each step keeps H to |grad-bar H| * (the solve's residual, tol = 1e-12 relative to max(|x|, 1)):
    # |grad H| <= 2 |p| + 3 <= 10 and |x| <= 4 here, so at most 400 * 4e-11 over the rollout (5.9e-11 measured)
    assert error["dg"] < 400 * 4e-11 and error["midpoint"] > 1e-3, error


def test_its_order_on_the_analytic_pendulum_is_the_declared_one():
    pend = hnn.load_task("pend")
    field = EnergyField(pend.dynamics, pend.hamiltonian)
    x0 = torch.tensor([[1.0, 0.5], [2.9, -0.3]], dtype=torch.float64)
    t = np.linspace(0.0, 2.0, 5)
    truth = hnn.rollout(pend.dynamics, x0, t, method="dop853", rtol=1e-13, atol=1e-13).numpy()
    dts = np.array([0.1, 0.05, 0.025, 0.0125])
    errors = [np.abs(hnn.rollout(field, x0, t, method="discrete_gradient", dt=dt).numpy() - truth).max()
              for dt in dts]
    slope = float(np.polyfit(np.log(dts), np.log(errors), 1)[0])
    assert abs(slope - hnn.get_solver("discrete_gradient").order) < 0.3, (slope, errors)


def test_declared_properties():
    solver = hnn.get_solver("discrete_gradient")
    assert (solver.order, solver.energy_preserving, solver.symplectic, solver.needs_hamiltonian) == (2, True, False,
                                                                                                     True)
    assert not any(s.energy_preserving for name, s in hnn.SOLVERS.items() if name != "discrete_gradient")


def test_a_step_too_long_for_the_iteration_is_a_convergence_error_naming_the_rows():
    spring = hnn.load_task("spring")
    field = EnergyField(spring.dynamics, spring.hamiltonian)
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.0]], dtype=torch.float64)
    # the iteration contracts by dt * |S grad^2 H| = 2 dt: it cannot converge at dt = 1.5 (the rest state can)
    with pytest.raises(hnn.ConvergenceError, match=r"did not converge .* 1 trajectories: #0 at t=1\.5.*reduce dt"):
        hnn.rollout(field, x0, [0.0, 1.5, 3.0], method="discrete_gradient")
    hnn.rollout(field, x0, [0.0, 1.5, 3.0], method="discrete_gradient", dt=0.1)      # converges at a short step


def test_a_field_without_its_h_or_not_of_it_is_refused_with_the_fix():
    spring = hnn.load_task("spring")
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    with pytest.raises(ValueError, match="needs the field's H.*carries none.*declares conservative"):
        hnn.rollout(spring.dynamics, x0, [0.0, 0.1], method="discrete_gradient")
    with pytest.raises(ValueError, match="needs the field's H"):
        hnn.rollout(_model("baseline"), x0.repeat(1, 2), [0.0, 0.1], method="discrete_gradient")
    # an H whose gradient flow is not the field (here twice as fast): another flow, refused
    wrong = EnergyField(lambda x: 2 * spring.dynamics(x), spring.hamiltonian)
    with pytest.raises(ValueError, match="not S grad H"):
        hnn.rollout(wrong, x0, [0.0, 0.1], method="discrete_gradient")


def test_a_differentiable_rollout_is_differentiable_in_the_weights():
    model = _model("hnn")
    x0 = torch.randn(3, 4, dtype=torch.float64)
    traj = hnn.rollout(model, x0, [0.0, 0.1, 0.2], method="discrete_gradient", differentiable=True)
    traj.pow(2).sum().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in model.parameters() if p.requires_grad)


def test_the_drift_study_finds_the_learned_h_kept_by_the_discrete_gradient_alone(tmp_path):
    from hnn_analysis.integrator_study import energy_drift

    results = energy_drift.main(["--steps", "50", "--dt", "0.3", "--train-steps", "30", "--out", str(tmp_path)])
    for kind, rows in results["rows"].items():
        assert set(rows) == set(energy_drift.METHODS[kind])
        # 1e-12 relative a solve, 50 steps: round-off, where every other method moves H by its truncation
        # error (a barely trained field is slow, so only 100x more here: RK4's was 1e-12 against 3e-15)
        assert rows["discrete_gradient"]["max"] < 1e-10
        assert all(r["max"] > 100 * rows["discrete_gradient"]["max"] for m, r in rows.items() if m != "discrete_gradient")
    assert results["rows"]["separable"]["leapfrog"]["field_calls_per_step"] == pytest.approx(1.0, abs=0.05)
    assert "| hnn | discrete_gradient |" in (tmp_path / "energy_drift.md").read_text()
