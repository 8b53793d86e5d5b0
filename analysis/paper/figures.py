"""The paper's figures for the 1-DOF tasks (spring, pend, real), as plain plotting functions.

    field_figure(task, system, models, dataset, path)   # data, true / baseline / HNN vector fields
    integration_figure(task, system, models, path)      # paths, coordinate MSE, learned H, true energy
    energy_figure(task, result, path)                   # output of hnn.evaluate_energy, per trial
    real_figure(task, models, dataset, energy, path)    # real pendulum: data arrows, learned fields, energy

``system`` is a task's data module (``dynamics`` and ``hamiltonian`` on float64 ``(batch, 2)``
tensors); ``models`` is ``{label: model}``: the paper's ``{"baseline": ..., "hnn": ...}``, or any run's
(``analysis/score.py --plot`` draws one), a panel or a line each. Each function writes one PNG
atomically and returns its path. States are ``x = [q, p]``; trajectories are ``(T, 2)`` arrays.
"""
from __future__ import annotations

import textwrap
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

import hnn  # noqa: E402
from hnn_analysis.plotting import save_figure  # noqa: E402

# the truth in black, each model kind in the colour it registered (hnn.kinds.ModelKind.color)
COLORS = {"truth": "black", **{kind: spec.color for kind, spec in hnn.MODEL_KINDS.items()}}
NAMES = {"truth": "Ground truth", "baseline": "Baseline NN", "hnn": "Hamiltonian NN"}


def phase_settings(task: str, figure: str) -> dict:
    """The settings of ``figure`` (``'fields'``, ``'integration'``) from the task's ``task.py``:
    its ``figure_settings[figure]`` with the shared start state ``x0`` (the original notebooks' values)."""
    settings = hnn.task_spec(task).figure_settings
    if figure not in settings:
        raise ValueError(f"task {task!r} has no {figure!r} figure settings: add figure_settings="
                         f"{{'x0': ..., '{figure}': {{...}}}} to its task.py")
    return {"x0": tuple(settings["x0"]), **settings[figure]}


def _name(label: str) -> str:
    return NAMES.get(label, label)


def _dtype(model) -> torch.dtype:
    return next(model.parameters()).dtype


def _field(f, x: torch.Tensor, dtype=torch.float64) -> np.ndarray:
    """``f`` at the states ``x`` ``(N, 2)``, evaluated in ``dtype`` without grad; ``(N, 2)`` float64."""
    with torch.no_grad():
        return f(x.to(dtype)).to(torch.float64).numpy()


def _rollout(f, x0, t: np.ndarray, dtype=torch.float64):
    """``(trajectory (T, 2) float64 or None, error message or None)``; a divergence is reported, not raised."""
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # the notebooks' rtol 1e-12 (atol solve_ivp's 1e-6) on float32 models: known, and not what the figure
            # is about
            warnings.filterwarnings("ignore", message=".*tighter than torch.float32", category=UserWarning)
            traj = hnn.rollout(f, torch.tensor([x0], dtype=dtype), t, rtol=1e-12, atol=1e-6)
        return traj[0].to(torch.float64).numpy(), None
    except hnn.DivergenceError as err:
        return None, textwrap.fill(f"diverged: {err}", 40, max_lines=4, placeholder=" ...")


