"""The pair kind (hnn.models.pair) and the bodies a task declares (hnn.bodies), against independent truths:
exact symmetries to round-off, the analytic gravity field of hnn.orbits.nbody, and sums written out by hand."""
import math

import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.kinds import model_from_args
from hnn.models.pair import PairHNN, TooManyPairsError
from hnn.orbits import nbody
from hnn.tasks import task_config

EPS = torch.finfo(torch.float64).eps


def _model(count=3, dim=2, seed=0, **bodies):
    torch.manual_seed(seed)
    model = PairHNN(Bodies(count, dim, **bodies), hidden_dim=32).double()
    with torch.no_grad():      # masses other than 1, so a wrong mass index shows
        model.log_mass.fill_(math.log(1.7))
    return model


def _states(count, dim, batch=16, seed=1):
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(batch, count, dim, generator=g, dtype=torch.float64) * 2
    p = torch.randn(batch, count, dim, generator=g, dtype=torch.float64)
    return q, p


def _rotation(dim: int, seed: int = 2) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    Q, _ = torch.linalg.qr(torch.randn(dim, dim, generator=g, dtype=torch.float64))
    return Q


def _tolerance(model, x, scale: float) -> torch.Tensor:
    """Round-off of H under a change of the inputs of relative size ``scale`` eps: |dH/dx| |x| per state, summed
    over the pairs' and bodies' terms (each term's error is its own size times eps times the depth of a few
    operations: the factor 64)."""
    grad = hnn.interface.gradient_of(model.hamiltonian, x)
    return 64 * scale * EPS * ((grad.abs() * (x.abs() + 1)).sum(dim=1) + model.hamiltonian(x).abs())


@pytest.mark.parametrize("dim", [2, 3])
def test_rotation_translation_and_permutation_leave_h_unchanged(dim):
    model = _model(4, dim)
    layout = model.bodies
    q, p = _states(4, dim)
    x = layout.join(q, p)
    H = model.hamiltonian(x).detach()
    tol = _tolerance(model, x, 4).detach()
    R = _rotation(dim)
    rotated = model.hamiltonian(layout.join(q @ R.T, p @ R.T)).detach()
    shift = torch.tensor([0.7, -1.3, 0.4][:dim], dtype=torch.float64)
    moved = model.hamiltonian(layout.join(q + shift, p)).detach()
    order = torch.tensor([2, 0, 3, 1])
    swapped = model.hamiltonian(layout.join(q[:, order], p[:, order])).detach()
    for other in (rotated, moved, swapped):
        assert ((other - H).abs() <= tol).all(), (other - H).abs().max()
    # the check can fail: a one-body field (no invariance under translation) moves H far beyond that bound
    fielded = _model(4, dim, external=True)
    change = (fielded.hamiltonian(layout.join(q + shift, p)) - fielded.hamiltonian(x)).abs().detach()
    assert (change > _tolerance(fielded, x, 4).detach()).any()


def test_a_model_built_for_three_bodies_reads_five():
    model = _model(3, 2)
    q, p = _states(5, 2, batch=4)
    x = Bodies(5, 2).join(q, p)
    H = model.hamiltonian(x)
    # written out: 5 kinetic terms of mass 1.7 and the 10 pairs' V(r)
    kinetic = (p * p).sum(dim=(1, 2)) / (2 * 1.7)
    pairs = sum(model.radial(torch.linalg.vector_norm(q[:, a] - q[:, b], dim=1))
                for a in range(5) for b in range(a + 1, 5))
    assert torch.allclose(H, kinetic + pairs, rtol=64 * EPS, atol=0)
    assert model.time_derivative(x).shape == (4, 20)


class _InverseDistance(torch.nn.Module):
    """V = -1/r exactly, on the pair model's inputs (r, 1/r): gravity between unit masses (G = 1)."""

    def forward(self, features):
        return -features[:, 1:2]


@pytest.mark.parametrize("count", [2, 3, 6])
def test_exact_gravity_gives_the_analytic_field(count):
    model = _model(count, 2)
    model.radial_net = _InverseDistance()
    with torch.no_grad():
        model.log_mass.zero_()
    q, p = _states(count, 2, batch=8, seed=5)
    x = Bodies(count, 2).join(q, p)
    truth = nbody.dynamics(x)
    got = model.time_derivative(x)
    # each force is a sum of count - 1 terms of size 1/r^2, each to a few eps
    scale = (1 + 1 / nbody.min_separation(x) ** 2)[:, None] * count
    assert ((got - truth).abs() <= 64 * EPS * scale).all()
    assert torch.allclose(model.hamiltonian(x), nbody.hamiltonian(x), rtol=64 * EPS * count ** 2, atol=0)


