"""REBOUND as the gravity task's second truth (hnn/orbits/rebound_truth.py), against independent truths: IAS15 and
WHFast on a 2-body Kepler orbit against its analytic solution, IAS15 against our true-force yoshida4 on an 8-body
scene of the gravity task to the yoshida4's own Richardson-estimated error, REBOUND's leapfrog converging to IAS15 at
second order, and IAS15 keeping the energy to round-off. REBOUND is an optional extra: its tests skip without it;
the checks of the arguments and the missing-extra message run everywhere."""
import math
import sys

import numpy as np
import pytest
import torch

import hnn
from hnn.interface import SplitField
from hnn.orbits import nbody, rebound_truth

EPS = float(np.finfo(np.float64).eps)
SOFTENING = 0.1         # the gravity task's default


@pytest.fixture
def rebound():
    return pytest.importorskip("rebound")


def _kepler(t: np.ndarray, a: float = 1.0, e: float = 0.5) -> np.ndarray:
    """Two unit masses (G = 1, mu = 2) on a relative ellipse of semi-major axis ``a`` and eccentricity ``e``, at
    pericentre at t = 0, centre of mass at rest at the origin: the states ``(len(t), 8)`` in nbody's layout. Kepler's
    equation solved by Newton's method to round-off."""
    mu = 2.0
    n = math.sqrt(mu / a ** 3)
    mean = n * t
    E = mean.copy()
    for _ in range(50):                             # quadratic convergence: a few iterations reach round-off
        E = E - (E - e * np.sin(E) - mean) / (1 - e * np.cos(E))
    rate = n / (1 - e * np.cos(E))
    b = a * math.sqrt(1 - e * e)
    rx, ry, vx, vy = a * (np.cos(E) - e), b * np.sin(E), -a * np.sin(E) * rate, b * np.cos(E) * rate
    # body 1 at -r/2, body 2 at +r/2 (r = q_2 - q_1), the same for the velocities
    return np.stack([-rx / 2, rx / 2, -ry / 2, ry / 2, -vx / 2, vx / 2, -vy / 2, vy / 2], axis=-1)


def _scene(count: int = 8, seeds=(0, 1)) -> torch.Tensor:
    """Start states of the gravity task's rotating disk ``(len(seeds), 4 count)``."""
    gravity = hnn.load_task("gravity")
    return torch.tensor(np.stack([gravity.random_config(np.random.RandomState(s), count) for s in seeds]))


def _truth():
    gravity = hnn.load_task("gravity")
    return SplitField(gravity.dynamics, lambda p: p, gravity.potential_gradient)


def test_ias15_follows_the_analytic_kepler_orbit(rebound):
    period = 2 * math.pi / math.sqrt(2.0)
    t = np.linspace(0.0, 3 * period, 13)
    exact = _kepler(t)
    stats = {}
    path = rebound_truth.rollout(exact[0], t, "ias15", softening=0.0, stats=stats).numpy()[0]
    steps = stats["steps"][0]
    # IAS15's truncation error per step is below round-off, so the error is round-off's: by Brouwer's law its phase
    # error grows as eps steps^1.5 (Rein & Spiegel 2015), times the largest coordinate it moves; 4 for the few
    # roundings of a step's update
    bound = 4 * EPS * steps ** 1.5 * np.abs(exact).max()
    assert np.abs(path - exact).max() <= bound, (np.abs(path - exact).max(), bound, steps)


def test_whfast_is_exact_on_two_bodies_at_any_step(rebound):
    """Two bodies in Jacobi coordinates: the Kepler drift is the whole motion (no interaction term), so WHFast's
    steps are exact but for round-off, even at 60 steps for three orbits."""
    t = np.arange(31) * 0.2
    exact = _kepler(t)
    for dt in (0.1, 0.05):
        stats = {}
        path = rebound_truth.rollout(exact[0], t, "whfast", softening=0.0, dt=dt, stats=stats).numpy()[0]
        # each step's Kepler solve rounds; the error walks with the steps (linear bound: no Brouwer phase growth
        # since a step's error is one solve's round-off), 16 for the solve's iterations
        bound = 16 * EPS * stats["steps"][0] * np.abs(exact).max()
        assert np.abs(path - exact).max() <= bound, (dt, np.abs(path - exact).max(), bound)


def test_ias15_agrees_with_our_yoshida4_to_its_error_on_8_gravitating_bodies(rebound):
    x0, t = _scene(), np.linspace(0.0, 0.5, 11)
    ias15 = rebound_truth.rollout(x0, t, "ias15", softening=SOFTENING)
    dt = 0.0025
    with torch.no_grad():
        coarse = hnn.rollout(_truth(), x0, t, method="yoshida4", dt=dt)
        fine = hnn.rollout(_truth(), x0, t, method="yoshida4", dt=dt / 2)
    # Richardson: a 4th-order method's error at dt is (coarse - fine) * 16/15 to leading order; twice that allows
    # the next order's share (measured: the ratio of errors at dt and dt/2 is 15.4, near 16)
    estimate = (coarse - fine).abs().max().item() * 16 / 15
    assert (coarse - ias15).abs().max().item() <= 2 * estimate, ((coarse - ias15).abs().max().item(), estimate)
    # and the estimate is the yoshida4's, not a bound too loose to test: IAS15 sits within it of both
    assert (fine - ias15).abs().max().item() <= 2 * estimate / 16


def test_rebound_leapfrog_converges_to_ias15_at_second_order(rebound):
    x0, t = _scene(), np.linspace(0.0, 0.5, 11)
    ias15 = rebound_truth.rollout(x0, t, "ias15", softening=SOFTENING)
    errors = [(rebound_truth.rollout(x0, t, "leapfrog", softening=SOFTENING, dt=dt) - ias15).abs().max().item()
              for dt in (0.005, 0.0025)]
    # halving the step of a second-order method divides its error by 4, up to the next order's share (measured 3.99)
    assert 3.5 < errors[0] / errors[1] < 4.5, errors


