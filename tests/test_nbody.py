"""The n-body tasks: physics, the batched orbit generator, close encounters, the cache, the datasets."""
import json
import warnings

import numpy as np
import pytest
import torch
from scipy.integrate import solve_ivp

import hnn
from hnn import cache
from hnn.orbits import nbody


@pytest.fixture(scope="module")
def two():
    return hnn.load_task("2body")


@pytest.fixture(scope="module")
def three():
    return hnn.load_task("3body")


SYSTEMS = [("2body", 50, (0.0, 20.0)), ("3body", 20, (0.0, 5.0))]


def numpy_rhs(t, y):
    """The gravitational field written out body by body, as one solve_ivp call per orbit would use it."""
    b = len(y) // 4
    q = np.stack([y[:b], y[b:2 * b]], axis=1)
    a = np.zeros_like(q)
    for i in range(b):
        for j in range(b):
            if i != j:
                d = q[j] - q[i]
                a[i] += d / np.linalg.norm(d) ** 3
    return np.concatenate([y[2 * b:], a[:, 0], a[:, 1]])


def state(q, p):
    """Canonical (4B,) state from per-body positions and momenta, each (B, 2)."""
    q, p = np.asarray(q, dtype=float), np.asarray(p, dtype=float)
    return np.concatenate([q[:, 0], q[:, 1], p[:, 0], p[:, 1]])


# --------------------------------------------------------------------------- physics

def test_potential_of_three_bodies_sums_every_pair():
    q = np.array([[0.3, -0.2], [1.1, 0.5], [-0.7, 0.9]])
    p = np.array([[0.1, 0.2], [-0.3, 0.05], [0.4, -0.6]])
    x = torch.tensor(state(q, p))[None]
    r = lambda i, j: np.linalg.norm(q[i] - q[j])  # noqa: E731
    by_hand = -(1 / r(0, 1) + 1 / r(0, 2) + 1 / r(1, 2))
    assert nbody.potential_energy(x).item() == pytest.approx(by_hand, rel=1e-14)
    # the original 2-body file added only the last pair (1, 2): that would fail here
    assert nbody.potential_energy(x).item() != pytest.approx(-1 / r(1, 2), rel=1e-3)
    assert nbody.kinetic_energy(x).item() == pytest.approx(0.5 * (p ** 2).sum(), rel=1e-14)
    assert nbody.hamiltonian(x).item() == pytest.approx(by_hand + 0.5 * (p ** 2).sum(), rel=1e-14)
    np.testing.assert_allclose(nbody.total_momentum(x)[0].numpy(), p.sum(0), rtol=1e-14)
    L = (q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]).sum()
    assert nbody.angular_momentum(x).item() == pytest.approx(L, rel=1e-14)
    assert nbody.min_separation(x).item() == pytest.approx(min(r(0, 1), r(0, 2), r(1, 2)), rel=1e-14)


@pytest.mark.parametrize("bodies", [2, 3, 4])
def test_dynamics_is_the_symplectic_gradient_of_the_hamiltonian(bodies):
    gen = torch.Generator().manual_seed(bodies)
    x = torch.randn(16, 4 * bodies, generator=gen, dtype=torch.float64) * 1.5
    x = x[nbody.min_separation(x) > 0.2].requires_grad_(True)
    (grad,) = torch.autograd.grad(nbody.hamiltonian(x).sum(), x)
    half = 2 * bodies
    symplectic = torch.cat([grad[:, half:], -grad[:, :half]], dim=1)    # (dH/dp, -dH/dq)
    torch.testing.assert_close(nbody.dynamics(x.detach()), symplectic, rtol=1e-12, atol=1e-12)
    # and the field, written out body by body, agrees
    for row in x.detach().numpy()[:4]:
        np.testing.assert_allclose(nbody.dynamics(torch.tensor(row)).numpy(), numpy_rhs(0, row), rtol=1e-12)


def test_width_must_be_a_multiple_of_four():
    with pytest.raises(ValueError, match="width 4B"):
        nbody.dynamics(torch.zeros(3, 6, dtype=torch.float64))


