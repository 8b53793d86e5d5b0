"""Gravity of N bodies (experiment-gravity, hnn.orbits.nbody's softening): the softened field is the symplectic
gradient of the softened H, softening converges to Newton's at second order, the pair kind with the exact softened
V gives the same field at any N, the radial library (at the task's softening) recovers the softened V and the masses
from dx/dt, a sampled pair fit's field call gives the same numbers in chunks as in one piece, and without softening
close encounters are redrawn."""
import numpy as np
import pytest
import torch

import hnn
from hnn.bodies import Bodies
from hnn.fits.radial import RADIAL_TERMS, RadialLibrary
from hnn.kinds import model_from_args
from hnn.models.pair import PairHNN
from hnn.orbits import nbody
from hnn.orbits.encounters import MIN_SEPARATION
from hnn.tasks import load_task, task_config

EPS = torch.finfo(torch.float64).eps


def _states(count, rows, seed=0):
    data = load_task("gravity")
    rng = np.random.RandomState(seed)
    return torch.tensor(np.stack([data.random_config(rng, count) for _ in range(rows)]))


@pytest.mark.parametrize("softening", [0.0, 0.1])
def test_the_softened_field_is_the_symplectic_gradient_of_the_softened_h(softening):
    x = _states(8, 6)
    grad = hnn.interface.gradient_of(lambda z: nbody.hamiltonian(z, softening), x)
    n = x.shape[1] // 2
    # accelerations of size up to 7 / 0.2^2 (pairs no closer than the start law's 0.2), each to a few eps
    assert torch.allclose(nbody.dynamics(x, softening), torch.cat([grad[:, n:], -grad[:, :n]], dim=1), rtol=0,
                          atol=64 * EPS * 7 / 0.2 ** 2)


def test_softening_converges_to_newton_at_second_order():
    x = _states(5, 4, seed=1)
    newton = nbody.potential_energy(x)
    gaps = [(nbody.potential_energy(x, e) - newton).abs() for e in (0.02, 0.01)]
    # V_e - V_0 = e^2 / (2 r^3) + O(e^4) per pair: halving e quarters the gap
    assert torch.allclose(gaps[0] / gaps[1], torch.full_like(gaps[0], 4.0), rtol=1e-2)
    assert torch.equal(nbody.dynamics(x, 0.0), nbody.dynamics(x))


class _Softened(torch.nn.Module):
    """V = -1 / sqrt(r^2 + e^2) on the pair model's inputs (r, 1/r)."""

    def __init__(self, softening):
        super().__init__()
        self.softening = softening

    def forward(self, features):
        return -(features[:, :1] ** 2 + self.softening ** 2).rsqrt()


@pytest.mark.parametrize("count", [3, 12])
def test_the_pair_kind_with_the_softened_potential_is_the_softened_field(count):
    torch.manual_seed(0)
    model = PairHNN(Bodies(8, 2), hidden_dim=8).double()
    model.radial_net = _Softened(0.1)
    x = _states(count, 4, seed=2)
    assert torch.allclose(model.time_derivative(x), nbody.dynamics(x, 0.1), rtol=0, atol=64 * EPS * count / 0.1 ** 2)
    assert torch.allclose(model.hamiltonian(x), nbody.hamiltonian(x, 0.1), rtol=64 * EPS * count ** 2, atol=0)


def _pair_fit(fit, **settings):
    """The pair kind of the gravity task's config (its softening) fitted by ``fit``, untrained."""
    config = task_config("gravity", {"seed": 0, **settings})
    return model_from_args({**config.to_dict(), "kind": "pairwise", "fit": fit, "hidden_dim": 32})


