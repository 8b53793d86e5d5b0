"""A chain of springs: N unit masses in the plane, each joined to the next by a spring of stiffness k and rest
length a (a 1-D lattice free in 2-D; not one of the paper's tasks).

H = sum_i |p_i|^2 / 2 + sum_{i=1}^{N-1} k (|q_{i+1} - q_i| - a)^2 / 2. Nearest neighbours only: short range, so
the true field costs O(N) a step (N - 1 springs), and the pair kind reads the same neighbours
(``hnn.bodies.Bodies(pairs='neighbours')``). States are the orbit tasks' layout, x = [qx_1..qx_N, qy_1..qy_N,
px_1..px_N, py_1..py_N] ``(batch, 4N)``, for any N (the task trains on ``NUM_BODIES``; ``random_config`` draws
any count, which the bodies study rolls out).

Start states: body i at ((i - (N - 1) / 2) a + U(-0.2, 0.2) a, N(0, 0.1 a)), momenta N(0, 0.3^2) per component less their mean
(the chain's centre of mass at rest). Paths by DOP853 (rtol 1e-10) on [0, 10].
"""
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.bodies import Bodies
from hnn.cache import get_cached_dataset

HERE = Path(__file__).resolve().parent
NAME = "lattice"
NUM_BODIES = 8
SPRING, REST = 1.0, 1.0          # k and a
JITTER, BEND, MOMENTUM = 0.2, 0.1, 0.3     # the start law's spreads (fractions of a; momenta's std)
DEFAULTS = {"num_trials": 200, "num_points": 20, "t_span": [0.0, 10.0], "test_split": 0.2, "rtol": 1e-10,
            "atol": 1e-10, "num_bodies": NUM_BODIES}
DATASET_VERSION = 2     # 2: the chain centred on the origin


def layout(count: int) -> Bodies:
    """The layout of a chain of ``count`` bodies (neighbours along the chain interact)."""
    return Bodies(count, 2, pairs="neighbours")


def _springs(x: torch.Tensor):
    q, p = layout(x.shape[-1] // 4).split(x)
    d = q[:, 1:] - q[:, :-1]                        # (batch, N - 1, 2): each spring's extent
    r = torch.linalg.vector_norm(d, dim=-1)
    return q, p, d, r


def hamiltonian(x: torch.Tensor) -> torch.Tensor:
    """H ``(...)`` of states ``(..., 4N)`` (a batch, or trials x times as an energy protocol's paths)."""
    _, p, _, r = _springs(x.reshape(-1, x.shape[-1]))
    return ((p * p).sum(dim=(1, 2)) / 2 + (SPRING * (r - REST) ** 2 / 2).sum(dim=1)).reshape(x.shape[:-1])


def _force(q: torch.Tensor) -> torch.Tensor:
    """-dV/dq ``(batch, N, 2)`` of positions ``(batch, N, 2)``: each spring pulls its two ends together (or apart)."""
    d = q[:, 1:] - q[:, :-1]                        # (batch, N - 1, 2): each spring's extent
    r = torch.linalg.vector_norm(d, dim=-1)
    pull = (SPRING * (r - REST) / r)[..., None] * d          # on body i towards i + 1
    force = torch.zeros_like(q)
    force[:, :-1] += pull
    force[:, 1:] -= pull
    return force


def potential_gradient(q_half: torch.Tensor) -> torch.Tensor:
    """dV/dq ``(batch, 2N)`` of one half of the states (positions), O(N): what a split integrator's kick reads."""
    bodies = layout(q_half.shape[-1] // 2)
    return -bodies.flat(_force(bodies.bodywise(q_half)))


def dynamics(x: torch.Tensor) -> torch.Tensor:
    """Hamilton's equations ``(batch, 4N) -> (batch, 4N)``, O(N): dq/dt = p, dp/dt = the springs' pulls."""
    squeeze = x.dim() == 1
    x = x.reshape(-1, x.shape[-1])
    q, p = layout(x.shape[-1] // 4).split(x)
    out = layout(q.shape[1]).join(p, _force(q))
    return out[0] if squeeze else out


def random_config(rng: np.random.RandomState, count: int = NUM_BODIES) -> np.ndarray:
    """One start state ``(4 count,)`` of the start law above, drawn from ``rng``."""
    # centred on the origin: the columns' sizes then stay within one unit scale (hnn.units' auto leaves them)
    qx = REST * (np.arange(count) - (count - 1) / 2 + JITTER * (2 * rng.rand(count) - 1))
    qy = REST * BEND * rng.randn(count)
    p = MOMENTUM * rng.randn(count, 2)
    p -= p.mean(axis=0)
    return np.concatenate([qx, qy, p[:, 0], p[:, 1]])


def initial_state(seed: int, count: int = NUM_BODIES) -> np.ndarray:
    """The start state of trial ``seed``."""
    return random_config(np.random.RandomState(seed), count)


def get_dataset(seed: int = 0, save_dir=HERE, **params) -> dict:
    """``num_trials`` paths of ``num_points`` states on ``t_span`` (DOP853) of ``num_bodies`` bodies; the first
    ``test_split`` of the paths test, the rest train. Float32 ``x``, ``dxdt`` (the analytic field at each row),
    ``test_x``, ``test_dxdt``, ``dt``, ``t_eval``; cached in ``save_dir`` under a hash of the params and seed."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown dataset params {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    p = {**DEFAULTS, **params, "seed": seed, "version": DATASET_VERSION}

    def build():
        rng = np.random.RandomState(seed)
        x0 = torch.tensor(np.stack([random_config(rng, p["num_bodies"]) for _ in range(p["num_trials"])]))
        t_eval = np.linspace(*p["t_span"], p["num_points"])
        return hnn.datasets.paths_dataset(dynamics, x0, t_eval, p["test_split"], rtol=p["rtol"], atol=p["atol"])

    return get_cached_dataset(save_dir, NAME, p, build,
                              describe=lambda d: f"{p['num_trials']} paths of a chain of {p['num_bodies']} springs")