def _note(ax, text: str) -> None:
    """A boxed message in the middle of a panel (used where a trajectory could not be drawn)."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=8, wrap=True,
            bbox={"facecolor": "white", "edgecolor": "gray", "alpha": 0.9})


def _time_path(ax, traj: np.ndarray, t: np.ndarray, cmap="viridis"):
    """Draw ``traj`` ``(T, 2)`` as segments coloured by ``t`` ``(T,)``; returns the LineCollection."""
    segments = np.stack([traj[:-1], traj[1:]], axis=1)
    lines = LineCollection(segments, cmap=cmap, norm=plt.Normalize(t[0], t[-1]), linewidths=1.5)
    lines.set_array((t[:-1] + t[1:]) / 2)
    ax.add_collection(lines)
    return lines


def field_figure(task: str, system, models: dict, dataset: dict, path, settings: dict | None = None) -> Path:
    """Phase-plane panels: training data over the true field, then the true field and each model's
    (quiver on a ``gridsize x gridsize`` grid) each with its trajectory from ``x0``, coloured by time.

    ``dataset["x"]`` holds the training states, ``(rows, 2)``; ``settings`` (``lim``, ``gridsize``,
    ``x0``, ``t_span``, ``num_points``) default to ``phase_settings(task, "fields")``.
    """
    s = settings or phase_settings(task, "fields")
    lim, n = s["lim"], s["gridsize"]
    axis = torch.linspace(-lim, lim, n, dtype=torch.float64)
    qq, pp = torch.meshgrid(axis, axis, indexing="xy")
    grid = torch.stack([qq.reshape(-1), pp.reshape(-1)], dim=1)             # (n*n, 2)
    t = np.linspace(*s["t_span"], s["num_points"])
    data_x = np.asarray(dataset["x"], dtype=np.float64).reshape(-1, 2)

    panels = [("Data", system.dynamics, torch.float64, None),
              ("Ground truth", system.dynamics, torch.float64, "truth")]
    panels += [(_name(label), model.time_derivative, _dtype(model), label) for label, model in models.items()]
    fig, axes = plt.subplots(1, len(panels), figsize=(4 * len(panels), 4.3), constrained_layout=True)
    lines = None
    for ax, (title, f, dtype, label) in zip(axes, panels):
        uv = _field(f, grid, dtype)
        ax.quiver(grid[:, 0], grid[:, 1], uv[:, 0], uv[:, 1], color="0.45", pivot="mid", width=0.006)
        if label is None:
            ax.scatter(data_x[:, 0], data_x[:, 1], s=4, color="tab:orange", alpha=0.6)
        else:
            traj, err = _rollout(f, s["x0"], t, dtype)
            if traj is None:
                _note(ax, f"trajectory from x0 = {s['x0']}\n{err}")
            else:
                lines = _time_path(ax, traj, t)
        ax.set(title=title, xlabel="q", ylabel="p", xlim=(-lim * 1.1, lim * 1.1), ylim=(-lim * 1.1, lim * 1.1))
        ax.set_aspect("equal")
    if lines is not None:
        fig.colorbar(lines, ax=axes, shrink=0.8, label="t")
    fig.suptitle(f"{task}: vector fields and trajectories from x0 = {s['x0']}")
    return save_figure(fig, path)


def integration_figure(task: str, system, models: dict, path, settings: dict | None = None) -> Path:
    """Four panels for one rollout from ``x0`` on ``t`` ``(T,)``: (a) phase-plane paths of the truth and
    each model; (b) coordinate MSE vs time, mean over (q, p) of the squared error vs truth; (c) the
    learned H of the first model that has one (the HNN's) along each path; (d) the true energy
    ``system.hamiltonian`` along each path.
    ``settings`` (``x0``, ``t_span``, ``num_points``) default to ``phase_settings(task, "integration")``.
    """
    s = settings or phase_settings(task, "integration")
    t = np.linspace(*s["t_span"], s["num_points"])
    paths, errors = {}, {}
    for label, f, dtype in [("truth", system.dynamics, torch.float64)] + [
            (label, model.time_derivative, _dtype(model)) for label, model in models.items()]:
        paths[label], errors[label] = _rollout(f, s["x0"], t, dtype)
    drawn = {k: v for k, v in paths.items() if v is not None}
    learned = next((label for label, model in models.items() if hnn.interface.declared(model).conservative), None)

    fig, axes = plt.subplots(1, 4, figsize=(17, 4), constrained_layout=True)
    for label, traj in drawn.items():
        style = {"color": COLORS.get(label), "label": _name(label), "lw": 1.2 if label == "truth" else 1.5}
        if label == "truth":
            style.update(ls="--", zorder=3)   # on top: a good HNN path would hide it
        axes[0].plot(traj[:, 0], traj[:, 1], **style)
        if label != "truth" and "truth" in drawn:
            axes[1].plot(t, ((traj - drawn["truth"]) ** 2).mean(axis=1), **style)
        with torch.no_grad():
            true_h = system.hamiltonian(torch.from_numpy(traj))
            if learned is not None:
                model = models[learned]
                learned_h = model.hamiltonian(torch.from_numpy(traj).to(_dtype(model)))
                axes[2].plot(t, learned_h.to(torch.float64).numpy(), **style)
        axes[3].plot(t, true_h.numpy(), **style)
    if learned is None:
        _note(axes[2], "no model here learns an H")
    failed = [f"{_name(k)} {e}" for k, e in errors.items() if e]
    if failed:
        _note(axes[0], "\n".join(failed))
    axes[0].plot(*s["x0"], "o", color="black", ms=4)
    axes[0].set(title="Predictions", xlabel="q", ylabel="p")
    axes[0].set_aspect("equal", adjustable="datalim")
    axes[1].set(title="MSE between coordinates", xlabel="t", ylabel="mean over (q, p) of squared error")
    who = "HNN" if learned in (None, "hnn") else _name(learned)
    axes[2].set(title=f"{who}-conserved quantity", xlabel="t", ylabel=f"learned H ({who}'s F2)")
    axes[3].set(title="Total energy", xlabel="t", ylabel="true H")
    axes[0].legend(fontsize=8, loc="upper right")
    fig.suptitle(f"{task}: integration from x0 = {s['x0']}, t in [{t[0]:g}, {t[-1]:g}] ({len(t)} points)")
    return save_figure(fig, path)


def energy_figure(task: str, result: dict, path) -> Path:
    """Energy over time for each trial of ``hnn.evaluate_energy``'s ``result``: truth vs every model.

    Uses ``result["energy_truth"]`` and ``result[label]["energy"]`` (each ``(trials, T)``) against
    ``result["t_truth"]`` ``(trials, T)``: the points the MSE compares. Under the paper's spring
    protocol the models' own clock runs ``time_rescale`` faster; that is stated in the title.
    """
    protocol = result["protocol"]
    # a model the protocol does not apply to (a map under a protocol that rescales time) has no energies to draw
    labels = [k for k, v in result.items() if k != "protocol" and isinstance(v, dict) and v.get("energy") is not None]
    e_true, t_truth = np.asarray(result["energy_truth"]), np.asarray(result["t_truth"])
    trials = e_true.shape[0]
    ncols = min(5, trials)
    nrows = -(-trials // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 2.4 * nrows), squeeze=False,
                             constrained_layout=True)
    for i, ax in enumerate(axes.flat):
        if i >= trials:
            ax.axis("off")
            continue
        ax.plot(t_truth[i], e_true[i], color=COLORS["truth"], ls="--", lw=1.2, label=NAMES["truth"])
        for label in labels:
            # a learned map's energies are at its own steps (``times``), not the truth's points
            t_model = result[label]["times"] if "times" in result[label] else t_truth[i]
            ax.plot(t_model, np.asarray(result[label]["energy"])[i], color=COLORS.get(label),
                    lw=1.2, label=NAMES.get(label, label))
        ax.set_title(f"trial {i}, x0 = ({result['x0'][i][0]:.2f}, {result['x0'][i][1]:.2f})"
                     if "x0" in result else f"trial {i}", fontsize=8)
        ax.tick_params(labelsize=7)
        if i % ncols == 0:
            ax.set_ylabel("q^2 + p^2" if protocol.get("energy") == "q2+p2" else "true H", fontsize=8)
        if i // ncols == nrows - 1:
            ax.set_xlabel("t (truth clock)", fontsize=8)
    handles, names = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncol=len(names), fontsize=9)
    scores = ", ".join(f"{NAMES.get(k, k)} MSE {result[k]['mse']:.3e}"
                       + (f" ± {result[k]['mse_se']:.1e}" if "mse_se" in result[k] else "") for k in labels)
    quirk = (f"; models' clock x{protocol['time_rescale']:g} (paper quirk)"
             if protocol.get("time_rescale") else "")
    fig.suptitle(f"{task}, energy protocol '{protocol['name']}' (energy = {protocol.get('energy')}{quirk})\n{scores}")
    return save_figure(fig, path)


def real_figure(task: str, models: dict, dataset: dict, energy: dict | None, path) -> Path:
    """The real pendulum, which has no known true field: (a) the measured states with the
    measured derivatives (forward differences) as arrows; then each model's field (the paper's: baseline,
    HNN) on a grid spanning the data, over the data; last, the energy along the measured test segment,
    measured vs each model's rollout from its first state (``energy`` is the paper protocol's
    ``hnn.evaluate_energy`` result; the panel is left out when it is None).
    """
    x = np.asarray(dataset["x"], dtype=np.float64)
    dxdt = np.asarray(dataset["dxdt"], dtype=np.float64)
    lo, hi = x.min(axis=0), x.max(axis=0)
    pad = 0.1 * (hi - lo)
    n = 12
    qq, pp = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], n), np.linspace(lo[1] - pad[1], hi[1] + pad[1], n))
    grid = torch.from_numpy(np.stack([qq.ravel(), pp.ravel()], axis=1))
    panels = 1 + len(models) + (energy is not None)
    fig, axes = plt.subplots(1, panels, figsize=(4.3 * panels, 4.2), constrained_layout=True)
    # each arrow is the measured derivative times 0.1 s, drawn in data units
    axes[0].quiver(x[::2, 0], x[::2, 1], dxdt[::2, 0], dxdt[::2, 1], color="tab:orange", angles="xy",
                   scale_units="xy", scale=10.0, width=0.003)
    axes[0].set(title="Data: measured states, derivative x 0.1 s")
    for ax, (label, model) in zip(axes[1:], models.items()):
        uv = _field(model.time_derivative, grid, _dtype(model))
        ax.quiver(grid[:, 0], grid[:, 1], uv[:, 0], uv[:, 1], color="0.45", pivot="mid", angles="xy", width=0.005)
        ax.scatter(x[:, 0], x[:, 1], s=3, color="tab:orange", alpha=0.5)
        ax.set(title=_name(label))
    for ax in axes[:1 + len(models)]:
        ax.set(xlabel="q (angle)", ylabel="p (angular velocity)")
    if energy is not None:
        t, ax = np.asarray(energy["t_truth"])[0], axes[-1]
        ax.plot(t, np.asarray(energy["energy_truth"])[0], color=COLORS["truth"], ls="--", label="Measured")
        for label in models:
            ax.plot(t, np.asarray(energy[label]["energy"])[0], color=COLORS.get(label), label=_name(label))
        ax.set(title="Energy on the test segment", xlabel="t (s, from the segment's start)",
               ylabel="2.4 (1 - cos q) + p^2")
        ax.legend(fontsize=8)
    fig.suptitle(f"{task}: measured pendulum (Schmidt & Lipson 2009), data and learned fields")
    return save_figure(fig, path)
