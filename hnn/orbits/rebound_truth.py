"""REBOUND (Rein & Liu 2012, https://rebound.readthedocs.io) as a second truth for the gravity of many bodies: a
batch of our states integrated by REBOUND's own integrators, returned in our layout.

    from hnn.orbits import rebound_truth
    path = rebound_truth.rollout(x0, t_eval, "ias15", softening=0.1)            # (n, len(t_eval), 4N)
    path = rebound_truth.rollout(x0, t_eval, "leapfrog", softening=0.1, dt=0.01, stats=stats)

REBOUND is an optional extra (``pip install -e ".[nbody]"``): this module imports it on use only, and says what to
install where it is missing. States are ``hnn.orbits.nbody``'s (the gravity task's), unit masses in the plane,
``x = [qx_1..qx_N, qy_1..qy_N, px_1..px_N, py_1..py_N]`` ``(n, 4N)``, momentum = velocity; REBOUND runs them in
3-D with z = vz = 0 (no force leaves the plane), G = 1 and no units (``sim.units`` unset: our units are its
units). ``softening`` is REBOUND's ``sim.softening``: the same Plummer length as ``hnn.orbits.nbody``'s, each pair's
pull (q_j - q_i) / (r^2 + softening^2)^(3/2) in its direct-summation gravity.

The integrators (``INTEGRATORS``):

- ``'ias15'``: 15th-order Gauss-Radau with an adaptive step (Rein & Spiegel 2015), error below float64's round-off
  per step at its default ``epsilon`` (1e-9); ``dt`` is only its first step; ``stats['steps']`` counts its steps.
- ``'leapfrog'``: drift-kick-drift, second order, symplectic, at the fixed step ``dt``.
- ``'whfast'``: the Wisdom-Holman map (Rein & Tamayo 2015) at the fixed step ``dt``, in Jacobi coordinates: each body
  drifts on the exact Kepler orbit about the mass of the bodies before it, and the rest of the forces kick. It is
  built for a dominant central mass with small perturbations (planets about a star); our bodies are equal masses,
  where the "perturbation" is as large as the Kepler part and the unsoftened Kepler drift is not the softened H's,
  so it may be a poor choice here: docs/bodies.md measures it beside the others rather than assume.
"""
from __future__ import annotations

import math
import time

import numpy as np
import torch

INTEGRATORS = ("ias15", "whfast", "leapfrog")
FIXED_STEP = ("whfast", "leapfrog")
INSTALL = 'pip install -e ".[nbody]"'
# t_eval's intervals hold whole fixed steps: off a multiple of dt by more than this (relative) is an error, since
# REBOUND would shorten a step to land there (a fixed-step method's accuracy and symplecticity lost at that step)
GRID_TOLERANCE = 1e-9


def rebound():
    """The ``rebound`` module, or an ImportError naming the extra that installs it."""
    try:
        import rebound as module
    except ImportError as err:
        raise ImportError(f"hnn.orbits.rebound_truth needs REBOUND, an optional extra: {INSTALL} ({err})") from None
    return module


def version() -> str | None:
    """REBOUND's version, or None where it is not installed."""
    try:
        import rebound as module
    except ImportError:
        return None
    return module.__version__


def _steps_between(t_eval: np.ndarray, dt: float) -> list[int]:
    """Whole steps of ``dt`` between consecutive ``t_eval``; a ValueError where an interval is not one."""
    counts = []
    for a, b in zip(t_eval[:-1], t_eval[1:]):
        k = (b - a) / dt
        if abs(k - round(k)) > GRID_TOLERANCE * max(1.0, k):
            raise ValueError(f"t_eval interval [{a:g}, {b:g}] is {k:.6g} steps of dt = {dt:g}: a fixed-step integrator "
                             "outputs on its own grid; give t_eval on multiples of dt, or a dt that divides it")
        counts.append(int(round(k)))
    return counts


def _simulation(module, q: np.ndarray, p: np.ndarray, integrator: str, softening: float, dt: float | None,
                epsilon: float | None):
    """A REBOUND simulation of ``N`` unit masses at positions ``q`` and velocities ``p`` ``(N, 2)``."""
    sim = module.Simulation()
    sim.G = 1.0
    sim.softening = softening
    sim.integrator = integrator
    if dt is not None:
        sim.dt = dt
    if epsilon is not None:
        sim.integrator.epsilon = epsilon
    for _ in range(len(q)):
        sim.add(m=1.0)
    xyz, vxvyvz = np.zeros((len(q), 3)), np.zeros((len(q), 3))
    xyz[:, :2], vxvyvz[:, :2] = q, p
    sim.set_serialized_particle_data(xyz=xyz, vxvyvz=vxvyvz)
    return sim


