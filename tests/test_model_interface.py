"""The declared model interface (hnn.Model): every registered kind declares what it reads and what
it conserves, and the declarations hold against the physics: a conservative kind's flow keeps its
own H (grad H . dx/dt = 0 for random weights), a separable kind's halves are its whole field, a
kind that maps observed coordinates maps them back exactly, and a pair that does not fit is one
clear error. Consumers read the declarations: rollout, the objectives and the energy protocol."""
import numpy as np
import pytest
import torch

import hnn
from hnn.interface import SplitField


def _args(kind: str) -> dict:
    pixel = hnn.MODEL_KINDS[kind].family == "pixel"
    # a body tethered to the origin in 2 dimensions: the width-4 state of the Cartesian kinds
    tether = {"bodies": 1, "dim": 2, "tethers": [[0, [0.0, 0.0], 1.0]], "links": []}
    return {"kind": kind, "input_dim": 16 if pixel else 4, "latent_dim": 2, "hidden_dim": 16,
            "nonlinearity": "tanh", "field_type": "solenoidal", "periodic": False, "dtype": "float64",
            "constraints": tether, "bodies": {"count": 2, "dim": 1}}     # the pair kind's: two bodies on a line


def _state_width(model) -> int:
    return model.latent_dim if isinstance(model, hnn.PixelHNN) else model.input_dim


@pytest.mark.parametrize("kind", sorted(hnn.MODEL_KINDS))
def test_every_kind_is_a_declared_model_whose_declarations_hold(kind):
    row = hnn.MODEL_KINDS[kind]
    torch.manual_seed(0)
    model = hnn.kinds.model_from_args(_args(kind))
    assert isinstance(model, hnn.Model) and isinstance(model, row.model)
    # the row reads the class, the instance agrees with it: one declaration
    assert (model.conservative, model.separable, model.dissipative) == (row.conservative, row.separable,
                                                                        row.dissipative)
    assert row.coordinates in hnn.interface.COORDINATES
    x = torch.randn(32, _state_width(model), dtype=torch.float64, requires_grad=True)
    if row.steps:
        # a learned map: no field, its step and inverse instead (tests/test_maps.py checks their physics)
        assert isinstance(model.field, hnn.interface.StepMap) and not (row.conservative or row.separable)
        with pytest.raises(TypeError, match="no field dx/dt.*hnn.rollout"):
            model.time_derivative(x)
        with torch.no_grad():
            torch.testing.assert_close(model.inverse(model.step(x)), x, rtol=1e-10, atol=1e-10)
        return
    dxdt = model.time_derivative(x).detach()
    assert dxdt.shape == x.shape and torch.isfinite(dxdt).all()
    if row.conservative:
        # dH/dt = grad H . dx/dt = 0 along the model's own field, for any weights
        grad = torch.autograd.grad(model.hamiltonian(x).sum(), x)[0]
        rate = (grad * dxdt).sum(1)
        assert rate.abs().max() < 1e-10 * (1 + grad.norm(dim=1) * dxdt.norm(dim=1)).max()
    else:
        if kind in ("baseline", "second_order", "pixel-baseline"):
            with pytest.raises((TypeError, ValueError), match="Hamiltonian"):
                model.hamiltonian(x)
    if row.separable:
        field = model.field
        assert isinstance(field, SplitField)
        n = x.shape[1] // 2
        with torch.no_grad():
            halves = torch.cat([field.kinetic_gradient(x[:, n:]), -field.potential_gradient(x[:, :n])], 1)
            torch.testing.assert_close(halves, model.time_derivative(x), rtol=1e-12, atol=1e-12)
    else:
        assert not isinstance(model.field, SplitField)


def test_a_dissipative_kind_loses_its_h():
    torch.manual_seed(1)
    model = hnn.kinds.model_from_args(_args("dissipative"))
    x = torch.randn(64, 4, dtype=torch.float64, requires_grad=True)
    dxdt = model.time_derivative(x).detach()
    grad_h = torch.autograd.grad(model.hamiltonian(x).sum(), x)[0]
    grad_d = torch.autograd.grad(model.dissipation(x).sum(), x)[0]
    # dH/dt = grad H . grad D: the dissipative part alone changes H
    torch.testing.assert_close((grad_h * dxdt).sum(1), (grad_h * grad_d).sum(1), rtol=1e-10, atol=1e-12)
    assert (grad_h * grad_d).sum(1).abs().max() > 1e-6


def test_the_mechanical_kind_maps_observed_velocities_both_ways():
    torch.manual_seed(2)
    model = hnn.kinds.model_from_args(_args("mechanical"))
    z = torch.randn(10, 4, dtype=torch.float64)
    assert model.relation("velocity") == "mapped" and model.relation("canonical") == "own"
    x = model.state_from(z, "velocity")
    torch.testing.assert_close(model.observed_from(x, "velocity"), z, rtol=1e-10, atol=1e-10)
    assert model.state_from(z, "canonical") is z
    # d/dt of the observed state is the map's derivative along the flow: finite differences of a rollout
    h = 1e-4
    ahead = hnn.objectives.trajectory.rollout_observed(model, z, [0.0, h], "velocity", method="dop853", rtol=1e-12,
                                            atol=1e-12)[:, 1]
    behind = hnn.objectives.trajectory.rollout_observed(model, z, [0.0, -h], "velocity", method="dop853", rtol=1e-12,
                                             atol=1e-12)[:, 1]
    with torch.no_grad():
        torch.testing.assert_close(model.observed_field("velocity")(z), (ahead - behind) / (2 * h), rtol=1e-6,
                                   atol=1e-6)


