"""The fits' features interface (hnn.fits.base.Features): a new feature set is one module and one row.

The feature set below lives in this file alone; one row added to ``hnn.fits.FITS`` makes it a fit that
``hnn.fit_least_squares`` and ``hnn.fits.build`` serve by name, with the row's declared solve. Its truth:
a Duffing oscillator H = p^2/2 + q^2/2 + q^4/4, which lies in the set's span (exact recovery to round-off),
and the interface's own defaults (the gradient through the Jacobian) checked against autograd."""
import numpy as np
import pytest
import torch

import hnn
from hnn.fits import FITS, Fit
from hnn.fits.base import Features
from hnn.fits.solves import PLAIN, THRESHOLDED


class EvenPowers(Features):
    """x_i^2 and x_i^4 of every input column: 2 in_dim features, no parameters of its own."""
    forms = ("hamiltonian", "kinetic", "potential")
    formula = False

    def __init__(self, in_dim: int):
        super().__init__()
        self.in_dim, self.width = in_dim, 2 * in_dim

    @classmethod
    def make(cls, spec, form, in_dim):
        return cls(in_dim)

    def forward(self, x):
        return torch.cat([x ** 2, x ** 4], dim=1)

    def jacobian(self, x):
        eye = torch.eye(self.in_dim, dtype=x.dtype)
        return torch.cat([(2 * x)[:, :, None] * eye, (4 * x ** 3)[:, :, None] * eye], dim=1)


def _duffing(rows=300, seed=0):
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, size=(rows, 2))
    q, p = x[:, :1], x[:, 1:]
    return x, np.concatenate([p, -(q + q ** 3)], axis=1)       # dq/dt = dH/dp, dp/dt = -dH/dq


@pytest.fixture
def toy_row(monkeypatch):
    row = Fit("even", "x^2 and x^4 of each column, by least squares", kinds=("hnn", "separable"),
              features=(EvenPowers,), solve=PLAIN)
    monkeypatch.setitem(FITS, "even", row)
    return row


@pytest.mark.parametrize("kind", ["hnn", "separable"])
def test_a_feature_set_of_one_file_and_one_row_is_fitted_by_name(toy_row, kind):
    x, dxdt = _duffing()
    model, stats = hnn.fit_least_squares(kind, x, dxdt, fit="even", anchor=(np.zeros(2), 0.0), progress=False)
    truth = torch.as_tensor(0.5 * x[:, 1] ** 2 + 0.5 * x[:, 0] ** 2 + 0.25 * x[:, 0] ** 4)
    H = model.hamiltonian(torch.as_tensor(x)).detach()
    # an exact fit in float64: a solve of conditioning ~1e2 on 4 columns, so ~1e3 eps of H's size (~3)
    assert torch.allclose(H, truth, rtol=0, atol=1e3 * torch.finfo(torch.float64).eps * 3)
    assert stats["fit"]["fit"] == "even" and stats["train_loss"][0] < 1e-20
    assert "equation" not in stats["fit"]       # a plain solve keeps every feature and prints none


def test_the_row_declares_the_solve_and_the_build_the_kinds_forms(toy_row, monkeypatch):
    x, dxdt = _duffing()
    dxdt = dxdt + 0.01 * np.random.default_rng(1).normal(size=dxdt.shape)    # the x^2 p-terms pick up noise
    plain, _ = hnn.fit_least_squares("hnn", x, dxdt, fit="even", progress=False)
    monkeypatch.setitem(FITS, "even", Fit("even", "thresholded", kinds=("hnn", "baseline"), features=(EvenPowers,),
                                          solve=THRESHOLDED))
    sparse, stats = hnn.fit_least_squares("hnn", x, dxdt, fit="even", threshold=0.1, progress=False)
    # the thresholded solve drops p^4 (truth 0; its noisy coefficient is far below 0.1) and keeps the rest; a
    # row naming a kind whose form its features do not stand for is refused at the build, naming the form
    assert bool((plain.coef != 0).all()) and sparse.coef[3] == 0 and bool((sparse.coef[:3] != 0).all())
    assert stats["fit"]["terms"] == 3
    with pytest.raises(ValueError, match=r"fit 'even' has no features for the field terms the baseline kind "
                                         r"reads .*stand for hamiltonian, kinetic, potential"):
        hnn.fits.build(hnn.specs.ModelSpec(kind="baseline", input_dim=2, fit="even"))


def test_a_row_must_say_how_it_solves_and_draws():
    with pytest.raises(ValueError, match="names its features and its solve"):
        Fit("broken", "no solve", features=(EvenPowers,))
    with pytest.raises(ValueError, match="a sampler exactly where its features are drawn"):
        Fit("broken", "drawn, no sampler", features=(hnn.fits.features.TanhFeatures,), solve=PLAIN)


def test_the_default_gradient_is_the_jacobians_and_autograds():
    features = EvenPowers(3)
    x = torch.randn(5, 3, dtype=torch.float64, requires_grad=True)
    coef = torch.randn(6, dtype=torch.float64)
    (want,) = torch.autograd.grad((features(x) @ coef).sum(), x)
    # both sums of a few products of O(1) numbers: equal to a few eps
    assert torch.allclose(features.gradient(x, coef), want, rtol=1e-14, atol=1e-14)


def test_every_row_builds_its_kinds_models_from_its_declared_features():
    """Each solved row's features stand for a form each of its kinds reads (no row names a kind it cannot build)."""
    bodies = hnn.bodies.Bodies(count=2, dim=2).to_dict()
    for name, row in FITS.items():
        for kind in row.kinds or ():
            spec = hnn.specs.ModelSpec(kind=kind, input_dim=8, hidden_dim=3, fit=name,
                                       bodies=bodies if kind == "pairwise" else None)
            model = hnn.fits.build(spec)
            assert model.input_dim == 8 and all(p.features is None or p.features.width >= 1 for p in model.parts())
