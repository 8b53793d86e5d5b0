"""Newtonian gravity of B bodies in the plane, and the batched generator of orbit datasets.

Units: G = 1 and every mass is 1, so momentum = velocity. A state is one row of width 4B in the
canonical ordering of the original code (docs/original.md),

    x = [qx_1..qx_B, qy_1..qy_B, px_1..px_B, py_1..py_B],

so the first half is q and the second half p, matching the HNN's M = [[0, I], [-I, 0]]. Every
physics function takes a torch tensor of shape ``(..., 4B)`` (usually ``(batch, 4B)``, float64)
and infers B from the width. There is no softening by default: forces are exactly 1/r^2.

Up to ``DENSE_BODIES`` bodies the pair sums are products with a dense incidence matrix ``(B, pairs)``
(every dataset of the orbit tasks); past it that matrix would not fit (B = 4096: 275 GB), so the sums
run over blocks of bodies, each block's rows against every body, within ``BLOCK_BYTES`` a block:
O(B^2) work and memory of a block, any B. A call that cannot fit even one body's row of pairs
raises ``hnn.models.pair.TooManyPairsError`` saying how much it needs.

The generator (``sample_orbits``) integrates all trajectories in one batched ``hnn.rollout``
call (or a few large chunks) and redraws close encounters and failed integrations; the dataset
builder (``orbit_dataset``) turns orbits into training rows, cached by ``hnn.cache`` in an
``.npz`` keyed by a hash of all its parameters.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..errors import DivergenceError
from ..models.pair import PAIR_BYTES, TooManyPairsError
from .encounters import MIN_SEPARATION, TASK_MIN_SEPARATION  # noqa: F401  (the tasks read both here)
from ..integrators.integrate import rollout
from ..cache import get_cached_dataset


DATASET_VERSION = 1   # bump when the generator changes what a given set of params produces
DENSE_BODIES = 64     # up to this many bodies the pair sums use the incidence matrix (64 x 2016: 1 MB)
# past it, the pair arrays of one block of bodies stay within this: 4 MB blocks stay in cache (4 states of 4096
# bodies: 2.0 s a call against 5.4 s with 256 MB blocks, one thread, loaded 2-core box)
BLOCK_BYTES = 2 ** 22
# numbers per (state, body, body) that a block holds at once, at most: dx, dy, r^2 (and a square's temporary), its
# inverse cube, a product
_BLOCK_ARRAYS = 6


# --------------------------------------------------------------------------- physics

def num_bodies(x: torch.Tensor) -> int:
    width = x.shape[-1]
    if width < 4 or width % 4:
        raise ValueError(f"an n-body state has width 4B (B bodies), got width {width}")
    return width // 4


def _positions(x: torch.Tensor) -> torch.Tensor:
    """``(..., B, 2)`` positions of ``(..., 4B)`` states."""
    b = num_bodies(x)
    return torch.stack([x[..., :b], x[..., b:2 * b]], dim=-1)


def _momenta(x: torch.Tensor) -> torch.Tensor:
    """``(..., B, 2)`` momenta (= velocities) of ``(..., 4B)`` states."""
    b = num_bodies(x)
    return torch.stack([x[..., 2 * b:3 * b], x[..., 3 * b:]], dim=-1)


@functools.lru_cache(maxsize=None)
def _incidence(b: int, dtype: torch.dtype, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """``D`` ``(B, pairs)`` with -1 at body i and +1 at body j of each pair i < j, and ``-D^T``.

    ``q @ D`` gives every pairwise difference q_j - q_i in one product, and ``f @ -D^T`` adds each
    pair's pull f to body i and its reaction -f to body j (each entry is exact: +-1 or 0).
    """
    i, j = torch.triu_indices(b, b, offset=1, device="cpu")
    i, j = i.to(device), j.to(device)
    pair = torch.arange(len(i), device=device)
    d = torch.zeros(b, len(i), dtype=dtype, device=device)
    d[i, pair], d[j, pair] = -1.0, 1.0
    return d, (-d.T).contiguous()


def _pair_differences(x: torch.Tensor) -> torch.Tensor:
    """``(..., 2, pairs)``: x and y components of q_j - q_i over the pairs i < j."""
    b = num_bodies(x)
    d, _ = _incidence(b, x.dtype, x.device)
    return x[..., :2 * b].reshape(*x.shape[:-1], 2, b) @ d


def _pair_distances(x: torch.Tensor) -> torch.Tensor:
    """``(..., B(B-1)/2)`` distances |q_j - q_i| over the pairs i < j."""
    return _pair_differences(x).pow(2).sum(-2).sqrt()


def _blocks(x: torch.Tensor):
    """For ``(n, 4B)`` states past ``DENSE_BODIES``: ``(rows, dx, dy, r2)`` per block of bodies ``rows`` (a slice):
    ``dx``, ``dy`` ``(n, c, B)`` the components of q_j - q_i of each body i of the block against every body j,
    ``r2`` their squared length, inf where j = i (no self pair). ``TooManyPairsError`` if one body's row of pairs
    passes ``PAIR_BYTES``."""
    n, b = x.shape[0], num_bodies(x)
    per_row = _BLOCK_ARRAYS * n * b * x.element_size()
    if per_row > PAIR_BYTES:
        raise TooManyPairsError(
            f"{n} states of {b} bodies need about {per_row / 2 ** 30:.3g} GiB for one body's pairs in one gravity "
            f"call (limit hnn.models.pair.PAIR_BYTES = {PAIR_BYTES / 2 ** 30:.3g} GiB): evaluate fewer states at once")
    size = int(min(b, max(1, BLOCK_BYTES // per_row)))
    qx, qy = x[:, :b], x[:, b:2 * b]
    for start in range(0, b, size):
        rows = slice(start, min(b, start + size))
        dx = qx[:, None, :] - qx[:, rows, None]                             # (n, c, B): x_j - x_i
        dy = qy[:, None, :] - qy[:, rows, None]
        r2 = dx * dx + dy * dy
        own = torch.arange(rows.start, rows.stop, device=x.device)
        r2[:, own - rows.start, own] = math.inf                              # no body pulls itself
        yield rows, dx, dy, r2


def _field(x: torch.Tensor, softening: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """dx/dt of ``(n, 4B)`` states, and each state's smallest squared pair distance ``(n,)`` (inf for one body).

    a_i = sum_{j != i} (q_j - q_i) / (|q_j - q_i|^2 + softening^2)^(3/2) (G = 1, unit masses; the tasks'
    softening is 0, the original's); a few whole-batch operations, since the batched integrator calls this
    once per stage.
    """
    n, b = x.shape[0], num_bodies(x)
    if b > DENSE_BODIES:
        return _blocked_field(x, softening)
    d, minus_dt = _incidence(b, x.dtype, x.device)
    diff = x[:, :2 * b].reshape(n, 2, b) @ d               # (n, 2, pairs)
    r2 = (diff * diff).sum(1)                              # (n, pairs)
    soft = r2 + softening ** 2 if softening else r2        # exactly the unsoftened arithmetic at 0
    accel = (diff * soft.pow(-1.5).unsqueeze(1)) @ minus_dt  # (n, 2, B): [ax_1..ax_B], [ay_1..ay_B]
    nearest = r2.amin(dim=1) if r2.shape[1] else torch.full((n,), math.inf, dtype=x.dtype, device=x.device)
    return torch.cat([x[:, 2 * b:], accel.reshape(n, 2 * b)], dim=1), nearest


def _blocked_field(x: torch.Tensor, softening: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``_field`` past ``DENSE_BODIES``, block by block of bodies (``_blocks``): O(B^2) work, a block's memory."""
    n, b = x.shape[0], num_bodies(x)
    accel = x.new_empty(n, 2, b)
    nearest = torch.full((n,), math.inf, dtype=x.dtype, device=x.device)
    for rows, dx, dy, r2 in _blocks(x):
        nearest = torch.minimum(nearest, r2.amin(dim=(1, 2)))
        inverse = (r2 + softening ** 2 if softening else r2).rsqrt_()        # the self term: 1 / sqrt(inf) = 0
        cube = inverse.mul_(inverse * inverse)
        accel[:, 0, rows], accel[:, 1, rows] = (dx * cube).sum(-1), (dy * cube).sum(-1)
    return torch.cat([x[:, 2 * b:], accel.reshape(n, 2 * b)], dim=1), nearest


def dynamics(x: torch.Tensor, softening: float = 0.0) -> torch.Tensor:
    """Hamilton's equations ``(..., 4B) -> (..., 4B)``: dq/dt = p, dp/dt = the gravitational acceleration
    (Plummer-softened by ``softening``, a length: the potential -1 / sqrt(r^2 + softening^2))."""
    dxdt, _ = _field(x.reshape(-1, x.shape[-1]), softening)
    return dxdt.reshape(x.shape)


def kinetic_energy(x: torch.Tensor) -> torch.Tensor:
    """sum_i |p_i|^2 / 2, shape ``(...)``."""
    return 0.5 * (x[..., 2 * num_bodies(x):] ** 2).sum(-1)


def potential_energy(x: torch.Tensor, softening: float = 0.0) -> torch.Tensor:
    """-sum over all pairs i < j of 1 / |q_i - q_j| (1 / sqrt(|q_i - q_j|^2 + softening^2) where softened),
    shape ``(...)`` (correct for any B, unlike the original 2-body file, which added only the last pair)."""
    if num_bodies(x) > DENSE_BODIES:
        flat = x.reshape(-1, x.shape[-1])
        # each pair twice (i's row and j's), halved; the self terms are 1 / sqrt(inf) = 0
        total = sum((r2 + softening ** 2).rsqrt().sum(dim=(1, 2)) for *_, r2 in _blocks(flat))
        return -(total / 2).reshape(x.shape[:-1])
    if softening:
        return -(_pair_differences(x).pow(2).sum(-2) + softening ** 2).rsqrt().sum(-1)
    return -(1.0 / _pair_distances(x)).sum(-1)


def hamiltonian(x: torch.Tensor, softening: float = 0.0) -> torch.Tensor:
    """The total energy H = kinetic + potential (softened by ``softening``), shape ``(...)``."""
    return kinetic_energy(x) + potential_energy(x, softening)


def total_momentum(x: torch.Tensor) -> torch.Tensor:
    """sum_i p_i, shape ``(..., 2)``."""
    return _momenta(x).sum(-2)


def angular_momentum(x: torch.Tensor) -> torch.Tensor:
    """sum_i q_i x p_i (the z component), shape ``(...)``."""
    q, p = _positions(x), _momenta(x)
    return (q[..., 0] * p[..., 1] - q[..., 1] * p[..., 0]).sum(-1)


def min_separation(x: torch.Tensor) -> torch.Tensor:
    """The smallest distance between two bodies, shape ``(...)`` (inf for one body)."""
    if num_bodies(x) < 2:
        return torch.full(x.shape[:-1], math.inf, dtype=x.dtype, device=x.device)
    if num_bodies(x) > DENSE_BODIES:
        flat = x.reshape(-1, x.shape[-1])
        nearest = torch.stack([r2.amin(dim=(1, 2)) for *_, r2 in _blocks(flat)]).amin(dim=0)
        return nearest.sqrt().reshape(x.shape[:-1])
    return _pair_distances(x).amin(dim=-1)


_closest_approach = min_separation   # sample_orbits' argument of that name hides the function


# --------------------------------------------------------------------------- generator

@dataclass
class Orbits:
    """What ``sample_orbits`` returns.

    Attributes:
        x: ``(num_trials, num_points, 4B)`` float64 trajectories, all finite and clean.
        t_eval: ``(num_points,)`` times shared by every trajectory.
        resampled: how many configurations were drawn again (close encounter or failed integration).
        reasons: how many were rejected for each reason.
        min_separation: ``(num_trials,)`` the closest approach of each kept trajectory.
        seconds: wall time of the generation.
    """
    x: np.ndarray
    t_eval: np.ndarray
    resampled: int
    reasons: dict = field(default_factory=dict)
    min_separation: np.ndarray | None = None
    seconds: float = 0.0


class _Guard:
    """The true dynamics, watching every state the integrator evaluates.

    Records each trajectory's closest approach over all evaluated states (every stage of every
    step, so an encounter between two output samples is not missed; stages of rejected steps
    can only make it more cautious). A trajectory that comes closer than ``threshold`` is
    frozen (zero derivative) from then on, so its encounter neither shrinks its steps forever
    nor blows up: it is discarded and redrawn afterwards.

    The integrator drops finished rows, so each state carries its trajectory's index as one
    extra last column (with zero derivative): ``with_ids`` adds it, the guard reads it.
    """

    def __init__(self, batch: int, threshold: float):
        self.threshold2 = threshold ** 2
        # the guard watches a CPU integration (the datasets' dop853 steps in numpy)
        self.closest2 = torch.full((batch,), math.inf, dtype=torch.float64, device="cpu")
        self.frozen = torch.zeros(batch, dtype=torch.bool, device="cpu")

    @staticmethod
    def with_ids(x0: np.ndarray) -> torch.Tensor:
        """``(n, 4B)`` start states with their row index as column 4B: ``(n, 4B + 1)``."""
        return torch.from_numpy(np.concatenate([x0, np.arange(len(x0), dtype=x0.dtype)[:, None]], axis=1))

    @property
    def closest(self) -> torch.Tensor:
        """Each trajectory's closest approach so far (NaN if a state was NaN)."""
        return self.closest2.sqrt()

    def __call__(self, state: torch.Tensor) -> torch.Tensor:
        x, ids = state[:, :-1], state[:, -1].long()
        dxdt, nearest = _field(x)
        frozen = self.frozen[ids]
        if x.shape[1] > 4:      # two bodies or more: a pair to watch
            nearest = nearest.to(torch.float64)
            closest = self.closest2[ids]
            self.closest2[ids] = torch.minimum(closest, nearest)   # NaN sticks, and counts as close
            frozen |= ~(nearest >= self.threshold2)
            self.frozen[ids] = frozen
        out = torch.zeros_like(state)
        out[:, :-1] = dxdt
        if frozen.any():
            out[frozen] = 0.0
        return out


def _integrate(x0: np.ndarray, t_eval: np.ndarray, rtol: float, atol: float, threshold: float,
               out: np.ndarray, closest: np.ndarray, reasons: np.ndarray) -> None:
    """Integrate the rows of ``x0`` in one batched call; fill ``out``, ``closest`` and ``reasons``
    (0 = clean, 1 = close encounter, 2 = failed or non-finite) for each row.

    ``rollout(method='dopri5')`` controls each trajectory's step with its own error norm, as one
    scipy RK45 call per trajectory would, so a hard orbit neither sets the step of the others
    nor gets a looser tolerance. If the batched call fails, the culprits it names (or else the
    two halves) are retried apart, down to single trajectories.
    """
    n = len(x0)
    guard = _Guard(n, threshold)
    # the id column's error is always 0 but counts in the RMS over dim + 1 components: shrinking
    # both tolerances by sqrt(dim / (dim + 1)) gives exactly the norm of the 4B real components
    shrink = math.sqrt(x0.shape[1] / (x0.shape[1] + 1))
    try:
        traj = rollout(guard, _Guard.with_ids(x0), t_eval, method="dopri5", rtol=rtol * shrink,
                       atol=atol * shrink, threads=None).numpy()[..., :-1]
    except DivergenceError as err:
        if n == 1:
            reasons[0], closest[0] = 2, float(guard.closest[0])
            return
        named = sorted({i for i in err.trajectories if 0 <= i < n})
        if named and len(named) < n:     # the culprits alone, then the rest together
            groups = [np.array([i]) for i in named] + [np.setdiff1d(np.arange(n), named)]
        else:                            # unknown culprits: bisect
            groups = [np.arange(n // 2), np.arange(n // 2, n)]
        for rows in groups:
            sub_out, sub_closest, sub_reasons = out[rows], closest[rows], reasons[rows]
            _integrate(x0[rows], t_eval, rtol, atol, threshold, sub_out, sub_closest, sub_reasons)
            out[rows], closest[rows], reasons[rows] = sub_out, sub_closest, sub_reasons
        return
    out[:] = traj
    closest[:] = guard.closest.numpy()
    finite = np.isfinite(traj).all(axis=(1, 2))
    reasons[:] = np.where(~finite, 2, np.where(guard.frozen.numpy() | (closest < threshold), 1, 0))


def sample_orbits(sample_config: Callable[[np.random.RandomState], np.ndarray], num_trials: int,
                  num_points: int, t_span: tuple[float, float], rng: np.random.RandomState,
                  rtol: float = 1e-9, atol: float = 1e-6, min_separation: float = MIN_SEPARATION,
                  max_resamples: int | None = None, chunk_size: int = 5000) -> Orbits:
    """``num_trials`` clean trajectories of ``num_points`` times on ``t_span``, integrated in batches.

    Draws ``num_trials`` states with ``sample_config(rng)`` (each ``(4B,)``, in order, so the
    first ``num_trials`` draws are those of a loop of one draw per trajectory), integrates them
    with RK45 (``rollout(method='dopri5')``, one step size per trajectory) in batches of up to
    ``chunk_size``, and redraws (fresh states from the
    same ``rng``, in index order) every trajectory that comes closer than ``min_separation``
    at any evaluated state, fails to integrate, or is non-finite; repeats until all are clean.

    Args:
        rtol, atol: the tolerances of one solve_ivp call per trajectory (the original: rtol
            1e-9 and scipy's default atol 1e-6); the batched calls tighten them so that each
            trajectory is at least that accurate (see ``_integrate``).
        min_separation: the close-encounter threshold (``MIN_SEPARATION``, 0.1, explains it).
        max_resamples: give up (RuntimeError) after this many redraws; default ``num_trials``.
        chunk_size: trajectories per batched call. Each trajectory has its own step size, but a
            chunk iterates until its hardest member is done, evaluating the whole chunk each
            time; chunks bound that waste and the memory.

    Returns:
        an ``Orbits``: trajectories ``x`` ``(num_trials, num_points, 4B)`` float64, ``t_eval``,
        and ``resampled``, the number of redrawn configurations.
    """
    start = time.perf_counter()
    if num_trials < 1 or num_points < 2:
        raise ValueError(f"need num_trials >= 1 and num_points >= 2, got {num_trials} and {num_points}")
    max_resamples = num_trials if max_resamples is None else max_resamples
    t_eval = np.linspace(float(t_span[0]), float(t_span[1]), num_points)

    def draw() -> np.ndarray:
        state = np.asarray(sample_config(rng), dtype=np.float64)
        if state.ndim != 1 or state.shape[0] % 4:
            raise ValueError(f"sample_config must return a (4B,) state, got shape {state.shape}")
        return state

    x0 = np.stack([draw() for _ in range(num_trials)])
    dim = x0.shape[1]
    x = np.empty((num_trials, num_points, dim))
    closest = np.full(num_trials, np.nan)
    reasons = {"close_encounter": 0, "failed": 0}
    resampled = 0
    pending = np.arange(num_trials)
    while len(pending):
        starts = x0[pending]
        status = np.zeros(len(pending), dtype=np.int64)
        best = np.full(len(pending), np.nan)
        traj = np.full((len(pending), num_points, dim), np.nan)
        finite = np.isfinite(starts).all(axis=1)
        sep0 = np.full(len(pending), np.nan)
        sep0[finite] = _closest_approach(torch.from_numpy(starts[finite])).numpy()
        status[~finite] = 2
        status[finite & ~(sep0 >= min_separation)] = 1
        best[finite] = sep0[finite]
        todo = np.nonzero(status == 0)[0]
        for lo in range(0, len(todo), chunk_size):
            rows = todo[lo:lo + chunk_size]
            sub_out, sub_best, sub_status = traj[rows], best[rows], status[rows]
            _integrate(starts[rows], t_eval, rtol, atol, min_separation, sub_out, sub_best, sub_status)
            traj[rows], best[rows], status[rows] = sub_out, sub_best, sub_status
        good = status == 0
        x[pending[good]] = traj[good]
        closest[pending[good]] = best[good]
        bad = pending[~good]
        reasons["close_encounter"] += int((status == 1).sum())
        reasons["failed"] += int((status == 2).sum())
        if resampled + len(bad) > max_resamples:
            raise RuntimeError(
                f"sample_orbits: {resampled + len(bad)} configurations would need redrawing "
                f"(close encounters below {min_separation}: {reasons['close_encounter']}, failed or "
                f"non-finite: {reasons['failed']}), more than max_resamples={max_resamples}; "
                "check the sampler, or raise max_resamples")
        for i in bad:
            x0[i] = draw()
        resampled += len(bad)
        pending = bad
    return Orbits(x=x, t_eval=t_eval, resampled=resampled, reasons=reasons, min_separation=closest,
                  seconds=time.perf_counter() - start)


def orbit_dataset(sample_config: Callable[[np.random.RandomState], np.ndarray], seed: int, num_trials: int,
                  num_points: int, t_span: tuple[float, float], test_split: float = 0.2, rtol: float = 1e-9,
                  atol: float = 1e-6, min_separation: float = MIN_SEPARATION) -> dict:
    """Training rows from ``sample_orbits`` seeded by ``np.random.RandomState(seed)``.

    Rows are every (trajectory, time) state, trajectory-major; ``dxdt`` is the analytic
    ``dynamics`` at each row. The first ``test_split`` of the rows is the test set, the rest
    train (the original's split: whole trajectories when ``num_trials * test_split`` is whole).

    Returns:
        float32 ``x``, ``dxdt``, ``test_x``, ``test_dxdt`` ``(rows, 4B)``, the grid step ``dt``,
        ``t_eval``, ``resampled`` (the number of redrawn configurations) and its two parts,
        ``resampled_close_encounter`` and ``resampled_failed``.
    """
    orbits = sample_orbits(sample_config, num_trials, num_points, t_span, np.random.RandomState(seed),
                           rtol=rtol, atol=atol, min_separation=min_separation)
    x = orbits.x.reshape(-1, orbits.x.shape[-1])
    dxdt = dynamics(torch.from_numpy(x)).numpy()
    split = int(len(x) * test_split)
    as32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return {"x": as32(x[split:]), "dxdt": as32(dxdt[split:]), "test_x": as32(x[:split]),
            "test_dxdt": as32(dxdt[:split]), "dt": float(orbits.t_eval[1] - orbits.t_eval[0]),
            "t_eval": orbits.t_eval, "resampled": int(orbits.resampled),
            "resampled_close_encounter": int(orbits.reasons["close_encounter"]),
            "resampled_failed": int(orbits.reasons["failed"])}


def task_dataset(name: str, random_config: Callable, defaults: dict, sampler_keys: tuple[str, ...], seed: int,
                 save_dir, params: dict) -> dict:
    """An orbit task's cached dataset: ``defaults`` overridden by ``params``, the start states from
    ``random_config(rng, **{k: value for k in sampler_keys})``, generated and cached as above."""
    unknown = set(params) - set(defaults)
    if unknown:
        raise TypeError(f"unknown dataset params {sorted(unknown)}; known: {sorted(defaults)}")
    p = {**defaults, **params, "seed": seed, "version": DATASET_VERSION}
    sampler = functools.partial(random_config, **{k: p[k] for k in sampler_keys})

    def build():
        return orbit_dataset(sampler, seed, p["num_trials"], p["num_points"], tuple(p["t_span"]),
                             test_split=p["test_split"], rtol=p["rtol"], atol=p["atol"],
                             min_separation=p["min_separation"])

    return get_cached_dataset(save_dir, name, p, build, describe=lambda d: (
        f"{p['num_trials']} orbits ({d['resampled']} resampled: {d['resampled_close_encounter']} close "
        f"encounters below {p['min_separation']:g}, {d['resampled_failed']} failed integrations)"))