def test_chain_pairs_are_neighbours_only():
    model = _model(6, 2, pairs="neighbours")
    q, p = _states(6, 2, batch=3)
    x = model.bodies.join(q, p)
    pairs = sum(model.radial(torch.linalg.vector_norm(q[:, a] - q[:, a + 1], dim=1)) for a in range(5))
    assert torch.allclose(model.potential(x[:, :12]), pairs, rtol=64 * EPS, atol=0)
    # the field is -grad H: autograd of the written-out H agrees with the pair sum's scatter
    grad = hnn.interface.gradient_of(model.hamiltonian, x)
    assert torch.allclose(model.time_derivative(x), torch.cat([grad[:, 12:], -grad[:, :12]], dim=1),
                          rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_cutoff_model_sums_the_shifted_pairs_inside_and_keeps_its_symmetries(dim):
    cutoff = 2.5
    model = _model(6, dim, pairs="cutoff", cutoff=cutoff)
    layout = model.bodies
    q, p = _states(6, dim)
    x = layout.join(q, p)
    H = model.hamiltonian(x).detach()
    # written out over every pair: V(r) - V(r_c) closer than r_c, nothing beyond (the model's own shift)
    shift = model.radial(torch.tensor([cutoff], dtype=torch.float64))
    r = torch.stack([torch.linalg.vector_norm(q[:, a] - q[:, b], dim=1) for a in range(6) for b in range(a + 1, 6)], 1)
    inside = r < cutoff
    assert inside.any() and not inside.all()        # the check can fail: pairs on both sides of the cutoff
    pairs = torch.where(inside, model.radial(r) - shift, 0).sum(dim=1)
    kinetic = (p * p).sum(dim=(1, 2)) / (2 * 1.7)
    assert torch.allclose(H, (kinetic + pairs).detach(), rtol=64 * EPS * 15, atol=0)
    # the field is -grad H: autograd of H against the pair sum's scatter, which reads V' only inside
    grad = hnn.interface.gradient_of(model.hamiltonian, x)
    n = x.shape[1] // 2
    assert torch.allclose(model.time_derivative(x), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=1e-12,
                          atol=1e-12)
    # a rotation, a translation and a permutation change the cells the bodies fall in, not H: a pair the round-off
    # moves across r_c changes H by V'(r_c) times that round-off (H is continuous there), within the bound
    tol = _tolerance(model, x, 4).detach()
    R = _rotation(dim)
    shift_q = torch.tensor([0.7, -1.3, 0.4][:dim], dtype=torch.float64)
    order = torch.tensor([2, 0, 5, 3, 1, 4])
    for moved in (layout.join(q @ R.T, p @ R.T), layout.join(q + shift_q, p), layout.join(q[:, order], p[:, order])):
        other = model.hamiltonian(moved).detach()
        assert ((other - H).abs() <= tol).all(), (other - H).abs().max()


def test_a_cutoffs_pairs_need_the_positions():
    with pytest.raises(ValueError, match="find_pairs"):
        hnn.models.pair.pair_index(5, "cutoff")


def test_the_closed_form_slope_trains_as_autograds(monkeypatch):
    # V' by the tanh MLP's closed form (training backpropagates once) against autograd's double backward: the field
    # and every parameter's gradient of a loss on it agree to round-off (a few products of width 32: 64 eps)
    model = _model(5, 2)
    assert model._closed_form_slope()
    q, p = _states(5, 2, batch=8)
    x = model.bodies.join(q, p)

    def field_and_grads():
        model.zero_grad()
        dxdt = model.time_derivative(x)
        (dxdt ** 2).sum().backward()
        return dxdt.detach(), [t.grad.clone() for t in model.parameters()]

    closed, closed_grads = field_and_grads()
    monkeypatch.setattr(PairHNN, "_closed_form_slope", lambda self: False)
    auto, auto_grads = field_and_grads()
    assert torch.allclose(closed, auto, rtol=64 * EPS, atol=64 * EPS * float(auto.abs().max()))
    for a, b in zip(closed_grads, auto_grads):
        assert torch.allclose(a, b, rtol=64 * EPS, atol=64 * EPS * float(b.abs().max()))


def test_too_many_pairs_say_how_much_they_need(monkeypatch):
    monkeypatch.setattr(hnn.models.pair, "PAIR_BYTES", 2 ** 20)
    model = _model(3, 2)
    x = Bodies(400, 2).join(*_states(400, 2, batch=2))
    with pytest.raises(TooManyPairsError, match="GiB"):
        model.hamiltonian(x)


def test_saved_args_rebuild_the_same_model(tmp_path):
    args = {**task_config("3body").to_dict(), "kind": "pairwise", "hidden_dim": 16, "dtype": "float64"}
    torch.manual_seed(3)
    model = model_from_args(args)
    torch.save(model.state_dict(), tmp_path / "model.pt")
    again = model_from_args(args)
    again.load_state_dict(torch.load(tmp_path / "model.pt"))
    x = Bodies(3, 2).join(*_states(3, 2, batch=4))
    assert torch.equal(again.time_derivative(x), model.time_derivative(x))


def test_a_task_without_bodies_is_refused():
    args = {**task_config("spring").to_dict(), "kind": "pairwise"}
    with pytest.raises(ValueError, match="BODIES"):
        model_from_args(args)


# -- the least-squares pair fit (hnn.fits.radial) ----------------------------------------------------------


def _gravity_data(count, rows=400, seed=7):
    """States of ``count`` unit masses with every pair at least 0.5 apart, and the true dx/dt (float64)."""
    q, p = _states(count, 2, batch=4 * rows, seed=seed)
    x = Bodies(count, 2).join(q, p)
    x = x[nbody.min_separation(x) > 0.5][:rows]
    return x, nbody.dynamics(x)


def _fit_args(count, fit, **extra):
    return {"kind": "pairwise", "fit": fit, "hidden_dim": 40, "bodies": Bodies(count, 2).to_dict(), **extra}


@pytest.mark.parametrize("count", [2, 3])
def test_the_radial_library_recovers_gravity(count):
    x, dxdt = _gravity_data(count)
    model = model_from_args(_fit_args(count, "library"))
    stats = hnn.fits.solve(model, x, dxdt, fit="library")
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # one term survives the threshold, -1/r, and the mass 1, to round-off: the refit after thresholding is one
    # column's ratio to the data (a few eps), and the ridge GCV keeps (1e-13 relative to unit columns) biases a
    # one-column solve by its square
    assert set(kept) == {"1/r"}
    assert kept["1/r"] == pytest.approx(-1.0, rel=64 * EPS)
    assert float(model.masses()[0]) == pytest.approx(1.0, rel=64 * EPS)
    assert "- 1 sum 1/r" in stats["fit"]["equation"] and stats["fit"]["equation"].startswith("H = sum p^2/(2 m)")
    # fitted on `count` bodies, it gives the analytic field of 5
    x5, dxdt5 = _gravity_data(5, rows=50)
    # (forces of size up to 4 x 1/0.5^2 = 16, each term to a few eps)
    assert torch.allclose(model.time_derivative(x5), dxdt5, rtol=0, atol=64 * 16 * EPS)


def test_sampled_radial_neurons_fit_a_smooth_pair_potential():
    # springs of rest length 1 between all pairs of 3 bodies in 3-D: V = (r - 1)^2 / 2, smooth, so a few
    # dozen tanh(w r + b) reach it far below the field's size
    torch.manual_seed(0)
    layout = Bodies(3, 3)
    q, p = _states(3, 3, batch=300, seed=11)
    x = layout.join(q, p)
    exact = _model(3, 3)
    exact.radial = lambda r: (r - 1) ** 2 / 2
    with torch.no_grad():
        exact.log_mass.zero_()
    dxdt = exact.time_derivative(x).detach()
    for fit in ("swim", "elm"):
        model = model_from_args({**_fit_args(3, fit), "bodies": layout.to_dict()})
        stats = hnn.fits.solve(model, x, dxdt, fit=fit, seed=0)
        # measured 2e-16 (swim) and 1e-21 (elm) of the field's mean square: the bound leaves the seeds' spread room
        assert stats["train_loss"][0] < 1e-10 * float((dxdt ** 2).mean())
        assert "tanh(w r + b)" in model.equation()


def test_a_fitted_pair_model_saves_and_reloads(tmp_path):
    x, dxdt = _gravity_data(3, rows=100)
    args = _fit_args(3, "swim")
    model = model_from_args(args)
    hnn.fits.solve(model, x, dxdt, fit="swim", seed=1)
    torch.save(model.state_dict(), tmp_path / "model.pt")
    again = model_from_args(args)
    again.load_state_dict(torch.load(tmp_path / "model.pt"))
    assert torch.equal(again.time_derivative(x), model.time_derivative(x))
    assert torch.equal(again.hamiltonian(x), model.hamiltonian(x))
