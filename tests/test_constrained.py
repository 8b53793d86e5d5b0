"""The constrained kinds (CHNN, CLNN) against truths: the projection is a projection, the flow keeps
its constraints and (CHNN) its H, with the chain's true potential and masses both fields are the
chain's own dynamics in Cartesian coordinates, the fast closed form is the dense P J grad H, its
gradients match finite differences, and bad input is one clear error."""
import numpy as np
import pytest
import torch

import hnn
from hnn.models.constrained import ConstrainedHNN, ConstrainedLNN, ConstraintGraph

data = hnn.load_task("chain")


class _TrueChain:
    """Plugs the chain's true V(x) = g sum_k m_k y_k and masses into a constrained model."""

    @staticmethod
    def make(cls, chain):
        class WithTrueV(cls):
            def potential(self, x):
                return chain.g * (x.view(len(x), chain.n, 2)[..., 1] * self.masses()).sum(1)

            def potential_gradient(self, x):
                grad = torch.zeros(len(x), chain.n, 2, dtype=x.dtype)
                grad[..., 1] = chain.g * self.masses()
                return grad.flatten(1)
        model = WithTrueV(chain.constraint_graph(), hidden_dim=8).double()
        with torch.no_grad():
            model.log_mass.copy_(torch.log(torch.tensor(chain.masses, dtype=torch.float64)))
        return model


def _states(chain, count: int, seed: int = 0) -> torch.Tensor:
    """Observed angle states of the chain on CHNN's start law, ``(count, 2N)``."""
    return data.sample_chnn_starts(chain, count, torch.Generator().manual_seed(seed))


def _random_model(cls, chain, seed: int = 0, width: int = 16):
    torch.manual_seed(seed)
    model = cls(chain.constraint_graph(), hidden_dim=width).double()
    with torch.no_grad():
        model.log_mass.normal_(0.0, 0.3)
    return model


@pytest.mark.parametrize("n", [1, 2, 5])
def test_with_the_true_potential_and_masses_both_fields_are_the_chains_dynamics(n):
    chain = data.chnn_chain(n)
    z = _states(chain, 64)
    cart, rates = torch.func.jvp(chain.to_cartesian, (z,), (chain.observed_dynamics(z),))
    for cls in (ConstrainedHNN, ConstrainedLNN):
        model = _TrueChain.make(cls, chain)
        with torch.no_grad():
            field = model.observed_field(model.coordinates if cls is ConstrainedLNN else "cartesian")(cart)
        torch.testing.assert_close(field, rates, rtol=1e-9, atol=1e-9 * rates.abs().max().item())


@pytest.mark.parametrize("n", [1, 2, 5])
def test_the_projection_is_a_projection_and_the_field_is_its_dense_form(n):
    chain = data.chnn_chain(n)
    model = _random_model(ConstrainedHNN, chain, seed=n)
    z = model.state_from(chain.to_cartesian(_states(chain, 16, seed=1)), "cartesian")
    # also off the constraints: P, D^T z' = 0 and dH/dt = 0 are identities of the algebra
    z = torch.cat([z, z + 0.05 * torch.randn(z.shape, generator=torch.Generator().manual_seed(2),
                                             dtype=torch.float64)]).requires_grad_(True)
    P = model.projection(z)
    torch.testing.assert_close(P @ P, P, rtol=1e-9, atol=1e-9)
    grad_h = torch.autograd.grad(model.hamiltonian(z).sum(), z)[0]
    j_grad = torch.cat([grad_h[:, model.nd:], -grad_h[:, :model.nd]], dim=1)
    dz = model.time_derivative(z)
    torch.testing.assert_close(dz, (P @ j_grad[..., None])[..., 0], rtol=1e-9, atol=1e-9)
    # the closed-form Jacobian is the Jacobian of the constraints
    auto = torch.func.vmap(torch.func.jacrev(lambda row: model.constraints(row[None])[0]))(z.detach())
    torch.testing.assert_close(model.constraint_jacobian(z.detach()), auto.transpose(1, 2), rtol=1e-10, atol=1e-10)
    # constraints and their velocity forms are invariants: D^T z' = 0; the H of random weights too
    scale = dz.norm(dim=1, keepdim=True) * auto.norm(dim=(1, 2))[:, None]
    assert ((model.constraint_jacobian(z.detach()).transpose(1, 2) @ dz.detach()[..., None])[..., 0].abs()
            < 1e-11 * scale).all()
    assert ((grad_h * dz).sum(1).abs() < 1e-11 * (grad_h.norm(dim=1) * dz.norm(dim=1))).all()


