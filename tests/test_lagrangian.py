"""The LNN kind against truths: with the true L of a pendulum and of a chain its Euler-Lagrange
acceleration is the chain's closed-form dynamics (an independent derivation through the mass
matrix and Hamilton's equations), its energy is the true one, its own energy is conserved along its
flow for random weights, and a degenerate L is one clear error naming the states."""
import json

import numpy as np
import pytest
import torch

import hnn

chain_data = hnn.load_task("chain")


class _BobsL(hnn.models.LagrangianNN):
    """The true L = T - V of ``chain``, written from the bobs' Cartesian positions (not its mass matrix)."""

    def __init__(self, chain):
        super().__init__(2 * chain.n, hidden_dim=4)
        self.chain = chain

    def lagrangian_at(self, q, v):
        m = torch.tensor(self.chain.masses, dtype=q.dtype)
        lengths = torch.tensor(self.chain.lengths, dtype=q.dtype)
        height = (-lengths * torch.cos(q)).cumsum(0)          # bob k hangs below the pivot by sum_j<=k l_j cos q_j
        vx, vy = (lengths * torch.cos(q) * v).cumsum(0), (lengths * torch.sin(q) * v).cumsum(0)
        return 0.5 * (m * (vx ** 2 + vy ** 2)).sum() - self.chain.g * (m * height).sum()


@pytest.mark.parametrize("chain", [chain_data.Chain((1.0,), (1.0,), 9.8), chain_data.lnn_double_pendulum(),
                                   chain_data.chnn_chain(3)], ids=["pendulum", "lnn-double-pendulum", "chnn-chain3"])
def test_with_the_true_l_the_acceleration_and_energy_are_the_true_ones(chain):
    model = _BobsL(chain).double()
    gen = torch.Generator().manual_seed(0)
    z = torch.cat([torch.rand(16, chain.n, generator=gen, dtype=torch.float64) * 6 - 3,
                   torch.randn(16, chain.n, generator=gen, dtype=torch.float64)], 1)
    with torch.no_grad():
        truth = chain.observed_dynamics(z)
    torch.testing.assert_close(model.time_derivative(z), truth, rtol=1e-10, atol=1e-10)
    torch.testing.assert_close(model.energy(z).detach(), chain.energy(z), rtol=1e-12, atol=1e-12)


def test_its_energy_is_conserved_along_its_flow_for_random_weights():
    torch.manual_seed(1)
    model = hnn.models.LagrangianNN(4, hidden_dim=32).double()
    # a black-box L has no guaranteed kinetic term: this seed's flow stays regular over [0, 0.3] from
    # these starts (other seeds reach states where d2L/dqdot2 is singular and the accelerations blow up)
    z0 = 0.3 * torch.randn(4, 4, dtype=torch.float64)
    t = np.linspace(0.0, 0.3, 2)
    drift = {}
    for method, options in (("dop853", {"rtol": 1e-11, "atol": 1e-11}), ("rk4", {"dt": 0.03})):
        traj = hnn.rollout(model, z0, t, method=method, **options)
        E = model.energy(traj.reshape(-1, 4)).reshape(4, -1).detach()
        drift[method] = float((E - E[:, :1]).abs().max())
    assert traj[:, -1].sub(z0).abs().max() > 0.5          # it moved (|E| <= 0.65 here)
    # measured: 1.2e-13 at rtol 1e-11; rk4 at dt 0.03 (order 4, not conservative) 3.7e-6
    assert drift["dop853"] < 1e-10 and drift["rk4"] > 1e3 * drift["dop853"], drift


class _LinearInV(hnn.models.LagrangianNN):        # L = qdot cos q - V: d2L/dqdot2 = 0 everywhere
    def lagrangian_at(self, q, v):
        return (v * torch.cos(q)).sum() - torch.cos(q).sum()


class _NoKinetic(hnn.models.LagrangianNN):        # L = -V(q): no qdot at all, so no autograd path to it
    def lagrangian_at(self, q, v):
        return -torch.cos(q).sum()


@pytest.mark.parametrize("degenerate", [_LinearInV, _NoKinetic], ids=["linear-in-qdot", "no-qdot"])
def test_a_degenerate_l_is_an_error_naming_the_states(degenerate):
    z = torch.tensor([[0.1, 0.2], [0.3, -0.4]], dtype=torch.float64)
    with pytest.raises(hnn.models.SingularLagrangianError, match=r"singular at 2 states.*#0 \[q, qdot\] = \[0\.1, 0\.2\]") as err:
        degenerate(2, 4).double().time_derivative(z)
    assert err.value.states == [0, 1]


