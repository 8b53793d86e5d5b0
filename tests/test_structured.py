"""The model ladder's structured kinds: a separable H (explicit leapfrog is symplectic for it) and
the dissipative split dx/dt = J grad H + grad D, checked against analytic truths."""
import json
import subprocess
import sys

import numpy as np
import pytest
import torch

import hnn

OMEGA = torch.tensor([[0.0, 1.0], [-1.0, 0.0]], dtype=torch.float64)


def _grad(f, x):
    x = x.detach().clone().requires_grad_(True)
    return torch.autograd.grad(f(x).sum(), x, create_graph=True)[0]


def _laplacian(f, x):
    x = x.detach().clone().requires_grad_(True)
    g = torch.autograd.grad(f(x).sum(), x, create_graph=True)[0]
    return sum(torch.autograd.grad(g[:, i].sum(), x, retain_graph=True)[0][:, i] for i in range(x.shape[1]))


def _step_jacobian(f, x0, method, dt=0.1):
    """The (2, 2) Jacobian of one ``method`` step of ``dx/dt = f(x)`` at the state ``x0`` ``(2,)``."""
    def step(x):
        return hnn.rollout(f, x[None], [0.0, dt], method=method, dt=dt, max_norm=None, differentiable=True)[0, -1]
    return torch.autograd.functional.jacobian(step, x0)


# ---------------------------------------------------------------------------- SeparableHNN

def test_separable_field_is_hamiltons_equations_of_t_plus_v():
    torch.manual_seed(0)
    model = hnn.SeparableHNN(4, 16).double()
    x = torch.randn(7, 4, dtype=torch.float64)
    H = model.hamiltonian(x)
    assert H.shape == (7,)
    torch.testing.assert_close(H, model.kinetic(x[:, 2:]) + model.potential(x[:, :2]))
    dH = _grad(model.hamiltonian, x)
    expected = torch.cat([dH[:, 2:], -dH[:, :2]], dim=1)            # J grad H, x = [q, p]
    torch.testing.assert_close(model.time_derivative(x), expected, rtol=1e-10, atol=1e-12)
    with torch.no_grad():                                          # evaluation: no graph, same numbers
        torch.testing.assert_close(model.time_derivative(x), expected.detach(), rtol=1e-10, atol=1e-12)
    # dq/dt reads p alone and dp/dt q alone: the structure explicit leapfrog needs
    moved_q = x.clone()
    moved_q[:, :2] += 1.0
    torch.testing.assert_close(model.time_derivative(moved_q)[:, :2], model.time_derivative(x)[:, :2])


@pytest.mark.parametrize("method", ["leapfrog", "yoshida4"])
def test_explicit_symplectic_methods_are_symplectic_for_a_learned_separable_h(method):
    torch.manual_seed(1)
    separable = hnn.SeparableHNN(2, 32).double()
    general = hnn.build_model(2, 32).double()
    x0 = torch.tensor([0.7, -0.4], dtype=torch.float64)
    J = _step_jacobian(separable.time_derivative, x0, method)
    torch.testing.assert_close(J.T @ OMEGA @ J, OMEGA, rtol=0, atol=1e-12)
    # the same explicit method on the general HNN's (non-separable) learned H is not symplectic
    J = _step_jacobian(general.time_derivative, x0, method)
    assert (J.T @ OMEGA @ J - OMEGA).abs().max() > 1e-8


def test_leapfrog_keeps_a_learned_separable_h_bounded():
    torch.manual_seed(2)
    model = hnn.SeparableHNN(2, 32).double()
    x0 = torch.tensor([[0.5, 0.0]], dtype=torch.float64)
    with torch.no_grad():
        traj = hnn.rollout(model.time_derivative, x0, np.linspace(0, 200, 2001), method="leapfrog", dt=0.05)
        H = model.hamiltonian(traj[0])
    # a symplectic method conserves a modified H: the error oscillates at O(dt^2), it does not grow
    first, last = (H[:1000] - H[0]).abs().max(), (H[1000:] - H[0]).abs().max()
    assert last < 2 * first + 1e-12 and first < 1e-3


