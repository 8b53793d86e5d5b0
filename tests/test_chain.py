"""The pendulum chain task (experiment-chain) and the peers' protocols on it, against analytic truths."""
import math

import numpy as np
import pytest
import torch

import hnn

data = hnn.load_task("chain")
protocols = hnn.load_task("chain", "protocols")


def _starts(chain, count=10, seed=0):
    return data.sample_chnn_starts(chain, count, torch.Generator().manual_seed(seed))


def test_true_chain_conserves_energy():
    chain = data.chnn_chain(3)
    x0 = chain.momenta(_starts(chain))
    t = 0.03 * np.arange(101)
    xs = hnn.rollout(chain.dynamics, x0, t, method="solve_ivp", scipy_method="DOP853", rtol=1e-12, atol=1e-12)
    H = chain.hamiltonian(xs.reshape(-1, 6)).reshape(len(x0), -1)
    assert xs.dtype == torch.float64
    assert ((H - H[:, :1]).abs() / H[:, :1].abs()).max() < 1e-9


def test_field_is_hamiltons_equations_of_h():
    chain = data.chnn_chain(5)
    x = chain.momenta(_starts(chain, 6)).requires_grad_(True)
    dH = torch.autograd.grad(chain.hamiltonian(x).sum(), x)[0]
    torch.testing.assert_close(chain.dynamics(x), torch.cat([dH[:, 5:], -dH[:, :5]], dim=1), rtol=0, atol=1e-12)


def test_one_bob_is_the_ideal_pendulum():
    m, length, g = 1.3, 0.7, 9.81
    chain = data.Chain((m,), (length,), g)
    x = torch.tensor([[0.3, -1.2], [2.5, 0.4], [-3.0, 2.0]], dtype=torch.float64)
    q, p = x[:, 0], x[:, 1]
    torch.testing.assert_close(chain.hamiltonian(x), p ** 2 / (2 * m * length ** 2) - m * g * length * torch.cos(q))
    torch.testing.assert_close(chain.dynamics(x), torch.stack([p / (m * length ** 2), -m * g * length * torch.sin(q)], 1))


def test_double_pendulum_matches_the_textbook_equations():
    """qddot of the canonical field against the classic closed form for two bobs (any m, l)."""
    chain = data.chnn_chain(2)
    (m1, m2), (l1, l2), g = chain.masses, chain.lengths, chain.g
    z = _starts(chain, 8)
    dz = chain.observed_dynamics(z)
    t1, t2, w1, w2 = z.T
    d = t1 - t2
    den = 2 * m1 + m2 - m2 * torch.cos(2 * d)
    a1 = (-g * (2 * m1 + m2) * torch.sin(t1) - m2 * g * torch.sin(t1 - 2 * t2)
          - 2 * torch.sin(d) * m2 * (w2 ** 2 * l2 + w1 ** 2 * l1 * torch.cos(d))) / (l1 * den)
    a2 = 2 * torch.sin(d) * (w1 ** 2 * l1 * (m1 + m2) + g * (m1 + m2) * torch.cos(t1)
                             + w2 ** 2 * l2 * m2 * torch.cos(d)) / (l2 * den)
    torch.testing.assert_close(dz[:, 2:], torch.stack([a1, a2], 1), rtol=1e-10, atol=1e-10)
    torch.testing.assert_close(dz[:, :2], z[:, 2:])


def test_cartesian_velocities_are_the_derivatives_of_positions():
    chain = data.chnn_chain(3)
    z = _starts(chain, 5)
    q, v = z[:, :3], z[:, 3:]
    _, dpos = torch.func.jvp(lambda q: chain.cartesian(torch.cat([q, v], 1))[:, 0], (q,), (v,))
    cart = chain.cartesian(z)
    torch.testing.assert_close(dpos, cart[:, 1])
    rods = torch.diff(torch.cat([torch.zeros_like(cart[:, 0, :1]), cart[:, 0]], 1), dim=1).norm(dim=-1)
    torch.testing.assert_close(rods, torch.tensor(chain.lengths, dtype=torch.float64).expand(5, 3))
    torch.testing.assert_close(chain.from_cartesian(cart), torch.cat([torch.remainder(q + np.pi, 2 * np.pi) - np.pi, v], 1))


