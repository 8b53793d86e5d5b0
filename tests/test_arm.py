"""The two-link arm task (experiment-arm) against independent truths, and the mechanical kind on it."""
import math

import numpy as np
import pytest
import torch

import hnn

data = hnn.load_task("arm")


def _states(arm, count=12, seed=0):
    return data.sample_states(arm, count, torch.Generator().manual_seed(seed))


def test_true_arm_conserves_energy():
    arm = data.Arm((1.3, 0.7), (0.9, 1.2))
    x0 = _states(arm)
    t = 0.03 * np.arange(101)
    xs = hnn.rollout(arm.dynamics, x0, t, method="solve_ivp", scipy_method="DOP853", rtol=1e-12, atol=1e-12)
    H = arm.hamiltonian(xs.reshape(-1, 4)).reshape(len(x0), -1)
    assert xs.dtype == torch.float64
    assert ((H - H[:, :1]).abs() / H.abs().max(1, keepdim=True).values).max() < 1e-9
    # the motion is not trivial: the elbow swings and kinetic energy is exchanged with potential
    assert (xs[:, :, 1].max(1).values - xs[:, :, 1].min(1).values).median() > 0.5


def test_field_is_hamiltons_equations_of_h():
    arm = data.Arm((1.3, 0.7), (0.9, 1.2), g=3.7)
    x = _states(arm).requires_grad_(True)
    dH = torch.autograd.grad(arm.hamiltonian(x).sum(), x)[0]
    torch.testing.assert_close(arm.dynamics(x), torch.cat([dH[:, 2:], -dH[:, :2]], dim=1), rtol=0, atol=1e-12)