@pytest.mark.parametrize("kind, observed, fits", [
    ("second_order", "canonical", False), ("second_order", "velocity", True), ("mechanical", "cartesian", False),
    ("hnn", "velocity", True), ("baseline", "cartesian", True), ("separable", "latent", False)])
def test_a_kind_reads_what_it_declares_and_refuses_the_rest_with_the_fix(kind, observed, fits):
    model = hnn.kinds.model_from_args(_args(kind))
    assert hnn.MODEL_KINDS[kind].reads(observed) == fits
    if fits:
        model.relation(observed)
    else:
        with pytest.raises(ValueError, match=f"cannot be fit to states in '{observed}'.*choose another --model"):
            model.relation(observed)
    with pytest.raises(ValueError, match="unknown coordinates 'polar'"):
        model.relation("polar")


def test_declarations_are_checked_when_a_kind_is_written():
    with pytest.raises(TypeError, match="separable=True: give it kinetic_gradient"):
        type("Bad", (hnn.Model,), {"separable": True})
    with pytest.raises(TypeError, match="conservative=True: give it hamiltonian"):
        type("Bad", (hnn.Model,), {"conservative": True})
    with pytest.raises(TypeError, match="declares coordinates 'polar'"):
        type("Bad", (hnn.Model,), {"coordinates": "polar"})
    with pytest.raises(TypeError, match="must be an hnn.Model subclass"):
        hnn.kinds.ModelKind(torch.nn.Linear, lambda spec: None)
    with pytest.raises(TypeError, match="is not an hnn.Model"):
        hnn.objectives.trajectory.default_method(torch.nn.Linear(2, 2))


def test_rollout_steps_a_models_declared_field():
    """``hnn.rollout(model)`` steps the model's field: a separable model by halves (fewer calls)."""
    torch.manual_seed(3)
    model = hnn.kinds.model_from_args(_args("separable"))
    x0 = torch.randn(4, 4, dtype=torch.float64)
    t = np.linspace(0.0, 1.0, 11)
    by_model, by_field = {}, {}
    a = hnn.rollout(model, x0, t, method="leapfrog", stats=by_model)
    b = hnn.rollout(lambda x: model.time_derivative(x), x0, t, method="leapfrog", stats=by_field)
    torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert by_model["nfev"] < by_field["nfev"]


def test_the_energy_protocol_rolls_a_model_out_in_its_own_state():
    """A mechanical model on observed [q, qdot]: the protocol maps the start into [q, p], rolls out, and
    maps the path back; the same path as ``rollout_observed``."""
    torch.manual_seed(4)
    model = hnn.kinds.model_from_args({**_args("mechanical"), "input_dim": 2})
    spring = hnn.load_task("spring")
    protocol = hnn.EnergyProtocol(name="t", x0="box", num_trials=2, t_span=(0.0, 1.0), num_points=5, splits=1,
                                  method="rk4", options={"dt": 0.05})
    out = hnn.evaluate_energy(spring, {"m": model}, protocol, observed="velocity")
    z0 = torch.as_tensor(out["x0"])
    expected = hnn.objectives.trajectory.rollout_observed(model, z0, np.linspace(0, 1, 5), "velocity", method="rk4", dt=0.05)
    np.testing.assert_allclose(out["m"]["traj"], expected.numpy(), rtol=1e-10, atol=1e-12)
    canonical = hnn.evaluate_energy(spring, {"m": model}, protocol)["m"]["traj"]
    assert np.abs(canonical - out["m"]["traj"]).max() > 1e-6       # a different start state: mapped, not read as is


def test_a_model_spec_reads_its_declared_fields_of_a_runs_args_and_a_missing_one_is_named():
    args = {"kind": "mechanical", "input_dim": 4, "hidden_dim": 8, "learn_rate": 1e-3, "periodic": "theta"}
    spec = hnn.kinds.ModelSpec.from_args(args)
    # the run's other settings (learn_rate) are not the model's; a task's column names mean "angles"
    assert (spec.kind, spec.input_dim, spec.hidden_dim, spec.periodic, spec.nonlinearity) == ("mechanical", 4, 8, True, "tanh")
    assert not hasattr(spec, "learn_rate")
    assert hnn.kinds.model_from_args(args).periodic is True
    with pytest.raises(ValueError, match="need its model's kind"):
        hnn.kinds.ModelSpec.from_args({"input_dim": 2})
    with pytest.raises(ValueError, match="input_dim must be a positive integer, got None"):
        hnn.kinds.model_from_args({"kind": "hnn"})
    with pytest.raises(ValueError, match="constraint graph"):
        hnn.MODEL_KINDS["constrained"].build(hnn.kinds.ModelSpec("constrained", input_dim=4))


def test_a_conservative_models_field_carries_its_energy_and_a_baselines_does_not():
    hnn_model = hnn.build_model(2, 16)
    baseline = hnn.build_model(2, 16, baseline=True)
    assert hnn.interface.carries_energy(hnn_model.field)
    assert not hnn.interface.carries_energy(baseline.field)
    assert not hnn.interface.carries_energy(lambda x, t=None: x)