def test_the_radial_library_recovers_the_softened_potential_and_the_masses():
    count, softening = 8, load_task("gravity").SOFTENING
    x = _states(count, 100, seed=3)
    model = _pair_fit("library")        # the task's default softening, which its data are drawn at
    stats = hnn.fits.solve(model, x, nbody.dynamics(x, softening), fit="library")
    names = model.features.names()
    kept = {names[k]: float(c) for k, c in enumerate(model.coef) if c != 0}
    # one term survives the threshold, and the mass 1: the refit after thresholding is one column's ratio to the
    # data, each entry of both a sum of count - 1 pair terms of a few operations each (the factor 16)
    assert set(kept) == {"1/sqrt(r^2 + 0.1^2)"}
    assert kept["1/sqrt(r^2 + 0.1^2)"] == pytest.approx(-1.0, rel=16 * count * EPS)
    assert float(model.masses()[0]) == pytest.approx(1.0, rel=16 * count * EPS)
    assert stats["fit"]["equation"] == "H = sum p^2/(2 m) - 1 sum 1/sqrt(r^2 + 0.1^2), m = 1"
    # a run's saved args (its config's, softening among them) rebuild the same terms, so its weights reload
    args = {**task_config("gravity", {"seed": 0}).to_dict(), "kind": "pairwise", "fit": "library"}
    again = model_from_args(args)
    again.load_state_dict(model.state_dict())
    assert torch.equal(again.time_derivative(x), model.time_derivative(x))
    # fitted on 8 bodies, the softened field of 40 (pulls up to 39 / 0.1^2 at worst, each pair's to a few eps)
    wide = _states(40, 3, seed=4)
    assert torch.allclose(model.time_derivative(wide), nbody.dynamics(wide, softening), rtol=0,
                          atol=64 * EPS * 39 / softening ** 2)


def test_without_softening_the_radial_library_is_the_unsoftened_one():
    # the 2-body and 3-body tasks' library, term by term, and the gravity task's at --softening 0
    assert RadialLibrary().names() == RadialLibrary(0.0).names() == list(RADIAL_TERMS)
    assert _pair_fit("library", softening=0.0).features.names() == list(RADIAL_TERMS)
    three = model_from_args({**task_config("3body").to_dict(), "kind": "pairwise", "fit": "library"})
    assert three.features.names() == list(RADIAL_TERMS)
    with pytest.raises(ValueError, match="softening"):
        RadialLibrary(-0.1)


def test_a_sampled_pair_field_in_chunks_is_the_field_in_one_piece(monkeypatch):
    x8 = _states(8, 40, seed=5)
    model = _pair_fit("swim")
    hnn.fits.solve(model, x8, nbody.dynamics(x8, 0.1), fit="swim", seed=0)
    x = _states(30, 3, seed=6)
    whole_field, whole_energy = model.time_derivative(x), model.hamiltonian(x)
    # a field call holds a few numbers a pair, not the features' width: exactly what it needs passes
    pairs = 30 * 29 // 2
    monkeypatch.setattr(hnn.models.pair, "PAIR_BYTES", len(x) * pairs * (3 + 3 * 2) * x.element_size())
    # chunks of 7 pair rows (the last one short): the features' rows cut where one call would not cut them
    monkeypatch.setattr(hnn.fits.radial, "CHUNK_BYTES", 7 * 3 * model.features.width * x.element_size())
    field, energy = model.time_derivative(x), model.hamiltonian(x)
    # V'(r) (or V) of each pair is a dot product over the width: its sum may be reordered in another chunk's
    # product, by up to width eps times the sum of its terms' sizes; a body's pull sums 29 of them in one order
    _, r = hnn.models.pair.separations(Bodies(30, 2).bodywise(x[:, :60]), *hnn.models.pair.pair_index(30))
    z = r.reshape(-1, 1)
    slope_terms = float((model.features.jacobian(z)[:, :, 0] * model.coef).abs().sum(dim=1).max())
    value_terms = float((model.features(z) * model.coef).abs().sum(dim=1).max())
    width = model.features.width
    assert torch.allclose(field, whole_field, rtol=0, atol=29 * width * EPS * slope_terms)
    assert torch.allclose(energy, whole_energy, rtol=0, atol=pairs * width * EPS * value_terms)