@pytest.mark.parametrize("n", [1, 2, 5])
def test_the_batched_acceleration_is_each_states_own_euler_lagrange_solve(n):
    """The batched autograd passes against torch.func's per-state Hessian of the same network L,
    solved state by state: a batch's rows must not mix, in value or in the weights' gradient."""
    torch.manual_seed(n)
    model = hnn.models.LagrangianNN(2 * n, hidden_dim=16, nonlinearity="softplus", periodic=True).double()
    z = torch.cat([torch.rand(6, n, dtype=torch.float64) * 6, torch.randn(6, n, dtype=torch.float64)], 1)

    def per_state(state):
        hess = torch.func.hessian(lambda s: model.lagrangian_at(s[:n], s[n:]))(state)
        dL = torch.func.grad(lambda s: model.lagrangian_at(s[:n], s[n:]))(state)
        return torch.linalg.solve(hess[n:, n:], dL[:n] - hess[n:, :n] @ state[n:])

    truth = torch.stack([per_state(state) for state in z])
    ours = model.acceleration(z)
    torch.testing.assert_close(ours, truth, rtol=1e-10, atol=1e-10)
    weight = model.net.linear2.weight
    g_ours, = torch.autograd.grad(ours.pow(2).sum(), weight)
    g_truth, = torch.autograd.grad(truth.pow(2).sum(), weight)
    torch.testing.assert_close(g_ours, g_truth, rtol=1e-9, atol=1e-9)
    with torch.no_grad():                                   # a rollout's call: same numbers, no graph
        quiet = model.acceleration(z)
    assert not quiet.requires_grad
    torch.testing.assert_close(quiet, truth.detach(), rtol=1e-10, atol=1e-10)


def test_it_reads_observed_velocities_and_no_solver_steps_its_energy_as_an_h():
    model = hnn.kinds.model_from_args({"kind": "lagrangian", "input_dim": 4, "hidden_dim": 8, "nonlinearity": "tanh",
                                       "periodic": True, "dtype": "float64"})
    assert model.relation("velocity") == "own" and hnn.MODEL_KINDS["lagrangian"].conservative
    with pytest.raises(ValueError, match="cannot be fit to states in 'canonical'"):
        model.relation("canonical")
    with pytest.raises(ValueError, match="needs the field's H"):
        hnn.rollout(model, torch.zeros(1, 4, dtype=torch.float64), [0.0, 0.1], method="discrete_gradient")
    # periodic: L sees (cos q, sin q), so the field is 2 pi-periodic in q
    z = torch.randn(5, 4, dtype=torch.float64)
    shifted = z + torch.tensor([2 * np.pi, -2 * np.pi, 0.0, 0.0], dtype=torch.float64)
    torch.testing.assert_close(model.time_derivative(shifted), model.time_derivative(z), rtol=1e-9, atol=1e-9)


def _lnn(init: str, n: int, seed: int):
    torch.manual_seed(seed)
    return hnn.kinds.model_from_args({"kind": "lagrangian", "input_dim": 2 * n, "hidden_dim": 64,
                                      "nonlinearity": "softplus", "periodic": True, "init": init})


def _velocity_hessians(model, states, n):
    """d2L/dqdot2 ``(batch, n, n)`` at ``states`` ``(batch, 2n)``, state by state."""
    return torch.func.vmap(lambda s: torch.func.hessian(lambda v: model.lagrangian_at(s[:n], v))(s[n:]))(states)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_convex_init_starts_with_a_positive_definite_d2l_dqdot2(seed):
    """'lnn_convex': softplus is convex and nondecreasing, and every weight after the first layer is
    nonnegative, so L is convex in its input and d2L/dqdot2 is positive semidefinite at every state
    (a convexity theorem, checked here on random states by the Hessian's eigenvalues)."""
    n = 3
    model = _lnn("lnn_convex", n, seed).double()
    states = torch.cat([torch.rand(64, n, dtype=torch.float64) * 2 * np.pi,
                        torch.randn(64, n, dtype=torch.float64) * 5], 1)
    eig = torch.linalg.eigvalsh(_velocity_hessians(model, states, n))
    assert (eig[:, 0] >= -1e-10 * eig[:, -1].abs()).all()
    # the LNN's own init, the same draw without the absolute values, is indefinite somewhere
    plain = _lnn("lnn", n, seed).double()
    assert (torch.linalg.eigvalsh(_velocity_hessians(plain, states, n))[:, 0] < 0).any()