# ---------------------------------------------------------------------------- DissipativeHNN

def test_dissipative_field_is_j_grad_h_plus_grad_d():
    torch.manual_seed(0)
    model = hnn.DissipativeHNN(2, 16).double()
    x = torch.randn(9, 2, dtype=torch.float64)
    dH, dD = _grad(model.hamiltonian, x), _grad(model.dissipation, x)
    expected = torch.cat([dH[:, 1:], -dH[:, :1]], dim=1) + dD
    torch.testing.assert_close(model.time_derivative(x), expected, rtol=1e-10, atol=1e-12)


def test_dissipative_split_of_a_damped_oscillator():
    """dq/dt = p, dp/dt = -q - gamma p is J grad H + grad D with H = (q^2 + p^2)/2 and D = -gamma p^2/2.

    The split is unique only up to a harmonic pair (J grad phi = grad psi), but the Laplacians are
    fixed by the field (lap H = -rot f = 2, lap D = div f = -gamma): those are what a learned split
    must get right. Measured at seed 0: lap H 2.006 +/- 0.026, lap D -0.501 +/- 0.006 over the
    test states; the 10% band holds that with a wide margin.
    """
    gamma = 0.5
    torch.manual_seed(0)
    x = torch.rand(1200, 2) * 3 - 1.5

    def field(x):
        return torch.cat([x[:, 1:], -x[:, :1] - gamma * x[:, 1:]], dim=1)

    model = hnn.DissipativeHNN(2, 64)
    hnn.train(model, x[:1000], field(x[:1000]), x[1000:], field(x[1000:]), total_steps=1500, weight_decay=0.0)
    model = model.double()
    test = torch.rand(200, 2, dtype=torch.float64) * 2 - 1
    with torch.no_grad():
        assert (model.time_derivative(test) - field(test)).norm(dim=1).mean() < 0.02
    assert _laplacian(model.hamiltonian, test).mean().item() == pytest.approx(2.0, rel=0.10)
    assert _laplacian(model.dissipation, test).mean().item() == pytest.approx(-gamma, rel=0.10)
    # the energy the learned H assigns falls along the true flow, as friction makes it
    with torch.no_grad():
        traj = hnn.rollout(field, torch.tensor([[1.0, 0.0]], dtype=torch.float64), np.linspace(0, 10, 50))
        H = model.hamiltonian(traj[0])
    assert H[-1] < H[0] - 0.3


# ---------------------------------------------------------------------------- runs and flags

@pytest.mark.parametrize("kind, cls", [("separable", hnn.SeparableHNN), ("dissipative", hnn.DissipativeHNN)])
def test_model_flag_trains_saves_and_reloads_each_kind(kind, cls, tmp_path):
    run = hnn.load_task("spring", "train").main(["--model", kind, "--total_steps", "3", "--hidden_dim", "8",
                                                  "--save_dir", str(tmp_path)])
    assert run.name.startswith(f"spring-{kind}-seed0-")
    assert json.loads((run / "args.json").read_text())["model"] == kind
    model, args, metrics = hnn.load_run(run)
    assert type(model) is cls and args["model"] == kind and np.isfinite(metrics["test_loss"])
    spring = hnn.load_task("spring")
    result = hnn.evaluate_energy(spring, {kind: model}, hnn.tasks.get_protocol("spring", "corrected"))
    assert np.isfinite(result[kind]["mse"])


def test_bad_input():
    for cls in (hnn.SeparableHNN, hnn.DissipativeHNN):
        with pytest.raises(ValueError, match="even width"):
            cls(3)
    with pytest.raises(ValueError, match=r"expected x of shape \(batch, 4\)"):
        hnn.SeparableHNN(4, 8).time_derivative(torch.zeros(2, 3))
    done = subprocess.run([sys.executable, "experiment-spring/train.py", "--model", "sideways"],
                          cwd=hnn.tasks.repo_root(), capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.splitlines()[-1].startswith("error: argument --model")
    assert "Traceback" not in done.stderr
    with pytest.raises(SystemExit):
        hnn.cli.parse(hnn.load_task("spring", "train").Config, ["--model", "separable", "--baseline"])
