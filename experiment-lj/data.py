"""A Lennard-Jones cluster: N unit masses in the plane, every pair at V(r) = 4 e ((s / r)^12 - (s / r)^6) (e = s = 1;
not one of the paper's tasks). A soft attractive tail and a steep wall: the extremes of a pair potential.

H = sum_i |p_i|^2 / 2 + sum_{i<j} V(|q_i - q_j|), all pairs (N(N-1)/2 a step). States are the orbit tasks' layout,
x = [qx_1..qx_N, qy_1..qy_N, px_1..px_N, py_1..py_N] ``(batch, 4N)``, for any N (the task trains on ``NUM_BODIES``).

The cutoff (``cutoff=r_c``, the task's ``--cutoff``; None, all pairs, by default): the truncated and shifted
potential of molecular dynamics, V(r) - V(r_c) for r < r_c and 0 beyond, over the pairs closer than r_c that a
cell list finds at each call (``hnn.bodies.Bodies(pairs='cutoff')``, ``hnn.cells``): O(N) a step at the cluster's
density. H stays continuous; the force jumps by |V'(r_c)| (3.9e-2 at r_c = 2.5) where a pair crosses r_c, so a
fixed-step integrator's energy error is first order in the step at each crossing (second order between them).
A cutoff must exceed the wall's range, so that every pair inside the wall is found.

The wall: a pair closer than ``WALL`` (0.7 s, where V = 4 (0.7^-12 - 0.7^-6) ~ 2.2e2 and the force ~ 4e3) is a
``WallError`` naming the pair and its distance, from ``hamiltonian`` and ``dynamics`` alike: the energy such a
pair needs is far beyond the cluster's, so reaching it means a start law, a step or a model gone wrong, and the
r^-12 term would otherwise overflow float32 silently below r ~ 6e-4.

Start states: bodies on a triangular lattice of spacing 2^(1/6) s (each pair of neighbours at V's minimum),
filled row by row around the origin, each displaced by N(0, 0.03^2 s^2), momenta N(0, 0.1^2) per component less
their mean. Paths by DOP853 (rtol 1e-10) on [0, 5].
"""
import functools
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.bodies import Bodies
from hnn.cache import get_cached_dataset
from hnn.models.pair import find_pairs, inside_cutoff, separations

HERE = Path(__file__).resolve().parent
NAME = "lj"
NUM_BODIES = 8
EPSILON, SIGMA = 1.0, 1.0
WALL = 0.7              # a pair closer than this (in units of SIGMA) is an error, never an overflow
SPACING = 2 ** (1 / 6)  # V's minimum
DISPLACEMENT, MOMENTUM = 0.03, 0.1
DEFAULTS = {"num_trials": 200, "num_points": 20, "t_span": [0.0, 5.0], "test_split": 0.2, "rtol": 1e-10,
            "atol": 1e-10, "num_bodies": NUM_BODIES}
DATASET_VERSION = 1


class WallError(hnn.DivergenceError, ValueError):
    """A pair of bodies closer than the wall's range ``WALL``: the message names the pair, its distance and the fix.
    Also a ``DivergenceError``: a learned path that brings two bodies inside the wall has failed as one that blew
    up has, and an energy protocol scores it so (no energy MSE, and why), where the true H cannot be read."""


def layout(count: int, cutoff: float | None = None) -> Bodies:
    """The layout of ``count`` bodies: every pair interacts, or (``cutoff``) the pairs closer than it."""
    if cutoff is None:
        return Bodies(count, 2)
    if not (isinstance(cutoff, (int, float)) and cutoff > WALL * SIGMA):
        raise ValueError(f"a Lennard-Jones cutoff must exceed the wall's range {WALL * SIGMA:g}, so that every pair "
                         f"inside the wall is found; got {cutoff!r}: use 2.5 (the usual choice) or more")
    return Bodies(count, 2, pairs="cutoff", cutoff=cutoff)


def _pairs(q: torch.Tensor, cutoff: float | None = None):
    """``(i, j, d, r, inside)`` of the interacting pairs of positions ``q`` ``(batch, N, 2)`` (``inside``: which are
    closer than the cutoff in each state, None without one); a ``WallError`` for a pair inside the wall."""
    bodies = layout(q.shape[1], cutoff)
    i, j = find_pairs(q, bodies)
    d, r = separations(q, i, j)
    if r.numel() and not bool((r >= WALL * SIGMA).all()):   # NaN fails the check too
        row, pair = divmod(int(torch.argmin(torch.nan_to_num(r, nan=-1.0)).item()), r.shape[1])
        raise WallError(f"bodies {int(i[pair])} and {int(j[pair])} of state {row} are {float(r[row, pair]):.3g} apart, "
                        f"inside the Lennard-Jones wall's range {WALL * SIGMA:g} (V there ~ 2e2, far beyond the "
                        "cluster's energy): draw starts from random_config, or integrate with a smaller step")
    return i, j, d, r, inside_cutoff(r, bodies)


