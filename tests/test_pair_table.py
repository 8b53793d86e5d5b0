"""A pair model's V(r) as a table (hnn.models.pair_table.TabulatedPair), against independent truths: the cubic
interpolant's error bound on a known potential (Lennard-Jones), the model it tabulates (its field, its H,
and its own numbers outside the table's range), and the refusals that name their fix."""
import math

import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.models import pair_table
from hnn.models.pair import PairHNN
from hnn.models.pair_table import TabulatedPair

EPS = torch.finfo(torch.float64).eps


def _lennard_jones(layout: Bodies) -> PairHNN:
    """A pair model whose V is Lennard-Jones' 4 (r^-12 - r^-6) exactly (V' by autograd), unit masses."""
    model = PairHNN(layout, hidden_dim=8).double()
    model.radial = lambda r: 4 * (r ** -12 - r ** -6)
    return model


def _network(layout: Bodies, seed: int = 0) -> PairHNN:
    torch.manual_seed(seed)
    model = PairHNN(layout, hidden_dim=32).double()
    with torch.no_grad():          # masses other than 1: the table reads the model's kinetic energy through
        model.log_mass.fill_(math.log(1.7))
    return model


def _states(count: int, batch: int = 8, seed: int = 1, spread: float = 1.5) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(batch, count, 2, generator=g, dtype=torch.float64) * spread
    p = torch.randn(batch, count, 2, generator=g, dtype=torch.float64)
    return Bodies(count, 2).join(q, p)


def test_the_tables_slope_of_lennard_jones_keeps_the_interpolation_bound():
    lo, hi = 0.8, 3.0
    table = TabulatedPair(_lennard_jones(Bodies(4, 2)), (lo, hi), tol=1e-9)
    assert table.max_error <= 1e-9
    r = torch.exp(torch.linspace(math.log(lo), math.log(hi), 10007, dtype=torch.float64))[None]
    exact_slope = 4 * (-12 * r ** -13 + 6 * r ** -7)
    # in s = log r the table's dV/ds is cubic Hermite of f(s) = 4 (-12 e^-12s + 6 e^-6s), its end derivatives by
    # second-order differences (each within h^2 / 3 max|f3| of f's, f3 the third derivative: the one-sided bound).
    # So |f - p| is at most the exact-derivative Hermite error h^4 / 384 max|f4| plus twice the basis' largest
    # weight on a derivative (4/27 h) times that error; V' = f / r. Round-off: f to a few eps of |f| <= 48 lo^-12
    h, top = table.h, lo ** -12
    f3 = 4 * (12 ** 4 * top + 6 ** 4 * lo ** -6)          # max|f3| and max|f4| at s = log lo
    f4 = 4 * (12 ** 5 * top + 6 ** 5 * lo ** -6)
    bound_f = h ** 4 / 384 * f4 + 2 * 4 / 27 * h * h ** 2 / 3 * f3 + 64 * EPS * 48 * top
    assert ((table.radial_slope(r) - exact_slope).abs() <= bound_f / r).all()
    # its V is the integral of its dV/ds from the model's V at r_hi: off by at most the slope's bound over log(hi/lo)
    exact = 4 * (r ** -12 - r ** -6)
    assert ((table.radial(r) - exact).abs() <= bound_f * math.log(hi / lo) + 64 * EPS * 4 * top).all()


def test_a_table_is_its_networks_field_and_h_to_its_tolerance():
    layout = Bodies(5, 2)
    model = _network(layout)
    x = _states(5)
    q = layout.split(x)[0]
    i, j = torch.triu_indices(5, 5, 1)
    r = torch.cdist(q, q)[:, i, j]
    table = TabulatedPair(model, (float(r.min()) / 2, float(r.max()) * 2), tol=1e-10)
    with torch.no_grad():
        exact, field = model.time_derivative(x), table.time_derivative(x)
        # each pair's slope within tol of the model's (relative to |V'| plus its median); ten pairs a body at most
        scale = float(model.radial_slope(r).abs().max())
        assert torch.allclose(field, exact, rtol=0, atol=10 * 1e-10 * 2 * scale)
        # dT/dp is the model's own: the masses (1.7) read through
        assert torch.equal(field[:, :10], exact[:, :10])
        assert torch.allclose(table.hamiltonian(x), model.hamiltonian(x), rtol=0, atol=1e-9)


