"""The integrator study's grid, shared with the scene study: every registered solver's settings that
apply to a field (``solver_settings``), start states inside each task's training distribution
(``start_states``) and one timed rollout (``timed_rollout``)."""
from __future__ import annotations

import statistics
import time
import warnings

import numpy as np
import torch

import hnn

def start_states(task: str, system, batch: int) -> torch.Tensor:
    """``(batch, dim)`` float64 start states inside each task's training distribution."""
    if hasattr(system, "initial_state"):            # the orbits: the energy-MSE trials' states
        return torch.tensor(np.stack([system.initial_state(s) for s in range(batch)]), dtype=torch.float64)
    if task == "pixels":                            # gym's own start states, |q| < pi/6
        return torch.tensor(system.canonical(system.sample_starts(0, batch)), dtype=torch.float64)
    lo, hi = system.RADIUS_RANGE
    rng = np.random.RandomState(0)
    r = np.linspace(lo, hi, batch)
    angle = rng.uniform(0, 2 * np.pi, batch)
    return torch.tensor(np.stack([r * np.cos(angle), r * np.sin(angle)], 1), dtype=torch.float64)


# the settings a study runs beyond a solver's defaults: solve_ivp also with DOP853; yoshida4 (a
# composition of a base method) also on the midpoint, which makes it symplectic for any H
ADAPTIVE_VARIANTS = {"solve_ivp": ({}, {"scipy_method": "DOP853"})}
ANY_H_VARIANTS = {"yoshida4": {"base": "midpoint"}}


def solver_settings(separable: bool, rtols, dts, adaptive_variants=ADAPTIVE_VARIANTS,
                    energy: bool = False) -> list[tuple[str, dict]]:
    """``(method label, rollout options)`` of every solver in ``hnn.SOLVERS`` that applies to a field:
    the adaptive ones at each of ``rtols`` (and their ``adaptive_variants``), the fixed-step ones at
    each of ``dts``; one that ``needs_separable`` only for a ``separable`` H, or else in its
    ``ANY_H_VARIANTS`` setting; one that ``needs_hamiltonian`` only for a field that carries its H
    (``energy``: an ``hnn.interface.EnergyField``)."""
    solvers = list(hnn.SOLVERS.values())
    out = []
    for rtol in rtols:
        for solver in (s for s in solvers if s.adaptive):
            for extra in adaptive_variants.get(solver.name, ({},)):
                out.append((solver.describe(extra), {"method": solver.name, **extra, "rtol": rtol, "atol": rtol}))
    for solver in (s for s in solvers if not s.adaptive and (energy or not s.needs_hamiltonian)):
        extra = {} if separable or not solver.needs_separable else ANY_H_VARIANTS.get(solver.name)
        if extra is not None:
            out += [(solver.name, {"method": solver.name, "dt": dt, **extra}) for dt in dts]
    return out


def timed_rollout(f, x0, t, options, repeats: int, enough: float = 1.0, runner=hnn.rollout):
    """(median seconds, trajectory, stats) of up to ``repeats`` identical rollouts; one taking over
    ``enough`` seconds ends the repeats (long enough that noise does not dominate it). ``runner``:
    ``hnn.rollout``, or a peer's solver of the same call (``peer_solvers.Peer.run``)."""
    seconds, traj, stats = [], None, {}
    for _ in range(repeats):
        stats = {}
        start = time.perf_counter()
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")         # tolerances are kept within the dtype (see _settings)
            traj = runner(f, x0, t, stats=stats, **options)
        seconds.append(time.perf_counter() - start)
        if seconds[-1] > enough:
            break
    return statistics.median(seconds), traj, stats