def _potential(r: torch.Tensor) -> torch.Tensor:
    s6 = (SIGMA / r) ** 6
    return 4 * EPSILON * (s6 * s6 - s6)


def hamiltonian(x: torch.Tensor, cutoff: float | None = None) -> torch.Tensor:
    """H ``(...)`` of states ``(..., 4N)`` (a batch, or trials x times as an energy protocol's paths); with
    ``cutoff``, each pair's V(r) - V(cutoff) below it, 0 beyond."""
    q, p = layout(x.shape[-1] // 4).split(x.reshape(-1, x.shape[-1]))
    _, _, _, r, inside = _pairs(q, cutoff)
    pairs = _potential(r) if inside is None else torch.where(inside, _potential(r) - _potential(r.new_tensor(cutoff)), 0)
    return ((p * p).sum(dim=(1, 2)) / 2 + pairs.sum(dim=1)).reshape(x.shape[:-1])


def _force(q: torch.Tensor, cutoff: float | None = None) -> torch.Tensor:
    i, j, d, r, inside = _pairs(q, cutoff)
    s6 = (SIGMA / r) ** 6
    size = 24 * EPSILON * (2 * s6 * s6 - s6) / r ** 2                      # -dV/dr / r
    push = (size if inside is None else torch.where(inside, size, 0))[..., None] * d    # along d, on body i
    return torch.zeros_like(q).index_add(1, i, push).index_add(1, j, -push)


def potential_gradient(q_half: torch.Tensor, cutoff: float | None = None) -> torch.Tensor:
    """dV/dq ``(batch, 2N)`` of one half of the states (positions): what a split integrator's kick reads."""
    bodies = layout(q_half.shape[-1] // 2)
    return -bodies.flat(_force(bodies.bodywise(q_half), cutoff))


def dynamics(x: torch.Tensor, cutoff: float | None = None) -> torch.Tensor:
    """Hamilton's equations ``(batch, 4N) -> (batch, 4N)``: dq/dt = p, dp/dt = the pairs' forces (closer than
    ``cutoff`` only, where one is given)."""
    squeeze = x.dim() == 1
    x = x.reshape(-1, x.shape[-1])
    q, p = layout(x.shape[-1] // 4).split(x)
    out = layout(q.shape[1]).join(p, _force(q, cutoff))
    return out[0] if squeeze else out


def random_config(rng: np.random.RandomState, count: int = NUM_BODIES) -> np.ndarray:
    """One start state ``(4 count,)``: a patch of the triangular lattice, jittered, with small momenta."""
    width = int(np.ceil(np.sqrt(count)))
    rows, cols = np.divmod(np.arange(count), width)
    q = np.stack([cols + 0.5 * (rows % 2), rows * np.sqrt(3) / 2], axis=1) * SPACING * SIGMA
    q = q - q.mean(axis=0) + DISPLACEMENT * SIGMA * rng.randn(count, 2)
    p = MOMENTUM * rng.randn(count, 2)
    p -= p.mean(axis=0)
    return np.concatenate([q[:, 0], q[:, 1], p[:, 0], p[:, 1]])


def initial_state(seed: int, count: int = NUM_BODIES) -> np.ndarray:
    """The start state of trial ``seed``."""
    return random_config(np.random.RandomState(seed), count)


def get_dataset(seed: int = 0, save_dir=HERE, cutoff: float | None = None, **params) -> dict:
    """``num_trials`` paths of ``num_points`` states on ``t_span`` (DOP853) of ``num_bodies`` bodies; the first
    ``test_split`` of the paths test, the rest train. Float32 ``x``, ``dxdt`` (the analytic field at each row),
    ``test_x``, ``test_dxdt``, ``dt``, ``t_eval``; cached in ``save_dir`` under a hash of the params and seed.
    ``cutoff``: the truncated and shifted potential's r_c (None: every pair, the task's default)."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown dataset params {sorted(unknown)}; known: {sorted(DEFAULTS)} and cutoff")
    layout(2, cutoff)       # a cutoff inside the wall is refused before any path is drawn
    # the cutoff enters the cache's hash only where one is set: the all-pairs datasets keep their files
    p = {**DEFAULTS, **params, "seed": seed, "version": DATASET_VERSION, **({} if cutoff is None else {"cutoff": cutoff})}

    def build():
        rng = np.random.RandomState(seed)
        x0 = torch.tensor(np.stack([random_config(rng, p["num_bodies"]) for _ in range(p["num_trials"])]))
        t_eval = np.linspace(*p["t_span"], p["num_points"])
        return hnn.datasets.paths_dataset(functools.partial(dynamics, cutoff=cutoff), x0, t_eval, p["test_split"],
                                          rtol=p["rtol"], atol=p["atol"])

    return get_cached_dataset(save_dir, NAME, p, build,
                              describe=lambda d: f"{p['num_trials']} paths of a Lennard-Jones cluster of "
                                                 f"{p['num_bodies']}" + ("" if cutoff is None else
                                                                         f", cut off at {cutoff:g}"))
