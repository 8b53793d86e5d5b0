"""Gravity of N bodies: N unit masses in the plane (G = 1), every pair at V(r) = -1 / sqrt(r^2 + e^2), e the Plummer
softening (``SOFTENING`` by default; 0 is Newton's, as the 2- and 3-body tasks); not one of the paper's tasks.

The physics is ``hnn.orbits.nbody``'s (any number of bodies, its softening option); states are its layout,
x = [qx_1..qx_N, qy_1..qy_N, px_1..px_N, py_1..py_N] ``(batch, 4N)``. The task trains on ``NUM_BODIES``;
``random_config`` draws any count.

Start states: a rotating disk. Positions uniform in the disk of radius 1.5 (redrawn until every pair is at least
0.2 apart; past ``NUM_BODIES`` bodies the disk grows as sqrt(N / NUM_BODIES), the training's density, and only the
bodies too close to another are redrawn, since a whole draw of many bodies would almost never pass); each body moves on the circle through it at 0.8 of the speed that the bodies inside its radius
would hold it at (sqrt(n(< r) / r), treating them as a point at the centre), plus N(0, 0.05^2) per component,
less the mean momentum. Paths by DOP853 (rtol 1e-10) on [0, 2]. Without softening the paths come from the orbit
tasks' generator (``hnn.orbits.nbody.orbit_dataset``: dopri5), which redraws a path whose bodies come closer than
``hnn.orbits.encounters.MIN_SEPARATION`` (a close encounter: huge, badly integrated dx/dt); the dataset says how
many. Point masses in this disk meet often (within a time unit nearly every start does, and the generator gives
up with a RuntimeError naming the count): hence the softened default.
"""
import functools
from pathlib import Path

import numpy as np
import torch

import hnn
from hnn.bodies import Bodies
from hnn.cache import get_cached_dataset
from hnn.orbits import nbody
from hnn.orbits.encounters import MIN_SEPARATION

HERE = Path(__file__).resolve().parent
NAME = "gravity"
NUM_BODIES = 8
SOFTENING = 0.1
RADIUS, MIN_START_SEPARATION, SPEED, NOISE = 1.5, 0.2, 0.8, 0.05
DEFAULTS = {"num_trials": 200, "num_points": 20, "t_span": [0.0, 2.0], "test_split": 0.2, "rtol": 1e-10,
            "atol": 1e-10, "num_bodies": NUM_BODIES, "softening": SOFTENING}
DATASET_VERSION = 1


def layout(count: int) -> Bodies:
    """The layout of ``count`` bodies (every pair interacts)."""
    return Bodies(count, 2)


def hamiltonian(x: torch.Tensor, softening: float = SOFTENING) -> torch.Tensor:
    """H ``(batch,)`` of states ``(batch, 4N)``."""
    return nbody.hamiltonian(x, softening)


def dynamics(x: torch.Tensor, softening: float = SOFTENING) -> torch.Tensor:
    """Hamilton's equations ``(batch, 4N) -> (batch, 4N)``."""
    return nbody.dynamics(x, softening)


def potential_gradient(q_half: torch.Tensor, softening: float = SOFTENING) -> torch.Tensor:
    """dV/dq ``(batch, 2N)`` of one half of the states (positions): minus the pull on each body, what a split
    integrator's kick reads (the field of the states at rest, whose second half is the pull)."""
    return -nbody.dynamics(torch.cat([q_half, torch.zeros_like(q_half)], dim=1), softening)[:, q_half.shape[1]:]


def random_config(rng: np.random.RandomState, count: int = NUM_BODIES) -> np.ndarray:
    """One start state ``(4 count,)`` of the rotating disk above, drawn from ``rng``."""
    if count > NUM_BODIES:
        r, angle = _spread_disk(rng, count)
        q = np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)
    else:
        while True:
            r = RADIUS * np.sqrt(rng.rand(count))
            angle = 2 * np.pi * rng.rand(count)
            q = np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)
            gaps = np.linalg.norm(q[:, None] - q[None], axis=-1) + np.eye(count) * 1e9
            if gaps.min() >= MIN_START_SEPARATION:
                break
    inside = (r[None, :] < r[:, None]).sum(axis=1) + 1                 # itself too: never a zero speed
    speed = SPEED * np.sqrt(inside / np.maximum(r, 1e-3))
    p = np.stack([-np.sin(angle), np.cos(angle)], axis=1) * speed[:, None] + NOISE * rng.randn(count, 2)
    p -= p.mean(axis=0)
    return np.concatenate([q[:, 0], q[:, 1], p[:, 0], p[:, 1]])


def _spread_disk(rng: np.random.RandomState, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(r, angle)`` of ``count`` bodies uniform in the disk of the training's density (radius RADIUS sqrt(count /
    NUM_BODIES)), each body closer than MIN_START_SEPARATION to an earlier one redrawn alone until none is."""
    radius = RADIUS * np.sqrt(count / NUM_BODIES)
    r, angle = radius * np.sqrt(rng.rand(count)), 2 * np.pi * rng.rand(count)
    while True:
        q = np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)
        gaps = np.linalg.norm(q[:, None] - q[None], axis=-1)
        close = np.triu(gaps < MIN_START_SEPARATION, k=1).any(axis=0)       # the later body of each close pair
        if not close.any():
            return r, angle
        redraw = int(close.sum())
        r[close], angle[close] = radius * np.sqrt(rng.rand(redraw)), 2 * np.pi * rng.rand(redraw)


def initial_state(seed: int, count: int = NUM_BODIES) -> np.ndarray:
    """The start state of trial ``seed``."""
    return random_config(np.random.RandomState(seed), count)


def get_dataset(seed: int = 0, save_dir=HERE, **params) -> dict:
    """``num_trials`` paths of ``num_points`` states on ``t_span`` (DOP853) of ``num_bodies`` bodies at ``softening``;
    the first ``test_split`` of the paths test, the rest train. Float32 ``x``, ``dxdt`` (the analytic field at each
    row), ``test_x``, ``test_dxdt``, ``dt``, ``t_eval``, ``resampled`` (paths redrawn for a close encounter; only
    without softening); cached in ``save_dir`` under a hash of the params and seed."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown dataset params {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    p = {**DEFAULTS, **params, "seed": seed, "version": DATASET_VERSION}
    field = functools.partial(nbody.dynamics, softening=p["softening"])

    def build():
        if not p["softening"]:      # Newton's: the orbit tasks' generator, which redraws close encounters
            sampler = functools.partial(random_config, count=p["num_bodies"])
            return nbody.orbit_dataset(sampler, seed, p["num_trials"], p["num_points"], tuple(p["t_span"]),
                                       test_split=p["test_split"], rtol=p["rtol"], atol=p["atol"],
                                       min_separation=MIN_SEPARATION)
        rng = np.random.RandomState(seed)
        x0 = torch.tensor(np.stack([random_config(rng, p["num_bodies"]) for _ in range(p["num_trials"])]))
        t_eval = np.linspace(*p["t_span"], p["num_points"])
        data = hnn.datasets.paths_dataset(field, x0, t_eval, p["test_split"], rtol=p["rtol"], atol=p["atol"])
        return {**data, "resampled": 0}

    return get_cached_dataset(save_dir, NAME, p, build, describe=lambda d: (
        f"{p['num_trials']} paths of {p['num_bodies']} bodies at softening {p['softening']:g} "
        f"({d['resampled']} redrawn for close encounters)"))