@pytest.mark.parametrize("bobs", [1, 3, pytest.param(5, marks=pytest.mark.slow)])
def test_the_convex_init_takes_its_first_steps_on_chnns_chains(bobs, tmp_path):
    """CHNN's protocol (RK4 through 4-step snippets, softplus, the LNN's learning rate): from
    'lnn_convex' two seeds each take two training steps with a finite loss, where the LNN's init
    failed at step 0 or 1 (SingularLagrangianError or a diverged snippet: docs/stress.md)."""
    for seed in range(2):
        config = hnn.tasks.task_config("chain", {"bobs": bobs, "model": "lagrangian", "nonlinearity": "softplus",
                                                 "learn_rate": 1e-3, "init": "lnn_convex", "hidden_dim": 64,
                                                 "n_train": 4, "n_test": 2, "batch_size": 40, "total_steps": 1,
                                                 "seed": seed, "save_dir": str(tmp_path)})
        metrics = json.loads((hnn.run_experiment(config) / "metrics.json").read_text())
        assert np.isfinite(metrics["train_loss"]) and np.isfinite(metrics["test_loss"])


class _VanishingMass(hnn.models.LagrangianNN):     # L = q^2 qdot^2 / 2 - q^2 / 2: d2L/dqdot2 = q^2, 0 at q = 0
    def lagrangian_at(self, q, v):
        return (q ** 2 * v ** 2).sum() / 2 - (q ** 2).sum() / 2


def test_the_pseudo_inverse_solve_is_the_plain_one_where_d2l_dqdot2_is_invertible_and_goes_on_where_not():
    """A known L whose kinetic term vanishes at q = 0 (d2L/dqdot2 = q^2): off q = 0 both solves give the
    Euler-Lagrange qddot = -(qdot^2 + 1) / q in closed form; at q = 0 the plain solve stops naming the state,
    the LNN authors' pseudo-inverse gives its minimum-norm qddot, 0 (pinv of a zero matrix), and counts it."""
    z = torch.tensor([[0.5, 0.3], [-1.2, 2.0], [0.0, 0.7], [2.0, -1.0]], dtype=torch.float64)
    exact = -(z[:, 1] ** 2 + 1) / z[:, 0]
    plain, pinv = _VanishingMass(2, 4).double(), _VanishingMass(2, 4, solve="pinv").double()
    with pytest.raises(hnn.models.SingularLagrangianError, match=r"singular at 1 states.*#2") as err:
        plain.acceleration(z)
    assert err.value.states == [2]
    keep = [0, 1, 3]
    torch.testing.assert_close(plain.acceleration(z[keep])[:, 0], exact[keep], rtol=1e-12, atol=0)
    got = pinv.acceleration(z)[:, 0]
    torch.testing.assert_close(got[keep], exact[keep], rtol=1e-12, atol=0)
    assert got[2].item() == 0.0 and pinv.pinv_states == 1
    with pytest.raises(ValueError, match="solve='lu': choose one of solve, pinv"):
        hnn.models.LagrangianNN(2, 4, solve="lu")


@pytest.mark.parametrize("n", [1, 2, 5])
def test_the_two_solves_agree_where_d2l_dqdot2_is_well_conditioned(n):
    """A network L from the convex init (d2L/dqdot2 positive definite at these states): the pseudo-inverse
    solve's qddot, its weights' gradient and a few training steps are the plain solve's, to the float64
    digit (the pseudo-inverse is the inverse where every singular value lies above its cutoff, and there
    the same LU solve is taken); no state is counted."""
    states = torch.cat([torch.rand(32, n, dtype=torch.float64) * 6, torch.randn(32, n, dtype=torch.float64)], 1)
    models = []
    for solve in ("solve", "pinv"):
        torch.manual_seed(n)
        models.append(hnn.kinds.model_from_args({"kind": "lagrangian", "input_dim": 2 * n, "hidden_dim": 32,
                                                 "nonlinearity": "softplus", "periodic": True, "init": "lnn_convex",
                                                 "dtype": "float64", "lnn_solve": solve}))
    plain, pinv = models
    assert torch.linalg.cond(_velocity_hessians(plain, states, n)).max() < 1e6
    a, b = plain.acceleration(states), pinv.acceleration(states)
    torch.testing.assert_close(b, a, rtol=0, atol=0)
    g_plain, = torch.autograd.grad(a.pow(2).sum(), plain.net.linear2.weight)
    g_pinv, = torch.autograd.grad(b.pow(2).sum(), pinv.net.linear2.weight)
    torch.testing.assert_close(g_pinv, g_plain, rtol=0, atol=0)
    target = plain.time_derivative(states).detach() * 0.9
    losses = [hnn.train(m, states, target, total_steps=3, progress=False)["train_loss"] for m in models]
    assert losses[0] == losses[1] and pinv.pinv_states == 0


# ----------------------------------------------------------------------------------------------
# the singular verdict in any units: the same physics, L in other units of energy, of time or of one q_i