def test_chnn_parameters_and_projection():
    draws = 0.6 + 0.8 * np.random.RandomState(0).rand(4)
    chain = data.chnn_chain(2)
    # their constructor pops from the ends: the pivot's bob gets the last mass drawn
    assert chain.masses == pytest.approx(draws[[1, 0]]) and chain.lengths == pytest.approx(draws[[3, 2]])
    assert data.chnn_chain(3, unit=True).masses == (1.0, 1.0, 1.0)
    assert data.lnn_double_pendulum().max_potential() == pytest.approx(29.4)
    cart = chain.cartesian(_starts(chain, 6))
    moved = chain.project(cart + 1e-3 * torch.randn(cart.shape, dtype=torch.float64))
    assert chain.constraints(moved).abs().max() < 1e-10
    assert (moved - cart).abs().max() < 1e-2       # a small perturbation is moved a small way back


# ------------------------------------------------------------------------------- the kinds

class _TrueMechanical(hnn.MechanicalHNN):
    """The mechanical HNN with the chain's M^-1 and V in place of its networks."""

    def __init__(self, chain):
        super().__init__(2 * chain.n, 8, eps=0.0)
        self.chain = chain

    def potential_and_factor(self, q):
        return self.chain.potential(q), torch.linalg.cholesky(torch.linalg.inv(self.chain.mass_matrix(q)))


def test_mechanical_hnn_with_the_true_m_and_v_is_the_true_field():
    chain = data.chnn_chain(3)
    model = _TrueMechanical(chain).double()
    z = _starts(chain, 7)
    x = chain.momenta(z)
    torch.testing.assert_close(model.time_derivative(x), chain.dynamics(x), rtol=1e-10, atol=1e-10)
    torch.testing.assert_close(model.state_from_observed(z), x)
    torch.testing.assert_close(model.observed_from_state(x), z)
    t = 0.03 * np.arange(11)
    torch.testing.assert_close(hnn.objectives.trajectory.rollout_observed(model, z, t, "velocity", rtol=1e-10, atol=1e-10),
                               data.trajectories(chain, z, t), rtol=1e-7, atol=1e-7)


def test_learned_mechanical_hnn_is_positive_definite_and_conserves_its_h():
    torch.manual_seed(1)
    model = hnn.MechanicalHNN(6, 32, periodic=True).double()
    x = 5 * torch.randn(50, 6, dtype=torch.float64)
    eigenvalues = torch.linalg.eigvalsh(model.inverse_mass(x[:, :3]))
    assert (eigenvalues >= model.eps * (1 - 1e-9)).all()
    x.requires_grad_(True)
    dH = torch.autograd.grad(model.hamiltonian(x).sum(), x)[0]
    assert (dH * model.time_derivative(x)).sum(1).abs().max() < 1e-12 * dH.norm(dim=1).pow(2).max()
    q_shift = x.detach() + torch.cat([torch.full((50, 3), 2 * np.pi, dtype=torch.float64), torch.zeros(50, 3, dtype=torch.float64)], 1)
    torch.testing.assert_close(model.hamiltonian(q_shift), model.hamiltonian(x.detach()))    # periodic in q


def test_second_order_node_moves_q_by_v():
    model = hnn.models.SecondOrderNODE(4, 16).double()
    z = torch.randn(9, 4, dtype=torch.float64)
    dz = model.time_derivative(z)
    assert torch.equal(dz[:, :2], z[:, 2:])
    torch.testing.assert_close(dz[:, 2:], model.acceleration(z))
    assert hnn.MODEL_KINDS["mechanical"].build(hnn.kinds.ModelSpec("mechanical", input_dim=4, hidden_dim=8)).n == 2
    second_order = hnn.kinds.ModelSpec("second_order", input_dim=4, hidden_dim=8, periodic=True)
    assert isinstance(hnn.MODEL_KINDS["second_order"].build(second_order), hnn.models.SecondOrderNODE)


def test_bad_input_is_refused_with_the_fix():
    for cls in (hnn.MechanicalHNN, hnn.models.SecondOrderNODE):
        for width in (3, 0, 2.0):
            with pytest.raises(ValueError, match="even width"):
                cls(width)
    with pytest.raises(ValueError, match="N >= 1"):
        data.chnn_chain(0)
    with pytest.raises(ValueError, match="N >= 1"):
        data.Chain((), ())
    with pytest.raises(ValueError, match="unknown objective 'energy'"):
        hnn.kinds.get_objective("energy")
    model = hnn.MechanicalHNN(4, 8)
    with pytest.raises(ValueError, match="shape \\(batch, 4\\)"):
        model.time_derivative(torch.zeros(3, 6))
    snippets = torch.zeros(2, 5, 4)
    with pytest.raises(ValueError, match="not separable; use method='rk4'"):
        hnn.objectives.trajectory.snippet_loss(model, snippets, 0.1, method="leapfrog")
    with pytest.raises(ValueError, match="fixed-step"):
        hnn.objectives.trajectory.snippet_loss(model, snippets, 0.1, method="dopri5")
    with pytest.raises(ValueError, match="unknown snippet loss"):
        hnn.objectives.trajectory.snippet_loss(model, snippets, 0.1, loss="huber")
    with pytest.raises(ValueError, match="needs the snippets' time step"):
        hnn.objectives.trajectory.TrajectoryObjective().loss_for(model)