@pytest.mark.parametrize("block_bytes", [None, 1])
def test_past_the_pair_list_the_field_in_blocks_of_bodies_is_the_pair_sum(monkeypatch, block_bytes):
    # N = 70 > PAIR_LIST_BODIES: blocks of bodies against every body (the default's of 24 rows, the last short,
    # or one body a block), against the pair list's scatter of the same pairs
    if block_bytes is not None:
        monkeypatch.setattr(hnn.fits.radial, "BLOCK_BYTES", block_bytes)
    count = 70
    assert count > hnn.fits.radial.PAIR_LIST_BODIES
    x8, x = _states(8, 40, seed=5), _states(count, 3, seed=7)
    library, sampled = _pair_fit("library"), _pair_fit("swim")
    hnn.fits.solve(library, x8, nbody.dynamics(x8, 0.1), fit="library")
    hnn.fits.solve(sampled, x8, nbody.dynamics(x8, 0.1), fit="swim", seed=0)
    # the library's softened term is the true field: each of 69 pulls (up to 1 / 0.1^2) to a few eps
    assert torch.allclose(library.time_derivative(x), nbody.dynamics(x, 0.1), rtol=0, atol=64 * EPS * 69 / 0.1 ** 2)
    blocked = sampled.time_derivative(x)
    monkeypatch.setattr(hnn.fits.radial, "PAIR_LIST_BODIES", count)
    listed = sampled.time_derivative(x)
    # each pull V'(r) (q_i - q_j) / r (|(q_i - q_j) / r| <= 1), V' a width-long dot product, summed over 69 bodies in
    # another order: (69 + width) eps times the largest |V'| term sum, per body
    _, r = hnn.models.pair.separations(Bodies(count, 2).bodywise(x[:, :2 * count]), *hnn.models.pair.pair_index(count))
    slope_terms = float((sampled.features.jacobian(r.reshape(-1, 1))[:, :, 0] * sampled.coef).abs().sum(dim=1).max())
    assert torch.allclose(blocked, listed, rtol=0, atol=69 * (69 + sampled.features.width) * EPS * slope_terms)


def test_without_softening_close_encounters_are_redrawn(tmp_path):
    data = load_task("gravity")
    # a tenth of a time unit: some of the disk's starts meet closer than MIN_SEPARATION, most do not
    d = data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 0.1], softening=0.0)
    x = torch.tensor(np.concatenate([d["x"], d["test_x"]]), dtype=torch.float64)
    assert x.shape == (50, 32) and d["resampled"] > 0
    assert float(nbody.min_separation(x).min()) >= MIN_SEPARATION * (1 - 1e-6)     # float32 rows
    soft = data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 0.1])
    assert soft["resampled"] == 0 and soft["cache_key"] != d["cache_key"]
    # over a whole time unit nearly every unsoftened path meets another body: the generator gives up, by name
    with pytest.raises(RuntimeError, match="redrawing"):
        data.get_dataset(seed=0, save_dir=tmp_path, num_trials=10, num_points=5, t_span=[0.0, 1.0], softening=0.0)


def test_fit_least_squares_at_the_scenes_softening_is_the_commands_fit():
    """Every path one answer: hnn.fit_least_squares given the task's softening and layout fits the softened V
    the command's library fit finds (the same terms and coefficients); without it, no softened term exists."""
    count, softening = 8, load_task("gravity").SOFTENING
    x = _states(count, 60, seed=5)
    dxdt = nbody.dynamics(x, softening)
    layout = task_config("gravity").BODIES
    model, stats = hnn.fit_least_squares("pairwise", x, dxdt, fit="library", bodies=layout, softening=softening,
                                         units="off", progress=False)
    command = _pair_fit("library")
    hnn.fits.solve(command, x, dxdt, fit="library", progress=False)
    assert stats["fit"]["equation"] == "H = sum p^2/(2 m) - 1 sum 1/sqrt(r^2 + 0.1^2), m = 1"
    inner = getattr(model, "model", model)
    assert torch.equal(inner.coef, command.coef)
    plain, _ = hnn.fit_least_squares("pairwise", x, dxdt, fit="library", bodies=layout, units="off", progress=False)
    assert not any("sqrt" in name for name in getattr(plain, "model", plain).features.names())
