"""Orbit figures for the n-body tasks: one configuration, truth / baseline / HNN side by side.

    orbit_figure(task, result, path)   # PNG: the three orbits and their energies over time
    orbit_gif(task, result, path)      # GIF: the same orbits as a short animation

``result`` is ``hnn.evaluate_energy``'s output for a ``'seeds'`` protocol; trial 0 (the start
state ``system.initial_state(0)``) is drawn. States are
``x = [qx_1..qx_n, qy_1..qy_n, px_1..px_n, py_1..py_n]``, trajectories ``(T, 4n)``.
"""
from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import imageio.v2 as imageio  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hnn_analysis.paper.figures import COLORS, NAMES
from hnn_analysis.plotting import STAMP, save_figure  # noqa: E402
from hnn.io import atomic_write  # noqa: E402

BODY_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown")
GIF = {"frames": 48, "fps": 12, "dpi": 60, "trail": 25}


def _trial0(result: dict) -> tuple[np.ndarray, dict]:
    """``(t (T,), {label: (T, 4n) trajectory})`` of trial 0: truth and every model."""
    paths = {"truth": np.asarray(result["truth"])[0]}
    for label, value in result.items():
        if isinstance(value, dict) and "traj" in value:
            paths[label] = np.asarray(value["traj"])[0]
    return np.asarray(result["t_truth"])[0], paths


def _positions(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(qx, qy)``, each ``(T, n)``, of a trajectory ``(T, 4n)``."""
    n = x.shape[1] // 4
    return x[:, :n], x[:, n:2 * n]


def _limits(paths: dict) -> tuple[float, float]:
    """A square window around the truth's orbits (models that fly off are clipped)."""
    qx, qy = _positions(paths["truth"])
    reach = 1.25 * max(np.abs(qx).max(), np.abs(qy).max())
    return -reach, reach


def orbit_figure(task: str, result: dict, path) -> Path:
    """Panels: orbits of truth, baseline, HNN from trial 0's start state; the true energy over time."""
    t, paths = _trial0(result)
    lo, hi = _limits(paths)
    fig, axes = plt.subplots(1, len(paths) + 1, figsize=(4 * (len(paths) + 1), 4), constrained_layout=True)
    for ax, (label, x) in zip(axes, paths.items()):
        qx, qy = _positions(x)
        for body in range(qx.shape[1]):
            color = BODY_COLORS[body % len(BODY_COLORS)]
            ax.plot(qx[:, body], qy[:, body], color=color, lw=1.2, label=f"body {body + 1}")
            ax.plot(qx[0, body], qy[0, body], "o", color=color, ms=4)
        ax.set(title=NAMES.get(label, label), xlabel="x", ylabel="y", xlim=(lo, hi), ylim=(lo, hi))
        ax.set_aspect("equal")
    axes[0].legend(fontsize=8)
    energy = axes[-1]
    energy.plot(t, np.asarray(result["energy_truth"])[0], color=COLORS["truth"], ls="--", label=NAMES["truth"])
    for label in paths:
        if label != "truth":
            energy.plot(t, np.asarray(result[label]["energy"])[0], color=COLORS.get(label),
                        label=NAMES.get(label, label))
    energy.set(title="Total energy", xlabel="t", ylabel="true H")
    energy.legend(fontsize=8)
    fig.suptitle(f"{task}: one configuration (the energy protocol's seed-0 start), t in [{t[0]:g}, {t[-1]:g}]")
    return save_figure(fig, path)


def orbit_gif(task: str, result: dict, path, frames: int = GIF["frames"], fps: int = GIF["fps"],
              dpi: int = GIF["dpi"], trail: int = GIF["trail"]) -> Path:
    """The three orbits as an animation of ``frames`` frames (each body with a trail of its last ``trail`` frames)."""
    t, paths = _trial0(result)
    lo, hi = _limits(paths)
    index = np.linspace(0, len(t) - 1, frames).round().astype(int)
    step = max(1, int(np.median(np.diff(index))))
    fig, axes = plt.subplots(1, len(paths), figsize=(2.6 * len(paths), 2.8), dpi=dpi,
                             constrained_layout=True)
    artists = []
    for ax, (label, x) in zip(axes, paths.items()):
        qx, qy = _positions(x)
        bodies = []
        for body in range(qx.shape[1]):
            color = BODY_COLORS[body % len(BODY_COLORS)]
            line, = ax.plot([], [], color=color, lw=1)
            dot, = ax.plot([], [], "o", color=color, ms=5)
            bodies.append((line, dot))
        artists.append((qx, qy, bodies))
        ax.set(title=NAMES.get(label, label), xlim=(lo, hi), ylim=(lo, hi), xticks=[], yticks=[])
        ax.set_aspect("equal")
    title = fig.suptitle("")
    images = []
    for i in index:
        first = max(0, i - trail * step)
        for qx, qy, bodies in artists:
            for body, (line, dot) in enumerate(bodies):
                line.set_data(qx[first:i + 1, body], qy[first:i + 1, body])
                dot.set_data([qx[i, body]], [qy[i, body]])
        title.set_text(f"{STAMP['text']} {task}, t = {t[i]:.2f}".strip())
        fig.canvas.draw()
        images.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    buffer = io.BytesIO()
    imageio.mimsave(buffer, images, format="GIF", duration=1000 / fps, loop=0)
    atomic_write(Path(path), lambda tmp: Path(tmp).write_bytes(buffer.getvalue()))
    return Path(path)