def test_mass_matrix_is_the_rods_kinetic_energy():
    """1/2 qdot^T M qdot from M's closed form equals T summed rod by rod from Cartesian velocities."""
    arm = data.Arm((1.3, 0.7), (0.9, 1.2))
    z = arm.velocities(_states(arm, 20))
    q, v = z[:, :2], z[:, 2:]
    kinetic = 0.5 * (v[:, None, :] @ arm.mass_matrix(q) @ v[:, :, None])[:, 0, 0]
    torch.testing.assert_close(kinetic, arm.rod_kinetic_energy(z), rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(arm.momenta(z), _states(arm, 20))


def test_a_massless_forearm_leaves_a_physical_pendulum():
    """m_2 -> 0: the upper arm swings as a uniform rod, I = m l^2 / 3 about the shoulder, torque m g l/2 sin q."""
    m, length, g = 1.4, 0.8, 9.81
    arm = data.Arm((m, 1e-12), (length, 1.0), g)
    x = torch.tensor([[0.7, 0.3, 0.5, 0.0], [-2.0, 1.0, -1.1, 0.0]], dtype=torch.float64)
    dx = arm.dynamics(x)
    torch.testing.assert_close(dx[:, 2], -m * g * length / 2 * torch.sin(x[:, 0]), rtol=1e-9, atol=1e-9)
    # qdot_1 = p_1 / I when the forearm's momentum p_2 is 0 and it carries no inertia of its own
    torch.testing.assert_close(dx[:, 0], x[:, 2] / (m * length ** 2 / 3), rtol=1e-6, atol=1e-9)


def test_mass_matrix_varies_strongly_with_the_elbow():
    arm = data.Arm()
    q = torch.tensor([[0.0, 0.0], [0.0, math.pi]], dtype=torch.float64)
    inverse = torch.linalg.inv(arm.mass_matrix(q))
    assert arm.mass_matrix(q)[0, 0, 0] / arm.mass_matrix(q)[1, 0, 0] == pytest.approx(4.0)
    assert inverse[0, 1, 1] / inverse[1, 1, 1] == pytest.approx(4.0)
    assert (torch.linalg.eigvalsh(arm.mass_matrix(_states(arm, 100)[:, :2])) > 0).all()


def test_dataset_is_the_true_field_at_its_states():
    ds = data.get_dataset(seed=3, n_train=50, n_test=20, n_rollouts=4)
    arm = data.Arm()
    assert ds["x"].shape == (50, 4) and ds["test_x"].shape == (20, 4) and ds["rollout_x0"].shape == (4, 4)
    np.testing.assert_allclose(ds["dxdt"], arm.dynamics(torch.tensor(ds["x"], dtype=torch.float64)).numpy(),
                               rtol=1e-4, atol=1e-4)   # float32 states and targets
    assert not np.allclose(ds["x"][:20], ds["test_x"])   # train and test are separate draws
    q = ds["x"][:, :2]
    assert q.min() >= -math.pi and q.max() <= math.pi


class _TrueMechanical(hnn.MechanicalHNN):
    """The mechanical HNN with the arm's M^-1 and V in place of its networks."""

    def __init__(self, arm):
        super().__init__(4, 8, eps=0.0)
        self.arm = arm

    def potential_and_factor(self, q):
        return self.arm.potential(q), torch.linalg.cholesky(torch.linalg.inv(self.arm.mass_matrix(q)))


def test_mechanical_hnn_with_the_true_m_and_v_is_the_true_field():
    arm = data.Arm((1.3, 0.7), (0.9, 1.2))
    model = _TrueMechanical(arm).double()
    x = _states(arm, 9)
    torch.testing.assert_close(model.time_derivative(x), arm.dynamics(x), rtol=1e-10, atol=1e-10)


def test_bad_input_is_refused_with_the_fix():
    with pytest.raises(ValueError, match="2 masses and 2 lengths"):
        data.Arm((1.0,), (1.0,))
    with pytest.raises(ValueError, match="positive"):
        data.Arm((1.0, 0.0))
    with pytest.raises(ValueError, match="shape \\(batch, 4\\)"):
        data.Arm().dynamics(torch.zeros(3, 6))
    with pytest.raises(ValueError, match="n_train must be a positive integer"):
        data.get_dataset(n_train=0)
    with pytest.raises(ValueError, match="input_dim=6"):
        hnn.tasks.task_config("arm", {"input_dim": 6})


def _small_run(kind, seed, ds):
    torch.manual_seed(seed)
    model = hnn.MODEL_KINDS[kind].build(hnn.kinds.ModelSpec(kind, input_dim=4, hidden_dim=64, periodic=True))
    hnn.train(model, ds["x"], ds["dxdt"], total_steps=500, learn_rate=3e-3, weight_decay=0.0, seed=seed)
    x, y = torch.tensor(ds["test_x"]), torch.tensor(ds["test_dxdt"])
    with torch.no_grad():
        return model, float((model.time_derivative(x) - y).norm() / y.norm())


def test_mechanical_kind_learns_the_arms_mass_matrix_and_beats_the_hnn_at_equal_budget():
    """Fixed-seed regression, 500 full-batch steps on 400 states, width 64: measured field errors
    0.039-0.040 (mechanical) against 0.25-0.27 (hnn) over seeds 0, 1, 2 (data and init); the bounds
    leave 2x. Fails where the mechanical model's M^-1 collapses, as issue 32 reported on another scene."""
    ds = data.get_dataset(seed=0, n_train=400, n_test=400)
    mechanical, field = _small_run("mechanical", 0, ds)
    _, hnn_field = _small_run("hnn", 0, ds)
    assert field < 0.08 and field < hnn_field / 3
    q = torch.tensor(ds["test_x"][:, :2])
    learned = mechanical.inverse_mass(q).detach().double()
    true = torch.linalg.inv(data.Arm().mass_matrix(q.double()))
    assert (learned - true).norm() / true.norm() < 0.45        # measured 0.21-0.23 over seeds 0, 1, 2
    # not collapsed in any direction: its smallest eigenvalue tracks the truth's everywhere
    assert (torch.linalg.eigvalsh(learned)[:, 0] / torch.linalg.eigvalsh(true)[:, 0]).min() > 0.3