@pytest.mark.parametrize("cls", [ConstrainedHNN, ConstrainedLNN])
def test_the_constraint_rates_vanish_along_the_field(cls):
    """d/dt [phi, psi] = D^T z' = 0 on the constraints, for random weights (the CLNN by construction of
    x'': its psi' = 0 where psi = 0)."""
    chain = data.chnn_chain(3)
    model = _random_model(cls, chain, seed=4)
    z = model.state_from(chain.to_cartesian(_states(chain, 32, seed=3)), "cartesian")
    with torch.no_grad():
        dz = model.time_derivative(z)
    _, rates = torch.func.jvp(model.constraints, (z,), (dz,))
    assert rates.abs().max() < 1e-10 * (1 + dz.abs().max())


@pytest.mark.parametrize("cls", [ConstrainedHNN, ConstrainedLNN])
def test_a_long_float64_rollout_keeps_the_constraints_to_round_off(cls):
    chain = data.chnn_chain(2)
    model = _random_model(cls, chain, seed=5)
    z0 = chain.to_cartesian(_states(chain, 8, seed=6))
    path = hnn.objectives.trajectory.rollout_observed(model, z0, np.linspace(0.0, 5.0, 51), "cartesian", method="dop853",
                                           rtol=1e-12, atol=1e-12)
    off = model.violation(path.reshape(-1, path.shape[-1]), "cartesian")
    assert off.max() < 1e-8, float(off.max())
    if cls is ConstrainedHNN:
        h = model.hamiltonian(model.state_from_observed(path.reshape(-1, path.shape[-1]))).reshape(8, -1)
        assert (h - h[:, :1]).abs().max() < 1e-8 * (1 + h.abs().max())


@pytest.mark.parametrize("cls", [ConstrainedHNN, ConstrainedLNN])
def test_the_field_and_its_parameter_gradients_match_finite_differences(cls):
    """Through the projection's solves and the closed-form grad V: in the state, and in every weight
    and log-mass (what training through RK4 differentiates)."""
    chain = data.chnn_chain(2)
    model = _random_model(cls, chain, seed=7, width=4)
    z = chain.to_cartesian(_states(chain, 3, seed=8))
    z = (z if cls is ConstrainedLNN else model.state_from_observed(z)).detach().requires_grad_(True)
    assert torch.autograd.gradcheck(model.time_derivative, (z,), eps=1e-6, atol=1e-6)
    field = _Field(model)
    names, values = zip(*((name, p.detach().requires_grad_(True)) for name, p in field.named_parameters()))
    assert torch.autograd.gradcheck(
        lambda *v: torch.func.functional_call(field, dict(zip(names, v)), (z.detach(),)), values,
        eps=1e-6, atol=1e-6)