# ----------------------------------------------------------------------- trajectory training

def test_separable_model_rolls_out_by_leapfrog_exactly_as_hnn_rollout():
    model = hnn.SeparableHNN(2, 8).double()
    z0 = torch.randn(4, 2, dtype=torch.float64)
    mine = hnn.objectives.trajectory.rollout_snippet(model, z0, 6, 0.05)
    theirs = hnn.rollout(model.time_derivative, z0, 0.05 * np.arange(6), method="leapfrog")
    torch.testing.assert_close(mine, theirs)
    paths = torch.arange(2 * 100 * 3, dtype=torch.float64).reshape(2, 100, 3)
    cut = hnn.objectives.trajectory.sample_snippets(paths, 5, torch.Generator().manual_seed(0))
    assert cut.shape == (2, 5, 3) and (cut[:, 0, 0] % 15 == 0).all()        # starts on a 5-state boundary
    torch.testing.assert_close(torch.diff(cut[..., 0], dim=1), torch.full((2, 4), 3.0, dtype=torch.float64))


# ------------------------------------------------------------------------------ the metrics

def _expected_geometric_mean(errors, dt, T):
    """exp((1/T) trapezoid of log(e + 1e-8)), summed by hand."""
    logs = [math.log(e + 1e-8) for e in errors]
    return math.exp(dt * (sum(logs) - (logs[0] + logs[-1]) / 2) / T)


def test_chnn_metric_on_a_detuned_rotation():
    """One bob spinning freely (g = 0) at omega; the 'model' spins at omega (1 + delta)."""
    omega, delta, length, dt = 2.0, 1e-3, 1.3, 0.03
    chain = data.Chain((1.0,), (length,), g=0.0)
    t = dt * np.arange(100)
    truth = torch.tensor(np.stack([omega * t, np.full_like(t, omega)], -1))[None]
    w2 = omega * (1 + delta)
    pred = torch.tensor(np.stack([w2 * t, np.full_like(t, w2)], -1))[None]
    # |z^ - z|^2: positions 2 l^2 (1 - cos d), velocities l^2 (w^2 + w2^2 - 2 w w2 cos d), d = (w2 - w) t
    e = [math.sqrt(2 * length ** 2 * (1 - math.cos(d)) + length ** 2 * (omega ** 2 + w2 ** 2 - 2 * omega * w2 * math.cos(d)))
         / (length * math.sqrt(1 + w2 ** 2) + length * math.sqrt(1 + omega ** 2)) for d in (w2 - omega) * t]
    got = protocols.rollout_error(chain, pred, truth)
    assert got.shape == (1,)
    assert got[0] == pytest.approx(_expected_geometric_mean(e, dt, 3.0), rel=1e-9)
    # free flight conserves omega: the chain's own field agrees with the analytic truth
    torch.testing.assert_close(data.trajectories(chain, truth[:, 0], t), truth, rtol=1e-8, atol=1e-8)
    assert protocols.summary([1.0, 2.0, 9.0]) == {"mean": 4.0, "median": 2.0, "n": 3}


def test_relative_error_denominators():
    """A planar vector of norm r turned by phi: |a - b| / (|a| + |b|) = sin(phi / 2); / |a + b| = tan(phi / 2)."""
    phi = torch.linspace(0, 1, 7, dtype=torch.float64)
    true = 2.5 * torch.stack([torch.ones_like(phi), torch.zeros_like(phi)], -1)[None]
    pred = 2.5 * torch.stack([torch.cos(phi), torch.sin(phi)], -1)[None]
    torch.testing.assert_close(protocols.relative_errors(pred, true), torch.sin(phi / 2)[None])
    torch.testing.assert_close(protocols.relative_errors(pred, true, "sum"), torch.tan(phi / 2)[None])
    with pytest.raises(ValueError, match="unknown denominator"):
        protocols.relative_errors(pred, true, "max")