# --------------------------------------------------------------------------- samplers

def test_two_body_start_states(two):
    x = np.stack([two.initial_state(s) for s in range(50)])
    q0, q1 = x[:, [0, 2]], x[:, [1, 3]]
    np.testing.assert_array_equal(q1, -q0)
    assert q0.min() >= 0.5 and q0.max() <= 1.5            # each coordinate of body 0 in [0.5, 1.5]
    assert np.abs(nbody.total_momentum(torch.tensor(x)).numpy()).max() == 0
    # circular speed about the centre of mass, 1 / (2 sqrt(r)), times one factor 1 + 0.05 N(0, 1)
    r = np.linalg.norm(q0, axis=1)
    factor = np.linalg.norm(x[:, [4, 6]], axis=1) * 2 * np.sqrt(r)
    assert 0.8 < factor.min() and factor.max() < 1.2 and factor.std() == pytest.approx(0.05, rel=0.4)
    # the original's draw order: rand(2) for the position, then randn() for the speed factor
    rng = np.random.RandomState(3)
    np.testing.assert_array_equal(q0[3], rng.rand(2) + 0.5)
    assert factor[3] == pytest.approx(1 + 0.05 * rng.randn(), rel=1e-12)


def test_three_body_start_states(three):
    x = np.stack([three.initial_state(s) for s in range(50)])
    xt = torch.tensor(x)
    q = np.stack([x[:, :3], x[:, 3:6]], axis=-1)                    # (n, body, 2)
    r = np.linalg.norm(q, axis=-1)
    assert np.ptp(r, axis=1).max() < 1e-12 and r.min() >= 0.9 and r.max() <= 1.2
    sides = nbody._pair_distances(xt).numpy()                       # an equilateral triangle
    np.testing.assert_allclose(sides, np.broadcast_to(r[:, :1] * np.sqrt(3), sides.shape), rtol=1e-12)
    # velocities: circular ones times 1 + 0.2 U[-1, 1] per component
    v = np.stack([x[:, 6:9], x[:, 9:]], axis=-1)
    rot = lambda a, t: np.stack([np.cos(t) * a[..., 0] - np.sin(t) * a[..., 1],  # noqa: E731
                                 np.sin(t) * a[..., 0] + np.cos(t) * a[..., 1]], -1)
    circular = rot(q, np.pi / 2) / r[..., None] ** 1.5 * 3 ** -0.25
    ratio = v / circular
    clear = np.abs(circular) > 1e-6                                 # components not ~0 by rounding
    assert np.abs(ratio - 1)[clear].max() <= 0.2 + 1e-9 and np.abs(ratio - 1)[clear].max() > 0.15
    assert np.abs(nbody.total_momentum(xt).numpy()).max() > 1e-3     # no longer exactly zero
    rng = np.random.RandomState(7)                                  # draw order: rand(2), rand(), rand(2) x 3
    direction = 2 * rng.rand(2) - 1
    radius = rng.rand() * 0.3 + 0.9
    np.testing.assert_allclose(q[7, 0], direction / np.linalg.norm(direction) * radius, rtol=1e-12)
    np.testing.assert_allclose(ratio[7, 0], 1 + 0.2 * (2 * rng.rand(2) - 1), rtol=1e-9)


# --------------------------------------------------------------------------- generator

@pytest.mark.parametrize("task, points, t_span", SYSTEMS)
def test_generated_orbits_conserve_energy_and_momenta(task, points, t_span):
    data = hnn.load_task(task)
    orbits = nbody.sample_orbits(data.random_config, 20, points, t_span, np.random.RandomState(0))
    x = torch.from_numpy(orbits.x)
    assert x.shape == (20, points, 4 * data.NUM_BODIES) and torch.isfinite(x).all()
    H, P, L = nbody.hamiltonian(x), nbody.total_momentum(x), nbody.angular_momentum(x)
    # RK45 at rtol 1e-9 with solve_ivp's default atol 1e-6 (as the original): a few 1e-5 at most
    assert ((H - H[:, :1]).abs() / H[:, :1].abs()).max() < 1e-4
    assert ((L - L[:, :1]).abs() / L[:, :1].abs()).max() < 1e-4
    # Runge-Kutta methods keep linear invariants exactly: the total momentum to rounding
    assert (P - P[:, :1]).abs().max() < 1e-12
    assert orbits.min_separation.min() >= nbody.MIN_SEPARATION
    np.testing.assert_allclose(orbits.t_eval, np.linspace(*t_span, points))