def test_ias15_keeps_the_energy_to_round_off(rebound):
    x0, t = _scene(), np.linspace(0.0, 0.5, 11)
    stats = {}
    path = rebound_truth.rollout(x0, t, "ias15", softening=SOFTENING, stats=stats)
    flat = path.reshape(-1, path.shape[-1])
    H = nbody.hamiltonian(flat, SOFTENING).reshape(path.shape[:2])
    # the size of H's terms: kinetic plus |potential|, the scale its float64 sum rounds at
    scale = (nbody.kinetic_energy(flat) - nbody.potential_energy(flat, SOFTENING)).reshape(path.shape[:2])
    terms = 8 + 8 * 7 // 2                      # H's sum: a kinetic term per body and a potential per pair
    for row in range(len(x0)):
        drift = (H[row] - H[row, 0]).abs().max().item()
        # evaluating H rounds at most eps per term of the sum, and IAS15's own round-off walks as sqrt(steps)
        bound = EPS * scale[row].max().item() * (terms + math.sqrt(stats["steps"][row]))
        assert drift <= bound, (row, drift, bound)
    # against the true forces' leapfrog at dt = 0.01, whose energy error is of order dt^2: eleven orders above
    with torch.no_grad():
        leapfrog = hnn.rollout(_truth(), x0, t, method="leapfrog", dt=0.01)
    H_leapfrog = nbody.hamiltonian(leapfrog.reshape(-1, leapfrog.shape[-1]), SOFTENING).reshape(leapfrog.shape[:2])
    assert (H_leapfrog - H_leapfrog[:, :1]).abs().max() > 1e6 * (H - H[:, :1]).abs().max()


def test_the_states_keep_our_layout(rebound):
    """Zero steps: what goes in comes back, in the same columns; a body's position lands where nbody reads it."""
    x0 = _scene(count=5, seeds=(3,))
    path = rebound_truth.rollout(x0, [0.0], "ias15", softening=SOFTENING)
    assert path.shape == (1, 1, 20) and torch.equal(path[:, 0], x0)


def test_the_arguments_are_checked_before_rebound_loads():
    x0, t = _scene(), np.linspace(0.0, 0.1, 3)
    with pytest.raises(ValueError, match="integrator 'rk4': choose one of ias15, whfast, leapfrog"):
        rebound_truth.rollout(x0, t, "rk4", softening=SOFTENING)
    with pytest.raises(ValueError, match="takes fixed steps: give dt"):
        rebound_truth.rollout(x0, t, "leapfrog", softening=SOFTENING)
    with pytest.raises(ValueError, match="is 1.66667 steps of dt = 0.03"):
        rebound_truth.rollout(x0, t, "whfast", softening=SOFTENING, dt=0.03)
    with pytest.raises(ValueError, match="softening -1"):
        rebound_truth.rollout(x0, t, "ias15", softening=-1)
    with pytest.raises(ValueError, match="shape \\(n, 4N\\)"):
        rebound_truth.rollout(torch.zeros(2, 6), t, "ias15", softening=SOFTENING)
    with pytest.raises(TypeError):
        rebound_truth.rollout(x0, t, "ias15")       # the softening is the caller's to give, never a silent default


def test_a_missing_rebound_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "rebound", None)        # what `import rebound` meets where it is not installed
    with pytest.raises(ImportError, match=r'pip install -e "\.\[nbody\]"'):
        rebound_truth.rebound()
    with pytest.raises(ImportError, match="nbody"):
        rebound_truth.rollout(_scene(), [0.0, 0.01], "ias15", softening=SOFTENING)
    assert rebound_truth.version() is None


def test_the_benchmark_measures_every_method_at_every_n(rebound, tmp_path):
    """analysis/benchmarks/nbody_truth.py end to end on a tiny budget: each method's row at each N, IAS15's energy
    error at round-off's scale and the leapfrogs' at their step's, the JSON and the table written."""
    from hnn_analysis.benchmarks import nbody_truth
    results = nbody_truth.main(["--sizes", "3", "8", "--horizon", "0.04", "--repeats", "1", "--out", str(tmp_path)])
    assert [row["N"] for row in results["rows"]] == [3, 8]
    for row in results["rows"]:
        methods = row["methods"]
        assert set(methods) == set(nbody_truth.METHODS)
        assert all(m["ms_per_step"] > 0 for m in methods.values()) and row["floor_ms"] > 0
        assert methods["REBOUND IAS15"]["error_at_T"] == 0.0            # the reference against itself
        # IAS15 keeps H to round-off: eps times the terms' scale (under 60 for 8 bodies of this disk) times the 36
        # terms of H's sum, per body, is under 1e-13; the leapfrogs at dt = 0.01 to order dt^2, their paths too
        assert methods["REBOUND IAS15"]["energy_per_body"] < 1e-12
        for label in ("ours leapfrog", "REBOUND leapfrog"):
            assert 1e-8 < methods[label]["energy_per_body"] < 1e-1 and methods[label]["error_at_T"] < 1e-1
    assert (tmp_path / "nbody_truth.json").exists() and "REBOUND WHFast" in (tmp_path / "nbody_truth.md").read_text()


def test_the_benchmark_refuses_a_quick_page():
    from hnn_analysis.benchmarks import nbody_truth
    with pytest.raises(SystemExit, match="drop --quick"):
        nbody_truth.main(["--quick", "--update-docs"])
    with pytest.raises(SystemExit, match="not a whole number of steps"):
        nbody_truth.main(["--horizon", "0.015", "--sizes", "3"])
