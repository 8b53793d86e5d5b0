"""The library fit's threshold against the data's units (issue 78), through ``hnn.fit_least_squares``.

A double well H = p^2/2 + q^4/4 - q^2/2 (m = 1) sampled in metres, and the same states in millimetres
(q and p times 1000, t unchanged: H in the millimetres' units is 1e6 H). The units rule fits data far from
unit scale in their canonical units, where the threshold (0.05) is relative to the data's scale: the
millimetres keep the quartic (2.5e-7 q^4 in their units, far below 0.05) and answer with the same physics.
``units='on'`` makes the threshold relative at any scale, inside the rule's band too (data within 10x of
unit scale are fitted as they are: there the threshold is in the data's units, docs/fits.md)."""
import numpy as np
import pytest
import torch

import hnn

EPS = np.finfo(np.float64).eps
TOL = 64 * EPS * 2      # see the first test: a 3-column refit of condition ~10 on H of size ~2


def _double_well(scale: float, rows: int = 600):
    x = np.random.default_rng(0).uniform(-1.6, 1.6, size=(rows, 2))
    q, p = x[:, :1], x[:, 1:]
    dxdt = np.concatenate([p, q - q ** 3], axis=1)         # dq/dt = p, dp/dt = -(q^3 - q)
    return scale * x, scale * dxdt


def _fit(scale: float, units: str = "auto"):
    x, dxdt = _double_well(scale)
    return hnn.fit_least_squares("hnn", x, dxdt, fit="library", anchor=(np.zeros(2), 0.0), units=units,
                                 progress=False)


def _H(model, x) -> np.ndarray:
    with torch.no_grad():
        return model.hamiltonian(torch.as_tensor(x)).numpy()


def test_metres_and_millimetres_give_one_physics_through_the_default_path():
    (metres, m_stats), (millimetres, mm_stats) = _fit(1.0), _fit(1000.0)
    assert "unit_scales" not in m_stats and "unit_scales" in mm_stats     # the rule rescaled the millimetres alone
    assert m_stats["fit"]["terms"] == mm_stats["fit"]["terms"] == 3      # q^2, p^2, q^4 kept in both
    assert "q^4" in mm_stats["fit"]["equation"] and "q^4" in m_stats["fit"]["equation"]
    x, _ = _double_well(1.0, rows=200)
    truth = 0.5 * x[:, 1] ** 2 + 0.25 * x[:, 0] ** 4 - 0.5 * x[:, 0] ** 2
    # exact data, the true H in the library: the refit on the 3 kept columns (unit-norm, q^2 against q^4 their
    # worst pair: a condition of order 10) to a few eps of H's size (~2) each, and H's three terms' rounding;
    # the millimetres' H is 1e6 times the metres'
    tol = TOL
    np.testing.assert_allclose(_H(metres, x), truth, rtol=0, atol=tol)
    np.testing.assert_allclose(_H(millimetres, 1000 * x) / 1e6, truth, rtol=0, atol=tol)


@pytest.mark.parametrize("scale", [0.3, 3.0, 10.0, 1000.0])
def test_units_on_makes_the_threshold_relative_at_every_scale(scale):
    model, stats = _fit(scale, units="on")
    assert stats["fit"]["terms"] == 3 and "q^4" in stats["fit"]["equation"]
    x, _ = _double_well(1.0, rows=200)
    truth = 0.5 * x[:, 1] ** 2 + 0.25 * x[:, 0] ** 4 - 0.5 * x[:, 0] ** 2
    # H in the scaled data's units is scale^2 H (q and p both times scale, t unchanged)
    np.testing.assert_allclose(_H(model, scale * x) / scale ** 2, truth, rtol=0, atol=TOL)
