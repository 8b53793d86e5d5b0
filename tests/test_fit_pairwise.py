"""The pair kind's least-squares fit by name through ``hnn.fit_least_squares`` (issue 81): it needs the bodies'
layout and says so with the fix; given it, the radial library recovers gravity's -1/r and the unit mass, in
the data's own units (the pair kind reads distances, which no per-column scale keeps)."""
import numpy as np
import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.orbits import nbody

EPS = torch.finfo(torch.float64).eps


def _gravity(count=3, rows=300, seed=7):
    """States of ``count`` unit masses in 2-D, every pair at least 0.5 apart, and the true dx/dt (float64)."""
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(4 * rows, count, 2, generator=g, dtype=torch.float64) * 2
    p = torch.randn(4 * rows, count, 2, generator=g, dtype=torch.float64)
    x = Bodies(count, 2).join(q, p)
    x = x[nbody.min_separation(x) > 0.5][:rows]
    return x, nbody.dynamics(x)


def test_the_pair_kind_by_name_without_its_layout_names_the_layout_and_the_fix():
    x, dxdt = _gravity()
    with pytest.raises(ValueError, match=r"the pairwise kind reads x as bodies and needs their layout: pass "
                                         r"bodies=hnn\.bodies\.Bodies\(count=N, dim=d\)"):
        hnn.fit_least_squares("pairwise", x, dxdt, fit="library", progress=False)
    with pytest.raises(ValueError, match=r"the hnn kind reads x as it is: drop bodies"):
        hnn.fit_least_squares("hnn", x, dxdt, fit="library", bodies=Bodies(3, 2), progress=False)


@pytest.mark.parametrize("layout", [Bodies(3, 2), Bodies(3, 2).to_dict()])
def test_the_pair_kind_by_name_recovers_gravity(layout):
    x, dxdt = _gravity()
    model, stats = hnn.fit_least_squares("pairwise", x, dxdt, fit="library", bodies=layout, progress=False)
    kept = {name: float(c) for name, c in zip(model.features.names(["r"]), model.coef) if c != 0}
    # -1/r alone and the mass 1, to round-off: after thresholding a one-column refit (a few eps), biased by the
    # square of the smallest ridge GCV keeps (1e-13 relative to unit columns), as tests/test_pair.py derives
    assert set(kept) == {"1/r"} and kept["1/r"] == pytest.approx(-1.0, rel=64 * EPS)
    assert float(model.masses()[0]) == pytest.approx(1.0, rel=64 * EPS)
    assert "- 1 sum 1/r" in stats["fit"]["equation"] and "unit_scales" not in stats
    # fitted on 3 bodies, the same weights give the analytic field of 5 (forces up to 4 x 1/0.5^2 = 16)
    x5, dxdt5 = _gravity(5, rows=40)
    assert torch.allclose(model.time_derivative(x5), dxdt5, rtol=0, atol=64 * 16 * EPS)


def test_the_pair_kind_refuses_data_the_units_rule_would_rescale_with_the_fix():
    x, dxdt = _gravity()
    with pytest.raises(ValueError, match=r"units='auto': x and dxdt are far from unit scale.*the pairwise kind "
                                         r"cannot be rescaled: it reads distances.*units='off'"):
        hnn.fit_least_squares("pairwise", 1000 * x, 1000 * dxdt, fit="swim", bodies=Bodies(3, 2), progress=False)
    # units='off' fits them as they are (a sampled V of the distances in the data's units): no refusal
    model, stats = hnn.fit_least_squares("pairwise", 1000 * x, 1000 * dxdt, fit="swim", width=20,
                                         bodies=Bodies(3, 2), units="off", progress=False)
    assert np.isfinite(stats["train_loss"][0]) and model.input_dim == 12