def test_chaos_floor_of_one_bob_is_near_the_published_one():
    chain = data.chnn_chain(1)
    floor = protocols.summary(protocols.chaos_floor(chain, protocols.chnn_test_starts(chain)))
    published, published_median = protocols.CHNN_PUBLISHED[1]["floor"]
    # other random perturbations of other starts: the same law, so within a factor 2
    assert published / 2 < floor["mean"] < 2 * published
    assert published_median / 2 < floor["median"] < 2 * published_median


def test_lnn_energy_error():
    chain = data.lnn_double_pendulum()
    z = data.sample_lnn_starts(5, torch.Generator().manual_seed(0), train=False)
    assert (z[:, 2:] >= 0).all() and (z[:, 2:] <= 0.1).all() and (z[:, :2] <= 2 * np.pi).all()
    assert np.all(protocols.energy_error(chain, z, z) == 0)
    # one bob raised: V changes by g m (l1 cos q1 - ...) computed by hand for the hanging chain
    hanging = torch.zeros(1, 4, dtype=torch.float64)
    raised = torch.tensor([[np.pi / 2, 0.0, 0.0, 0.0]], dtype=torch.float64)     # rod 1 horizontal
    assert protocols.energy_error(chain, raised, hanging)[0] == pytest.approx(2 * 9.8 / 29.4)
    assert len(protocols.lnn_times()) == 1000 and protocols.lnn_times()[-1] == 100.0


# ------------------------------------------------------------------------------ the task folder

def test_chain_task_trains_every_kind_and_reloads(tmp_path):
    """experiment-chain/train.py: CHNN's paths (their d/dt is the paths' slope), every kind by
    --model, the angle embedding saved with the run; the chain is not one of the paper's tasks."""
    main = hnn.load_task("chain", "train").main
    common = ["--bobs", "2", "--n_train", "6", "--n_test", "3", "--total_steps", "3", "--hidden_dim", "16",
              "--save_dir", str(tmp_path)]
    dataset = data.get_dataset(bobs=2, n_train=6, n_test=3, dt=0.003, save_dir=tmp_path)
    paths, slopes = dataset["x"].reshape(6, 100, 4), dataset["dxdt"].reshape(6, 100, 4)
    # the five-point central difference, O(dt^4): at dt = 0.03 it is off by 0.07 (fast swings), at 0.003 by 1e-5
    central = (-paths[:, 4:] + 8 * paths[:, 3:-1] - 8 * paths[:, 1:-3] + paths[:, :-4]) / (12 * dataset["dt"])
    np.testing.assert_allclose(central, slopes[:, 2:-2], atol=1e-5 * np.abs(slopes).max())
    for model in ("mechanical", "second_order", "hnn", "baseline"):
        run = main(common + ["--model", model])
        loaded, args, metrics = hnn.load_run(run)
        assert args["objective"] == "trajectory" and args["input_dim"] == 4 and np.isfinite(metrics["test_loss"])
        assert getattr(loaded, "periodic", True)
    assert "chain" not in hnn.tasks.paper_tasks() and not hnn.task_spec("chain").in_paper
    run = main(common + ["--model", "mechanical", "--objective", "derivative"])     # through its mass matrix
    assert np.isfinite(hnn.load_run(run)[2]["test_loss"])
    with pytest.raises(ValueError, match="cannot be fit to states in 'canonical' coordinates.*choose another --model"):
        hnn.load_task("spring", "train").main(["--model", "second_order", "--total_steps", "1", "--save_dir", str(tmp_path)])
    with pytest.raises(ValueError, match="the LNN protocol is the double pendulum"):
        data.get_dataset(bobs=3, protocol="lnn", save_dir=tmp_path)


def test_mechanical_hnn_with_the_true_m_and_v_gives_the_observed_accelerations():
    """d/dt [q, qdot] through the model's own mass matrix is the chain's (qdot, qddot), and the
    derivative objective trains a learned mechanical HNN on it (its loss falls)."""
    chain = data.chnn_chain(3)
    z = _starts(chain, 7)
    torch.testing.assert_close(_TrueMechanical(chain).double().observed_time_derivative(z),
                               chain.observed_dynamics(z), rtol=1e-10, atol=1e-10)
    with torch.no_grad():
        assert not _TrueMechanical(chain).double().observed_time_derivative(z).requires_grad
    z = _starts(chain, 64)
    model = hnn.MechanicalHNN(6, 32, periodic=True).double()
    options = hnn.DerivativeObjective().train_options(model, hnn.specs.ObjectiveSpec(), {"state": "velocity"})
    stats = hnn.train(model, z, chain.observed_dynamics(z), total_steps=60, learn_rate=1e-2, progress=False,
                      **options.train_kwargs())
    assert stats["train_loss"][-1] < 0.5 * stats["train_loss"][0]
