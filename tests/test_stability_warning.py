"""hnn.rollout's warning past a fixed-step method's stability limit (hnn/integrators/stability.py), on an
analytic stiff oscillator: each limit measured on the exact oscillator, the Jacobian's spectral radius
against its closed form, a warning past the limit naming dt and the fix, and silence inside it."""
import math
import warnings

import numpy as np
import pytest
import torch

import hnn
from hnn.integrators.stability import MIN_STEPS, StepSizeWarning, spectral_radius, warn_if_unstable

OMEGA = 1e3         # a stiff oscillator: q'' = -omega^2 q, its modes at +-i omega


def stiff(x):
    """dx/dt = (omega p, -omega q): H = omega (q^2 + p^2) / 2, eigenvalues +-i omega."""
    return torch.stack([OMEGA * x[:, 1], -OMEGA * x[:, 0]], 1)


LIMITED = sorted(name for name, solver in hnn.SOLVERS.items() if solver.limit({}) is not None)


def test_the_explicit_fixed_step_methods_declare_a_limit_and_no_other_does():
    assert LIMITED == ["leapfrog", "rk4", "yoshida4"]
    assert hnn.get_solver("yoshida4").limit({"base": "midpoint"}) is None


@pytest.mark.parametrize("method", LIMITED)
def test_each_limit_is_where_the_method_starts_to_grow_on_the_exact_oscillator(method):
    """At 0.99 of its limit the method's path on the oscillator stays bounded (its largest state over steps
    1000-2000 is within 1.5x of that over steps 0-1000: near the limit a symplectic method's orbit is a
    long ellipse, bounded but not a circle); at 1.01 times it the path grows over 10x from one half to
    the next: the declared limit is the measured one within 1%."""
    x0 = torch.tensor([[1.0, 0.0]], dtype=torch.float64)

    def growth(fraction):
        dt = fraction * hnn.get_solver(method).limit({}) / OMEGA
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StepSizeWarning)
            size = hnn.rollout(stiff, x0, dt * np.arange(2001), method=method, max_norm=None)[0].norm(dim=1)
        return float(size[1000:].max() / size[:1001].max())
    assert growth(0.99) < 1.5
    assert growth(1.01) > 10


def test_the_spectral_radius_is_the_oscillators_frequency():
    x0 = torch.randn(8, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 100
    assert spectral_radius(stiff, x0) == pytest.approx(OMEGA, rel=1e-6)
    # a nonlinear field: the pendulum dx/dt = (p, -k sin q), |lambda| = sqrt(k |cos q|) at each start
    k = 400.0
    q = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)
    x = torch.stack([q, torch.zeros(3, dtype=torch.float64)], 1)
    assert spectral_radius(lambda s: torch.stack([s[:, 1], -k * torch.sin(s[:, 0])], 1), x) == pytest.approx(
        math.sqrt(k), rel=1e-6)


def test_a_rollout_past_the_limit_warns_once_naming_dt_and_the_fix():
    """RK4 at omega dt = 3 (its limit is 2.83): one StepSizeWarning naming dt, the estimate and the
    largest stable dt; at omega dt = 2.5 none. The implicit and adaptive methods have no limit: no check.
    (The midpoint's own fixed-point iteration stops at h L ~ 2 with its own error.)"""
    x0 = torch.tensor([[1.0, 0.0], [0.0, 0.5]], dtype=torch.float64)
    t = (3.0 / OMEGA) * np.arange(MIN_STEPS + 1)
    with pytest.warns(StepSizeWarning) as caught:
        hnn.rollout(stiff, x0, t, method="rk4", max_norm=None)
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "dt = 0.003" in message and "|lambda| = 1e+03" in message and "Use dt below 0.00283" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error", StepSizeWarning)
        hnn.rollout(stiff, x0, (2.5 / OMEGA) * np.arange(MIN_STEPS + 1), method="rk4")
        # a finer dt than the grid's interval is what is checked
        hnn.rollout(stiff, x0, t, method="rk4", dt=2.0 / OMEGA)
    for method, options in (("midpoint", {}), ("yoshida4", {"base": "midpoint"}), ("dopri5", {})):
        assert warn_if_unstable(hnn.get_solver(method), stiff, x0, t, options) is None


def test_a_learned_field_past_the_limit_warns():
    """An HNN whose H is a stiff spring's, given by its weights: its rollout by leapfrog past 2 / omega warns."""
    torch.manual_seed(0)
    model = hnn.SeparableHNN(2, 8).double()
    with torch.no_grad():
        omega = spectral_radius(model.field, torch.zeros(1, 2, dtype=torch.float64))
    t = (2.2 / omega) * np.arange(MIN_STEPS + 1)
    with pytest.warns(StepSizeWarning, match="leapfrog"):
        hnn.rollout(model, torch.zeros(1, 2, dtype=torch.float64), t, method="leapfrog", max_norm=None)


def test_a_registered_method_that_declares_a_limit_is_checked():
    """The warning reads the limit from the method's ``Solver``: a new explicit method registered with one warns."""
    rk4 = hnn.get_solver("rk4")
    hnn.register_solver(hnn.integrators.solvers.fixed_step_solver("my_rk4", hnn.integrators.fixed_step.RK4, order=4,
                                                                  stability_limit=rk4.stability_limit))
    try:
        with pytest.warns(StepSizeWarning, match="my_rk4"):
            hnn.rollout(stiff, torch.tensor([[1.0, 0.0]], dtype=torch.float64), (3.0 / OMEGA) * np.arange(MIN_STEPS + 1),
                        method="my_rk4", max_norm=None)
    finally:
        del hnn.SOLVERS["my_rk4"]
