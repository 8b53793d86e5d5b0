"""A learned map's rollout (``hnn.interface.StepMap``: a model that declares ``steps``): no solver,
the map's own step applied as many times as each interval of ``t_eval`` holds steps ``dt``.

``hnn.rollout(model, x0, t_eval)`` comes here for a map. The map steps only by the step it learned:
``t_eval`` must lie on ``t_eval[0] + k dt`` (any whole k, gaps allowed; backwards by the map's
inverse), and a ``dt`` option must be the map's own. Anything else is one ValueError naming the step.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from ..errors import divergence_error
from ..interface import StepMap
from ..modes import in_model_axis

# how far (in steps) a time of t_eval may sit off the map's grid: the rounding of t = t0 + k dt in
# float64 and of measured times written to a few digits, far below a whole step
GRID_TOLERANCE = 1e-4
OPTIONS = ("dt", "max_norm", "stats")       # the options a map's rollout takes


def step_counts(t: np.ndarray, dt: float) -> np.ndarray:
    """``(len(t) - 1,)`` whole steps ``dt`` between consecutive times of ``t`` (negative backwards),
    or a ValueError naming the first time off the grid ``t[0] + k dt``."""
    k = (t - t[0]) / dt
    whole = np.rint(k)
    off = np.abs(k - whole) > GRID_TOLERANCE
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"t_eval[{i}] - t_eval[0] = {t[i] - t[0]:.6g} is {k[i]:.6g} steps of this learned map's step "
                         f"dt={dt:g}: a map steps only by the step it was trained at; give t_eval on t_eval[0] + k * "
                         f"{dt:g} (e.g. t_eval[0] + {dt:g} * np.arange(n)), or train a map at the step you need")
    return np.diff(whole).astype(np.int64)


def check_request(f: StepMap, method: str, default_method: str, options: dict) -> None:
    """A ValueError for what a map's rollout cannot honour: another ``method``, an option it does not
    take, a ``dt`` that is not its own, a map without a step."""
    if f.dt is None:
        raise ValueError("this learned map has no step dt (it was built without the data's): build it with dt=... or "
                         "train it through hnn.run_experiment, which gives it the dataset's")
    if method != default_method:
        raise ValueError(f"a learned map steps itself (dt={f.dt:g}): no integrator applies, drop method={method!r} "
                         "(hnn.rollout(model, x0, t_eval) steps the map on t_eval)")
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise ValueError(f"a learned map's rollout takes the options {', '.join(OPTIONS)}; got {', '.join(unknown)}: "
                         "drop them (tolerances and solvers are for fields)")
    if options.get("dt") is not None and not math.isclose(options["dt"], f.dt, rel_tol=1e-9):
        raise ValueError(f"dt={options['dt']:g} is not this learned map's step dt={f.dt:g}: a map steps only by the "
                         f"step it was trained at; drop dt, or train a map at dt={options['dt']:g}")


def map_rollout(f: StepMap, x0: torch.Tensor, t: np.ndarray, dt: float | None = None,
                max_norm: float | None = 1e6, stats: dict | None = None) -> torch.Tensor:
    """``(batch, len(t), dim)``: ``f.step`` (``f.inverse`` backwards) applied between the times of ``t``,
    from the checked ``x0`` ``(batch, dim)``; ``stats["nfev"]``: the map's batched steps. Rows that blow
    up (non-finite, or a component beyond ``max_norm``) are named with their first time in
    ``hnn.DivergenceError``; they are found once the path is whole (a check at every step would cost as
    much as the step). ``dt`` is checked by ``check_request``."""
    counts = step_counts(t, f.dt)
    move = f.step if counts.sum() >= 0 else f.inverse
    out, x = [x0], x0
    for count in counts:
        for _ in range(abs(int(count))):
            x = move(x)
        out.append(x)
    if stats is not None:
        stats["nfev"] = int(np.abs(counts).sum())
    path = torch.stack(out, dim=1)
    if not in_model_axis():     # vmap over models cannot branch on a value: the group's trainer checks
        bad = ~torch.isfinite(path).all(dim=2)
        if max_norm is not None:
            bad |= ~(path.detach().abs() <= max_norm).all(dim=2)
        rows = torch.nonzero(bad.any(dim=1)).flatten()
        if len(rows):
            first = bad[rows].to(torch.int8).argmax(dim=1).cpu().numpy()
            raise divergence_error(f"learned map (dt={f.dt:g}, max_norm={max_norm})", rows.tolist(), t[first].tolist())
    return path