@pytest.mark.parametrize("task, points, t_span", SYSTEMS)
def test_batched_generation_equals_one_solve_ivp_per_orbit(task, points, t_span):
    data = hnn.load_task(task)
    # tight tolerances: the two agree to the integrator's accuracy
    tight = nbody.sample_orbits(data.random_config, 8, points, t_span, np.random.RandomState(1),
                                rtol=1e-11, atol=1e-11)
    for k in range(8):
        solo = solve_ivp(numpy_rhs, t_span, tight.x[k, 0], t_eval=tight.t_eval, rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(tight.x[k], solo.y.T, rtol=0, atol=1e-7)
    # the data's tolerances (rtol 1e-9, atol 1e-6): the batched call is at least as accurate as one
    # call per orbit (its tolerances are tightened by sqrt(batch)), measured against DOP853 at 1e-12
    orbits = nbody.sample_orbits(data.random_config, 8, points, t_span, np.random.RandomState(1))
    np.testing.assert_array_equal(orbits.x[:, 0], tight.x[:, 0])                 # same start states
    for k in range(8):
        truth = solve_ivp(numpy_rhs, t_span, orbits.x[k, 0], t_eval=orbits.t_eval, rtol=1e-12, atol=1e-12,
                          method="DOP853").y.T
        solo = solve_ivp(numpy_rhs, t_span, orbits.x[k, 0], t_eval=orbits.t_eval, rtol=1e-9).y.T
        solo_error = np.abs(solo - truth).max()
        assert np.abs(orbits.x[k] - truth).max() <= 1.5 * solo_error + 1e-9
        assert np.abs(orbits.x[k] - solo).max() <= 2.5 * solo_error + 1e-9


def _sampler_with(bad_states, data):
    """``data.random_config``, except that the first draws return ``bad_states``."""
    queue = list(bad_states)

    def sample(rng):
        return queue.pop(0) if queue else data.random_config(rng)
    return sample


def test_a_start_at_near_collision_is_redrawn_and_counted(two):
    near = state([[0.5, 0.5], [0.5 + 1e-3, 0.5]], [[0.0, 0.1], [0.0, -0.1]])      # 1e-3 apart
    assert nbody.min_separation(torch.tensor(near)).item() == pytest.approx(1e-3)
    orbits = nbody.sample_orbits(_sampler_with([near], two), 6, 20, (0.0, 20.0), np.random.RandomState(0))
    assert orbits.resampled == 1 and orbits.reasons == {"close_encounter": 1, "failed": 0}
    assert not np.isclose(orbits.x[:, 0], near).all(axis=1).any()
    assert np.isfinite(orbits.x).all() and orbits.min_separation.min() >= nbody.MIN_SEPARATION
    # the other orbits are the sampler's own draws, in order: draws 2..6, then the redraw (draw 7)
    rng = np.random.RandomState(0)
    expected = [two.random_config(rng) for _ in range(6)]
    np.testing.assert_array_equal(orbits.x[1:, 0], np.stack(expected[:5]))
    np.testing.assert_array_equal(orbits.x[0, 0], expected[5])


def test_a_collision_during_the_integration_is_caught_between_samples(two):
    # at rest 1 apart, the two bodies fall into each other at t = pi / 4: a head-on collision
    # that no output sample (every 5 time units) comes near, and no integrator survives
    fall = state([[-0.5, 0.0], [0.5, 0.0]], [[0.0, 0.0], [0.0, 0.0]])
    orbits = nbody.sample_orbits(_sampler_with([fall, fall], two), 4, 5, (0.0, 20.0), np.random.RandomState(0))
    assert orbits.resampled == 2 and orbits.reasons["close_encounter"] == 2
    assert np.isfinite(orbits.x).all() and orbits.min_separation.min() >= nbody.MIN_SEPARATION


def test_failed_integrations_are_isolated_and_redrawn(two, monkeypatch):
    """A batched call that fails (as scipy does when one orbit needs too small a step) is bisected
    until the culprit is alone; the culprit is redrawn and the rest kept."""
    poison = two.initial_state(100)
    real_rollout = nbody.rollout
    calls = []

    def rollout(f, x0, t_eval, **kw):
        calls.append(len(x0))
        if np.isclose(x0.numpy()[:, :poison.size], poison).all(axis=1).any():   # x0 carries a row-id column
            raise hnn.DivergenceError("solve_ivp failed: required step size is less than spacing")
        return real_rollout(f, x0, t_eval, **kw)

    monkeypatch.setattr(nbody, "rollout", rollout)
    sample = _sampler_with([two.initial_state(1), two.initial_state(2), poison, two.initial_state(3)], two)
    orbits = nbody.sample_orbits(sample, 4, 10, (0.0, 20.0), np.random.RandomState(0))
    assert orbits.resampled == 1 and orbits.reasons == {"close_encounter": 0, "failed": 1}
    # the whole batch, its halves, the failing half's two rows, then the redraw
    assert calls == [4, 2, 2, 1, 1, 1]
    np.testing.assert_array_equal(orbits.x[[0, 1, 3], 0], np.stack([two.initial_state(s) for s in (1, 2, 3)]))
    assert not np.isclose(orbits.x[2, 0], poison).all()
    # non-finite start states are redrawn too, without integrating them
    sample = _sampler_with([np.full(8, np.nan)], two)
    orbits = nbody.sample_orbits(sample, 2, 5, (0.0, 1.0), np.random.RandomState(0))
    assert orbits.resampled == 1 and orbits.reasons["failed"] == 1 and np.isfinite(orbits.x).all()


def test_gives_up_after_max_resamples(two):
    near = state([[0.5, 0.5], [0.5, 0.5 + 1e-3]], [[0.0, 0.0], [0.0, 0.0]])
    with pytest.raises(RuntimeError, match="max_resamples=2"):
        nbody.sample_orbits(lambda rng: near, 3, 5, (0.0, 1.0), np.random.RandomState(0), max_resamples=2)


def test_three_bodies_are_chaotic_yet_conserve_energy(three):
    x = torch.tensor(three.initial_state(14))
    nudged = x.clone()
    nudged[0] += 1e-8
    traj = hnn.rollout(nbody.dynamics, torch.stack([x, nudged]), np.linspace(0, 20, 201), rtol=1e-12, atol=1e-12)
    gap = (traj[0] - traj[1]).norm(dim=-1)
    assert gap[0].item() == pytest.approx(1e-8, rel=1e-6)
    # exponential divergence: about two orders of magnitude per 10 time units, five over [0, 20]
    assert gap[100] > 30 * gap[0] and gap[200] > 30 * gap[100] and gap[200] > 1e4 * gap[0]
    H = nbody.hamiltonian(traj)
    assert ((H - H[:, :1]).abs() / H[:, :1].abs()).max() < 1e-9
    assert nbody.min_separation(traj).min() > nbody.MIN_SEPARATION


# --------------------------------------------------------------------------- cache

def _builder(calls, value=1.0):
    def build():
        calls.append(1)
        return {"x": np.full((3, 4), value, dtype=np.float32), "dt": 0.5, "resampled": 2}
    return build


def test_cache_reuses_the_file_for_the_same_params(tmp_path, capsys):
    calls = []
    params = {"seed": 0, "num_trials": 10, "t_span": (0.0, 20.0)}
    first = cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    assert "toy: generated" in capsys.readouterr().out
    again = cache.get_cached_dataset(tmp_path, "toy", dict(params), _builder(calls))
    assert len(calls) == 1 and capsys.readouterr().out == ""
    for data in (first, again):
        assert data["dt"] == 0.5 and isinstance(data["dt"], float) and data["resampled"] == 2
        assert isinstance(data["resampled"], int) and data["x"].dtype == np.float32
    np.testing.assert_array_equal(first["x"], again["x"])
    (path,) = tmp_path.glob("toy-*.npz")
    assert path == cache.cache_path(tmp_path, "toy", params)
    with np.load(path) as f:                                       # the params travel inside the file
        assert json.loads(str(f["__params__"])) == {"seed": 0, "num_trials": 10, "t_span": [0.0, 20.0]}
    assert not list(tmp_path.glob(".*"))                           # no temporary file left behind


def test_cache_regenerates_for_a_new_seed_or_param_and_says_which(tmp_path, capsys):
    calls = []
    params = {"seed": 0, "num_trials": 10}
    cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    capsys.readouterr()
    cache.get_cached_dataset(tmp_path, "toy", {"seed": 1, "num_trials": 10}, _builder(calls, 2.0))
    out = capsys.readouterr().out
    assert len(calls) == 2 and "differs in seed (cached 0, requested 1)" in out and "generated" in out
    cache.get_cached_dataset(tmp_path, "toy", {"seed": 0, "num_trials": 20}, _builder(calls))
    assert len(calls) == 3 and "num_trials (cached 10, requested 20)" in capsys.readouterr().out
    assert len(list(tmp_path.glob("toy-*.npz"))) == 3
    # the seed-0 file still serves seed 0
    assert cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))["x"][0, 0] == 1.0
    assert len(calls) == 3