_MASS = torch.tensor([[2.0, 0.5], [0.5, 1.0]], dtype=torch.float64)        # condition 2.1 (its scaled form 2.1)
_SPRING = torch.tensor([[3.0, -1.0], [-1.0, 2.0]], dtype=torch.float64)


class _CoupledL(hnn.models.LagrangianNN):
    """L' = c (v'^T S M S v' - q'^T S K S q') / 2: two coupled oscillators (L = (v^T M v - q^T K q) / 2) in units
    where q = S q' (S = diag(1, d): the second position in units d of the first's) and c units of L; with
    ``w`` instead, a rank-one kinetic term c cosh(w . S v'), whose d2L/dqdot2 is singular everywhere."""

    def __init__(self, c: float, d: float, w=None):
        super().__init__(4, hidden_dim=4)
        self.c, self.s, self.w = c, torch.tensor([1.0, d], dtype=torch.float64), w

    def lagrangian_at(self, q, v):
        s = self.s.to(q.dtype)
        q, v = s * q, s * v
        kinetic = torch.cosh(v @ self.w.to(q.dtype)) if self.w is not None else v @ _MASS.to(q.dtype) @ v / 2
        return self.c * (kinetic - q @ _SPRING.to(q.dtype) @ q / 2)


# a second position in units 1e-4 (float32) or 1e-8 (float64) of the first's puts d2L/dqdot2's own condition
# number (2e8, 2e16) past 1 / eps, the verdict's bound before it was scaled; c from tiny to huge energy units
_UNITS = {torch.float32: [(1.0, 1.0), (1e-12, 1.0), (1e12, 1.0), (1.0, 1e-4), (1e-12, 1e-4), (1e12, 1e-4)],
          torch.float64: [(1.0, 1.0), (1e-30, 1.0), (1e30, 1.0), (1.0, 1e-8), (1e-30, 1e-8), (1e30, 1e-8)]}
_CASES = [pytest.param(dtype, c, d, id=f"{str(dtype)[6:]}-c{c:g}-d{d:g}") for dtype, units in _UNITS.items()
          for c, d in units]


def _states(d: float, dtype) -> torch.Tensor:
    """Eight states [q', qdot'] in the units of ``_CoupledL(c, d)``: physical states q, v of size 1 over S."""
    z = torch.randn(8, 4, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return (z / torch.tensor([1.0, d, 1.0, d], dtype=torch.float64)).to(dtype)


@pytest.mark.parametrize("dtype, c, d", _CASES)
def test_a_well_conditioned_l_is_solved_in_any_units_and_its_qddot_is_the_physics(dtype, c, d):
    z = _states(d, dtype)
    qddot = _CoupledL(c, d).to(dtype).acceleration(z).double()       # no SingularLagrangianError
    # the same physics: S qddot' = -M^-1 K q of the physical q = S q'
    s = torch.tensor([1.0, d], dtype=torch.float64)
    truth = -(torch.linalg.solve(_MASS, _SPRING) @ (s * z[:, :2].double()).T).T
    # the rounding: each entry of d2L/dqdot2 and of the right side is a product c s_i s_j M_ij of 3 roundings
    # summed over 2 terms (4 eps), the LU solve's backward error 2n eps (4 eps), amplified by the scaled matrix's
    # condition number 2.1: about 2.1 (4 + 4 + 4) = 25 eps, held to 32 (measured: at most 2.0 eps)
    err = (s * qddot - truth).norm(dim=1) / truth.norm(dim=1)
    assert err.max() < 32 * torch.finfo(dtype).eps, err.max()


@pytest.mark.parametrize("dtype, c, d", _CASES)
def test_a_singular_l_is_flagged_at_every_state_in_any_units(dtype, c, d):
    w = torch.tensor([0.7, -1.3], dtype=torch.float64)      # not powers of 2: its Hessian c cosh w w^T is rounded
    with pytest.raises(hnn.models.SingularLagrangianError) as err:
        _CoupledL(c, d, w).to(dtype).acceleration(_states(d, dtype))
    assert err.value.states == list(range(8))


class _NotFinite(hnn.models.LagrangianNN):      # L = log(q) qdot^2 / 2: nan where q < 0, every derivative with it
    def lagrangian_at(self, q, v):
        return (torch.log(q) * v ** 2).sum() / 2


@pytest.mark.parametrize("solve", ["solve", "pinv"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_non_finite_d2l_dqdot2_is_the_singular_error_not_the_svds(dtype, solve):
    z = torch.tensor([[1.5, 2.0, 0.3, 0.1], [-1.0, 2.0, 0.2, 0.4]], dtype=dtype)      # the second state: q < 0
    with pytest.raises(hnn.models.SingularLagrangianError) as err:
        _NotFinite(4, 4, solve=solve).to(dtype).acceleration(z)
    assert err.value.states == [1]