class _Field(torch.nn.Module):
    """A model's time_derivative as a forward (torch.func.functional_call calls forward)."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, z):
        return self.model.time_derivative(z)


def test_the_chain_maps_angles_to_cartesian_and_back():
    for n in (1, 2, 5):
        chain = data.chnn_chain(n)
        z = _states(chain, 20, seed=n)
        cart = chain.to_cartesian(z)
        assert cart.shape == (20, 4 * n)
        back = chain.from_flat_cartesian(cart)
        # angles come back in (-pi, pi]
        torch.testing.assert_close(torch.remainder(back - z + np.pi, 2 * np.pi) - np.pi, torch.zeros_like(z),
                                   rtol=0, atol=1e-12)
        torch.testing.assert_close(chain.to_cartesian(back), cart, rtol=1e-12, atol=1e-12)
        graph_model = ConstrainedLNN(chain.constraint_graph(), hidden_dim=4).double()
        assert graph_model.violation(cart).max() < 1e-12


def test_the_cartesian_dataset_is_the_same_paths():
    chain = data.chnn_chain(2)
    z = _states(chain, 10)
    found = {"x": z.numpy(), "dxdt": chain.observed_dynamics(z).numpy(), "test_x": z[:3].numpy(),
             "test_dxdt": chain.observed_dynamics(z[:3]).numpy(), "state": "velocity"}
    cart = data.cartesian_dataset(chain, found)
    assert cart["state"] == "cartesian" and cart["x"].shape == (10, 8)
    # d/dt of the Cartesian states by finite differences of the true path
    ahead, behind = (data.trajectories(chain, z, [0.0, h], rtol=1e-13, atol=1e-13)[:, 1] for h in (1e-4, -1e-4))
    rates = (chain.to_cartesian(ahead) - chain.to_cartesian(behind)) / 2e-4
    np.testing.assert_allclose(cart["dxdt"], rates.numpy(), rtol=1e-6, atol=1e-5)
    assert data.observed_coordinates("constrained") == "cartesian"
    assert data.observed_coordinates("mechanical") == data.observed_coordinates("hnn") == "velocity"


@pytest.mark.parametrize("make, message", [
    (lambda: ConstraintGraph(2, 2, links=((0, 2, 1.0),)), "names body 2, out of range for 2 bodies"),
    (lambda: ConstraintGraph(2, 2, links=((0, 1, 0.0),)), "link 0-1 has length 0.0"),
    (lambda: ConstraintGraph(2, 2, tethers=((0, (0.0, 0.0), -1.0),)), "tether of body 0 has length -1.0"),
    (lambda: ConstraintGraph(2, 2, tethers=((-1, (0.0, 0.0), 1.0),)), "names body -1"),
    (lambda: ConstraintGraph(2, 2, tethers=((0, (0.0,), 1.0),)), "fixed point must be 2 finite coordinates"),
    (lambda: ConstraintGraph(2, 2, links=((1, 1, 1.0),)), "joins body 1 to itself"),
    (lambda: ConstraintGraph(0), "bodies >= 1"),
])
def test_a_bad_graph_is_one_clear_error(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_state_off_the_constraints_is_one_clear_error():
    chain = data.chnn_chain(2)
    model = _random_model(ConstrainedHNN, chain)
    cart = chain.to_cartesian(_states(chain, 4))
    model.state_from(cart, "cartesian")
    off = cart.clone()
    off[2, 0] += 0.1                                # bob 0 moved 10 cm off its rod
    with pytest.raises(ValueError, match="state row 2 is off the constraints by .*project them first"):
        model.state_from(off, "cartesian")
    with pytest.raises(ValueError, match=r"shape \(batch, 8\)"):
        model.time_derivative(cart[:, :4])
    with pytest.raises(ValueError, match="needs the task's constraint graph"):
        hnn.kinds.model_from_args({"kind": "constrained", "hidden_dim": 8, "nonlinearity": "tanh"})


def test_a_saved_run_rebuilds_its_graph(tmp_path):
    config = hnn.tasks.task_config("chain", {"model": "constrained", "bobs": 2, "n_train": 4, "n_test": 2,
                                             "hidden_dim": 8, "total_steps": 2, "save_dir": str(tmp_path)})
    run = hnn.run_experiment(config)
    model, saved, metrics = hnn.load_run(run)
    assert isinstance(model, ConstrainedHNN) and model.graph == data.chnn_chain(2).constraint_graph()
    assert saved["constraints"]["links"] == [[0, 1, data.chnn_chain(2).lengths[1]]]
    assert np.isfinite(metrics["test_loss"])