def test_cache_with_other_params_under_its_name_is_reported_and_rebuilt(tmp_path):
    calls = []
    params = {"seed": 0, "num_trials": 10}
    path = cache.cache_path(tmp_path, "toy", params)
    cache._save(path, {"seed": 0, "num_trials": 99}, {"x": np.zeros(2)})   # e.g. copied over by hand
    with pytest.warns(UserWarning, match=r"num_trials \(cached 99, requested 10\); regenerating"):
        data = cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    assert len(calls) == 1 and data["x"].shape == (3, 4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    assert len(calls) == 1


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
def test_a_corrupt_cache_is_reported_and_rebuilt(tmp_path, damage):
    calls = []
    params = {"seed": 0}
    path = cache.cache_path(tmp_path, "toy", params)
    cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    blob = path.read_bytes()
    path.write_bytes(b"not an npz at all" if damage == "garbage" else blob[: len(blob) // 2])
    with pytest.warns(UserWarning, match="unreadable"):
        data = cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))
    assert len(calls) == 2 and data["x"].shape == (3, 4)
    cache.get_cached_dataset(tmp_path, "toy", params, _builder(calls))       # the rebuilt file is good
    assert len(calls) == 2


# --------------------------------------------------------------------------- datasets

@pytest.mark.parametrize("task, trials, points, t_end", [("2body", 10, 5, 20.0), ("3body", 10, 4, 5.0)])
def test_small_datasets_shapes_split_and_cache(task, trials, points, t_end, tmp_path, capsys):
    data = hnn.load_task(task)
    width = 4 * data.NUM_BODIES
    d = data.get_dataset(seed=3, save_dir=tmp_path, num_trials=trials, num_points=points)
    assert f"{task}: generated {trials} orbits ({d['resampled']} resampled: " in capsys.readouterr().out
    rows = trials * points
    test_rows = int(rows * 0.2)          # the first 20% of rows: whole trajectories
    assert d["x"].shape == (rows - test_rows, width) and d["test_x"].shape == (test_rows, width)
    for key in ("x", "dxdt", "test_x", "test_dxdt"):
        assert d[key].dtype == np.float32 and np.isfinite(d[key]).all()
    assert d["dt"] == pytest.approx(t_end / (points - 1)) and d["resampled"] == 0   # (none for this seed)
    assert d["resampled_close_encounter"] == d["resampled_failed"] == 0
    # test = trajectories 0 and 1: the first row is the first draw of RandomState(seed)
    np.testing.assert_allclose(d["test_x"][0], data.initial_state(3), rtol=1e-6)
    np.testing.assert_allclose(d["test_x"][points], data.random_config(_after(data, 3, 1)), rtol=1e-6)
    # the targets are the analytic derivatives of the (float64) states
    x = torch.tensor(np.concatenate([d["test_x"], d["x"]]), dtype=torch.float64)
    np.testing.assert_allclose(np.concatenate([d["test_dxdt"], d["dxdt"]]), data.dynamics(x).numpy(),
                               rtol=1e-4, atol=1e-5)
    again = data.get_dataset(seed=3, save_dir=tmp_path, num_trials=trials, num_points=points)
    assert capsys.readouterr().out == ""
    np.testing.assert_array_equal(again["x"], d["x"])
    other = data.get_dataset(seed=4, save_dir=tmp_path, num_trials=trials, num_points=points)
    assert "differs in seed (cached 3, requested 4)" in capsys.readouterr().out
    assert not np.allclose(other["x"], d["x"])
    with pytest.raises(TypeError, match="unknown dataset params"):
        data.get_dataset(save_dir=tmp_path, trials=5)


def _after(data, seed, draws):
    """A RandomState(seed) after ``draws`` calls of the task's sampler."""
    rng = np.random.RandomState(seed)
    for _ in range(draws):
        data.random_config(rng)
    return rng


def test_default_dataset_sizes(two, three):
    assert two.DEFAULTS["num_trials"] * two.DEFAULTS["num_points"] == 50000
    assert three.DEFAULTS["num_trials"] * three.DEFAULTS["num_points"] == 100000
    assert two.DEFAULTS["t_span"] == [0.0, 20.0] and three.DEFAULTS["t_span"] == [0.0, 5.0]
    assert two.DEFAULTS["test_split"] == three.DEFAULTS["test_split"] == 0.2


@pytest.mark.slow
@pytest.mark.parametrize("task, rows, test_rows", [("2body", 50000, 10000), ("3body", 100000, 20000)])
def test_full_datasets(task, rows, test_rows, tmp_path):
    data = hnn.load_task(task)
    d = data.get_dataset(seed=0, save_dir=tmp_path, min_separation=nbody.MIN_SEPARATION)
    assert len(d["x"]) + len(d["test_x"]) == rows and len(d["test_x"]) == test_rows
    assert d["resampled"] == d["resampled_close_encounter"] + d["resampled_failed"]
    assert d["resampled"] < 0.05 * rows / data.DEFAULTS["num_points"]         # 0 (2-body), ~3% (3-body)
    x = torch.tensor(np.concatenate([d["test_x"], d["x"]]), dtype=torch.float64)
    assert nbody.min_separation(x).min() >= nbody.MIN_SEPARATION * 0.99


# --------------------------------------------------------------------------- train.py

def test_train_flags_have_the_original_defaults():
    two = hnn.cli.parse(hnn.load_task("2body", "train").Config, [])
    three = hnn.cli.parse(hnn.load_task("3body", "train").Config, [])
    assert (two.input_dim, two.batch_size, two.total_steps, two.weight_decay, two.name) == (8, 200, 10000, 0.0, "2body")
    assert (three.input_dim, three.batch_size, three.total_steps, three.weight_decay, three.name) == (
        12, 600, 10000, 1e-4, "3body")
    assert two.input_noise == 0.0 and not hasattr(three, "input_noise")
    # the original kept close encounters; the cleaned dataset is opt-in
    assert two.min_separation == three.min_separation == 0.0
    assert hnn.load_task("2body").DEFAULTS["min_separation"] == hnn.load_task("3body").DEFAULTS["min_separation"] == 0.0
    assert hnn.cli.parse(hnn.load_task("2body", "train").Config, ["--input_noise", "0.05"]).input_noise == 0.05
