"""The paper's "other mischief" for 1-DOF tasks: the energy bump and time reversibility.

    hnn.evaluation.energy_bump(model, x0, ...)           # flow, climb grad H, flow again: the learned H steps up
    reversibility(models, x0, horizons)       # forward T then backward T: |x_back - x0| per model
    energy_bump_figures(task, system, models, x0, fig_dir)   # each as a PNG, and its numbers
    reversibility_figures(task, models, x0, fig_dir)

Models are integrated in float64 copies (the trained float32 weights, evaluated in float64) so
the curves show the fields, not float32 rounding. States are ``x = [q, p]`` ``(batch, 2)``.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

import hnn  # noqa: E402
from hnn_analysis.paper.figures import COLORS, NAMES
from hnn_analysis.plotting import save_figure  # noqa: E402

# flow for t_flow, climb the gradient of the learned H for t_bump, flow again for t_flow
BUMP = {"t_flow": 6.0, "t_bump": 0.1, "points": 300}
HORIZONS = (1.0, 2.0, 5.0, 10.0, 20.0)
# moderate tolerances on purpose: reversibility measures how integration errors grow when
# the flow is run back, which is what separates a volume-preserving field from one that is not
REVERSE_TOL = {"rtol": 1e-6, "atol": 1e-8}


def reversibility(models: dict, x0, horizons=HORIZONS, rtol: float = REVERSE_TOL["rtol"],
                  atol: float = REVERSE_TOL["atol"]) -> dict:
    """For each model and each T in ``horizons``: integrate ``dx/dt = f(x)`` from ``x0`` for T,
    then ``dx/dt = -f(x)`` for T, and measure ``|x_back - x0|`` (Euclidean). ``None`` where a
    trajectory diverged. Returns ``{label: [error per T]}``.
    """
    x0 = torch.tensor([x0], dtype=torch.float64)
    out = {}
    for label, model in models.items():
        f = hnn.evaluation.float64_copy(model).time_derivative
        errors = []
        for horizon in horizons:
            try:
                with torch.no_grad():
                    ahead = hnn.rollout(f, x0, [0.0, horizon], rtol=rtol, atol=atol)[:, -1]
                    back = hnn.rollout(lambda x, f=f: -f(x), ahead, [0.0, horizon], rtol=rtol, atol=atol)[:, -1]
                errors.append(float((back - x0).norm()))
            except hnn.DivergenceError:
                errors.append(None)
        out[label] = errors
    return out


def _paths_there_and_back(model, x0, horizon: float, points: int = 400):
    """``(forward (T, 2), backward (T, 2))`` paths for the figure, or ``(None, None)`` on divergence."""
    f = hnn.evaluation.float64_copy(model).time_derivative
    t = np.linspace(0.0, horizon, points)
    try:
        with torch.no_grad():
            ahead = hnn.rollout(f, torch.tensor([x0], dtype=torch.float64), t, **REVERSE_TOL)[0]
            back = hnn.rollout(lambda x: -f(x), ahead[-1:], t, **REVERSE_TOL)[0]
        return ahead.numpy(), back.numpy()
    except hnn.DivergenceError:
        return None, None


def bump_figure(task: str, system, bump: dict, path) -> Path:
    """Phase-space path coloured by stage, and the learned (and true) H over time."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    styles = [("tab:blue", "symplectic field"), ("tab:red", "dx/dt = dH/dx (bump)"), ("tab:green", "symplectic field again")]
    for stage, (color, label) in enumerate(styles):
        keep = bump["stage"] == stage
        axes[0].plot(bump["x"][keep, 0], bump["x"][keep, 1], color=color, lw=1.5 if stage != 1 else 3, label=label)
        axes[1].plot(bump["t"][keep], bump["H"][keep], color=color, lw=1.5)
    axes[0].plot(*bump["x"][0], "o", color="black", ms=4)
    axes[0].set(title="HNN path", xlabel="q", ylabel="p")
    axes[0].set_aspect("equal", adjustable="datalim")
    axes[0].legend(fontsize=8)
    with torch.no_grad():
        true_h = system.hamiltonian(torch.from_numpy(bump["x"])).numpy()
    twin = axes[1].twinx()
    twin.plot(bump["t"], true_h, color="0.5", ls="--", lw=1, label="true H (right axis)")
    twin.set_ylabel("true H", color="0.4")
    twin.legend(fontsize=8, loc="lower right")
    axes[1].set(title=f"learned H: {bump['H_before']:.3g} before, {bump['H_after']:.3g} after",
                xlabel="t", ylabel="learned H (HNN's F2)")
    fig.suptitle(f"{task}: energy bump, following the gradient of the learned H for a short time")
    return save_figure(fig, path)


def reversibility_figure(task: str, models: dict, x0, horizons, errors: dict, path) -> Path:
    """|x_back - x0| against T per model, and the forward / backward paths for the longest T."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for label, errs in errors.items():
        keep = [(h, e) for h, e in zip(horizons, errs) if e is not None]
        if keep:
            axes[0].plot(*zip(*keep), "o-", color=COLORS.get(label), label=NAMES.get(label, label))
    axes[0].set(xscale="log", yscale="log", xlabel="T", ylabel="|x_back - x0|", title="forward T, then backward T")
    axes[0].legend(fontsize=8)
    horizon = horizons[-1]
    for label, model in models.items():
        ahead, back = _paths_there_and_back(model, x0, horizon)
        if ahead is None:
            continue
        axes[1].plot(ahead[:, 0], ahead[:, 1], color=COLORS.get(label), lw=1.2, label=f"{NAMES.get(label, label)}, forward")
        axes[1].plot(back[:, 0], back[:, 1], color=COLORS.get(label), lw=1.2, ls=":", label="backward")
        axes[1].plot(*back[-1], "x", color=COLORS.get(label), ms=8)
    axes[1].plot(*x0, "o", color="black", ms=4)
    axes[1].set(title=f"paths for T = {horizon:g} (x: where backward ends)", xlabel="q", ylabel="p")
    axes[1].set_aspect("equal", adjustable="datalim")
    axes[1].legend(fontsize=7)
    fig.suptitle(f"{task}: time reversibility from x0 = ({x0[0]:.3g}, {x0[1]:.3g}), "
                 f"RK45 rtol {REVERSE_TOL['rtol']:g} atol {REVERSE_TOL['atol']:g}")
    return save_figure(fig, path)


def energy_bump_figures(task: str, system, models: dict, x0, fig_dir: Path) -> dict:
    """``<task>-energy-bump.png`` of the HNN from ``x0``; returns ``{"energy_bump": its numbers}``."""
    bump = hnn.evaluation.energy_bump(models["hnn"], x0, **BUMP)
    bump_figure(task, system, bump, Path(fig_dir) / f"{task}-energy-bump.png")
    numbers = {k: bump[k] for k in ("H_before", "H_after", "H_spread_before", "H_spread_after")}
    return {"energy_bump": {**numbers, "x0": list(x0), **BUMP}}


def reversibility_figures(task: str, models: dict, x0, fig_dir: Path) -> dict:
    """``<task>-reversibility.png`` of every model from ``x0``; returns ``{"reversibility": its numbers}``."""
    errors = reversibility(models, x0)
    reversibility_figure(task, models, x0, HORIZONS, errors, Path(fig_dir) / f"{task}-reversibility.png")
    return {"reversibility": {"x0": list(x0), "T": list(HORIZONS), **REVERSE_TOL, "error": errors}}