def _state(sim, count: int) -> np.ndarray:
    """The simulation's state in our layout ``(4N,)``."""
    xyz, vxvyvz = np.empty((count, 3)), np.empty((count, 3))
    sim.serialize_particle_data(xyz=xyz, vxvyvz=vxvyvz)
    return np.concatenate([xyz[:, 0], xyz[:, 1], vxvyvz[:, 0], vxvyvz[:, 1]])


def rollout(x0, t_eval, integrator: str = "ias15", *, softening: float, dt: float | None = None,
            epsilon: float | None = None, stats: dict | None = None) -> torch.Tensor:
    """Integrate every state of ``x0`` under REBOUND's ``integrator`` and sample at ``t_eval``.

    Args:
        x0: ``(n, 4N)`` (or one ``(4N,)``) start states in ``hnn.orbits.nbody``'s layout, unit masses.
        t_eval: 1-D increasing times (time units, G = 1), the first the time of ``x0``.
        integrator: one of ``INTEGRATORS``.
        softening: the Plummer length (the gravity task's ``--softening``; 0 for Newton's). Required: REBOUND's
            default 0 silently differs from the task's 0.1.
        dt: the step of ``'leapfrog'`` and ``'whfast'`` (required; each ``t_eval`` interval a whole number of
            steps); ``'ias15'``'s first try (default REBOUND's), after which it chooses its own.
        epsilon: ``'ias15'``'s precision parameter (default REBOUND's 1e-9).
        stats: a dict, filled with ``steps`` (a list: each row's steps taken), ``seconds`` (each row's wall time
            inside REBOUND, setup excluded) and, per row, ``interval_steps`` and ``interval_seconds`` (lists over the
            ``t_eval`` intervals: an adaptive step's cost, timed where it ran).

    Returns:
        ``(n, len(t_eval), 4N)`` float64 states (CPU), as ``hnn.rollout`` returns them.
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator {integrator!r}: choose one of {', '.join(INTEGRATORS)}")
    if not (isinstance(softening, (int, float)) and math.isfinite(softening) and softening >= 0):
        raise ValueError(f"softening {softening!r}: give the Plummer length, a finite number >= 0 (the gravity "
                         "task's --softening)")
    if integrator in FIXED_STEP and dt is None:
        raise ValueError(f"integrator {integrator!r} takes fixed steps: give dt (e.g. the true forces' leapfrog's)")
    if dt is not None and not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt {dt!r}: must be a finite number > 0")
    if epsilon is not None and integrator != "ias15":
        raise ValueError(f"epsilon is IAS15's precision; integrator {integrator!r} takes none")
    x0 = torch.as_tensor(x0, dtype=torch.float64).cpu()
    x0 = x0[None] if x0.ndim == 1 else x0
    if x0.ndim != 2 or x0.shape[1] < 4 or x0.shape[1] % 4:
        raise ValueError(f"x0 holds states of N bodies in the plane, shape (n, 4N); got {tuple(x0.shape)}")
    t_eval = np.asarray(t_eval, dtype=np.float64)
    if t_eval.ndim != 1 or len(t_eval) < 1 or np.any(np.diff(t_eval) <= 0):
        raise ValueError(f"t_eval must be 1-D and increasing; got {t_eval!r}")
    steps = _steps_between(t_eval, dt) if integrator in FIXED_STEP else None
    module = rebound()
    n, count = x0.shape[0], x0.shape[1] // 4
    out = np.empty((n, len(t_eval), 4 * count))
    taken, seconds, interval_steps, interval_seconds = [], [], [], []
    for row, state in enumerate(x0.numpy()):
        q = state[:2 * count].reshape(2, count).T
        p = state[2 * count:].reshape(2, count).T
        sim = _simulation(module, q, p, integrator, float(softening), dt, epsilon)
        sim.t = float(t_eval[0])
        out[row, 0] = _state(sim, count)
        row_steps, row_seconds = [], []
        for k, t in enumerate(t_eval[1:], start=1):
            before, tic = int(sim.steps_done), time.perf_counter()
            if steps is None:
                sim.integrate(float(t), exact_finish_time=1)
            else:
                sim.steps(steps[k - 1])
            row_seconds.append(time.perf_counter() - tic)
            row_steps.append(int(sim.steps_done) - before)
            out[row, k] = _state(sim, count)
        taken.append(int(sim.steps_done))
        seconds.append(sum(row_seconds))
        interval_steps.append(row_steps)
        interval_seconds.append(row_seconds)
    if stats is not None:
        stats.update(steps=taken, seconds=seconds, interval_steps=interval_steps, interval_seconds=interval_seconds)
    return torch.from_numpy(out)