def test_pairs_outside_the_tables_range_read_the_model_itself():
    model = _network(Bodies(3, 2))
    table = TabulatedPair(model, (0.5, 4.0), tol=1e-8)
    r = torch.tensor([[0.1, 0.4999, 7.0, float("nan"), 1.0]], dtype=torch.float64)
    with torch.no_grad():
        slope, value = table.radial_slope(r), table.radial(r)
        want_slope, want_value = model.radial_slope(r), model.radial(r)
    assert torch.equal(slope[:, :3], want_slope[:, :3]) and torch.equal(value[:, :3], want_value[:, :3])
    assert slope[0, 3].isnan() and value[0, 3].isnan()          # a NaN distance stays NaN, as the model's does
    assert slope[0, 4] == pytest.approx(float(want_slope[0, 4]), abs=1e-7)


def test_a_cutoffs_table_ends_at_the_cutoff_and_keeps_the_shifted_pairs():
    layout = Bodies(6, 2, pairs="cutoff", cutoff=2.5)
    model = _lennard_jones(layout)
    table = TabulatedPair(model, (0.7, 10.0), tol=1e-10)
    assert table.r_range == (0.7, 2.5)
    g = torch.Generator().manual_seed(3)
    # a row of bodies 1.1 apart, jittered: neighbours inside r_c, others beyond it
    q = torch.arange(6, dtype=torch.float64)[None, :, None] * torch.tensor([1.1, 0.0], dtype=torch.float64)
    q = q + 0.05 * torch.randn(4, 6, 2, generator=g, dtype=torch.float64)
    x = layout.join(q, torch.randn(4, 6, 2, generator=g, dtype=torch.float64))
    exact, field = model.time_derivative(x).detach(), table.time_derivative(x)
    # forces of size up to 4 x 24 (2 / 1^13): the tolerance relative to that
    assert torch.allclose(field, exact, rtol=0, atol=1e-8)
    assert torch.allclose(table.hamiltonian(x), model.hamiltonian(x).detach(), rtol=0, atol=1e-9)


def test_a_leapfrog_path_on_the_table_follows_the_models():
    layout = Bodies(4, 2)
    model = _network(layout, seed=4)
    x0 = _states(4, batch=2, seed=5, spread=1.0)
    table = TabulatedPair(model, (0.05, 20.0), tol=1e-10)
    t = torch.linspace(0, 1, 11, dtype=torch.float64).numpy()
    with torch.no_grad():
        a = hnn.rollout(model.field, x0, t, method="leapfrog", dt=0.01)
        b = hnn.rollout(table.field, x0, t, method="leapfrog", dt=0.01)
    # 100 steps, each moving the path by dt^2 times a force error of 1e-10 of the forces' size: far below 1e-8
    assert torch.allclose(a, b, rtol=0, atol=1e-8)


def test_a_table_refuses_bad_input_naming_the_fix(monkeypatch):
    model = _network(Bodies(3, 2))
    with pytest.raises(ValueError, match=r"give two finite distances 0 < r_lo < r_hi"):
        TabulatedPair(model, (2.0, 1.0))
    with pytest.raises(ValueError, match=r"give a relative slope error between 0 and 1"):
        TabulatedPair(model, (0.5, 2.0), tol=0)
    with pytest.raises(TypeError, match=r"tabulates a pair model's V\(r\)"):
        TabulatedPair(hnn.models.HNN(4, 16), (0.5, 2.0))
    with pytest.raises(ValueError, match=r"starts past the cutoff 2.5"):
        TabulatedPair(_network(Bodies(3, 2, pairs="cutoff", cutoff=2.5)), (3.0, 4.0))
    with pytest.raises(ValueError, match=r"one-body field U\(q_i\)"):
        TabulatedPair(_network(Bodies(3, 2, external=True)), (0.5, 2.0))
    # the model's own V' rounds at about 1e-16 of its terms: no table reaches a tenth of that, and doubling the
    # knots stops where the error no longer falls
    with pytest.raises(ValueError, match=r"relative error of .* knots where more knots no longer reduce it .* "
                                         r"above tol=1e-17: narrow r_range"):
        TabulatedPair(model, (0.5, 2.0), tol=1e-17)
    monkeypatch.setattr(pair_table, "MAX_KNOTS", pair_table.START_KNOTS)
    with pytest.raises(ValueError, match=r"relative error of .* at 1025 knots \(at most 1025\), above tol=1e-15"):
        TabulatedPair(model, (0.5, 2.0), tol=1e-15)
