"""The pixel pendulum's figures: what the models see, what they learned, and what they predict.

Drawn by the figure registry (``hnn_analysis.paper.registry``) under the names the task's ``task.py`` lists:

- ``pixels-compare.gif``: the 200 test frames, truth | baseline | HNN, each decoded from its
  model's latent path (the paper's ``pixels-compare.gif``);
- ``pixels-compare-static.png``: every 6th of the first 100 frames of each, and q over time;
- ``pixels-energy.png``: the energy 1.9 (1 - cos q) + p^2 of truth, baseline and HNN;
- ``pixels-phase-space.png``: each model's latents of the training frames; for the HNN with the
  contours of its learned H;
- ``pixels-add-energy.gif`` / ``.png``: the paper's demo (flow, climb grad H, flow), decoded.

``result`` is the paper protocol's output of the task's ``metric.evaluate_pixel_energy``;
``models`` are PixelHNNs.
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

SIDE = 28


def _first_frames(pixels: np.ndarray) -> np.ndarray:
    return np.asarray(pixels)[:, :SIDE * SIDE].reshape(-1, SIDE, SIDE)


def compare_static(result: dict, path, every: int = 6, upto: int = 100) -> Path:
    """Rows truth / baseline / HNN of frames 0, every, ... < upto; below, q over time."""
    rows = {"truth": result["truth"]["pixels"], **{k: v["decoded"] for k, v in result.items() if k in COLORS and k != "truth"}}
    idx = np.arange(0, upto, every)
    fig = plt.figure(figsize=(12, 1.0 * len(rows) + 3), constrained_layout=True)
    grid = fig.add_gridspec(len(rows) + 1, 1, height_ratios=[1] * len(rows) + [2.5])
    for i, (label, pixels) in enumerate(rows.items()):
        ax = fig.add_subplot(grid[i])
        strip = np.concatenate([np.pad(f, 1, constant_values=0.5) for f in _first_frames(pixels)[idx]], axis=1)
        ax.imshow(strip, cmap="gray", vmin=0, vmax=0.5)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_ylabel(NAMES[label], rotation=0, ha="right", va="center", fontsize=9)
    ax = fig.add_subplot(grid[-1])
    ax.plot(result["truth"]["coords"][:upto, 0], color=COLORS["truth"], label=NAMES["truth"])
    for label in rows:
        if label != "truth":
            ax.plot(result[label]["coords"][:upto, 0], color=COLORS[label], label=NAMES[label])
    ax.set_xlabel("frame")
    ax.set_ylabel("q (rad), decoded then mapped linearly")
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def energy_plot(result: dict, path) -> Path:
    fig, ax = plt.subplots(figsize=(6, 3.5), constrained_layout=True)
    ax.plot(result["truth"]["energy"], color=COLORS["truth"], label=NAMES["truth"])
    for label in ("baseline", "hnn"):
        if label in result:
            ax.plot(result[label]["energy"], color=COLORS[label],
                    label=f"{NAMES[label]} (MSE {result[label]['mse']:.2e})")
    ax.set_xlabel("frame")
    ax.set_ylabel("energy 1.9 (1 - cos q) + p^2")
    # log: a baseline that blows up (1e6) would flatten the truth and the HNN into one line at 0
    ax.set_yscale("log")
    ax.set_title("Pixel pendulum: energy of the decoded paths")
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def phase_space(models: dict, dataset: dict, path, points: int = 3000) -> Path:
    """Training latents of each model; the HNN's panel adds the contours of its learned H."""
    fig, axes = plt.subplots(1, len(models), figsize=(4.5 * len(models), 4), constrained_layout=True, squeeze=False)
    pixels = torch.as_tensor(dataset["pixels"][:points])
    for ax, (label, model) in zip(axes[0], models.items()):
        with torch.no_grad():
            z = model.encode(pixels.to(next(model.parameters()).dtype)).double().numpy()
        ax.scatter(z[:, 0], z[:, 1], s=2, c=dataset["coords"][:points, 0], cmap="twilight")
        if not model.baseline:
            lo, hi = z.min(0), z.max(0)
            pad = 0.15 * (hi - lo)
            g0, g1 = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], 50),
                                 np.linspace(lo[1] - pad[1], hi[1] + pad[1], 50))
            grid = torch.as_tensor(np.stack([g0.ravel(), g1.ravel()], 1), dtype=next(model.parameters()).dtype)
            with torch.no_grad():
                h = model.hamiltonian(grid).double().numpy().reshape(g0.shape)
            ax.contour(g0, g1, h, levels=15, cmap="viridis", linewidths=0.8)
        ax.set_xlabel("latent z_q")
        ax.set_ylabel("latent z_p")
        ax.set_title(f"{NAMES[label]}: latents" + ("" if model.baseline else " and learned H")
                     + " (colour: true q)", fontsize=10)
    return save_figure(fig, path)


def compare(result: dict, gif_path, png_path) -> None:
    """The test frames, truth | baseline | HNN, as a GIF, and ``compare_static`` as a PNG."""
    panels = {"truth": result["truth"]["pixels"], **{k: result[k]["decoded"] for k in ("baseline", "hnn") if k in result}}
    hnn.gifs.write_gif(panels, gif_path)
    compare_static(result, png_path)


def add_energy(model, z0, gif_path, png_path, settings: dict) -> dict:
    """The paper's add-energy demo (``hnn.evaluation.energy_bump(model, z0, **settings)``), decoded to frames
    (GIF) and plotted (latent path, learned H)."""
    bump = hnn.evaluation.energy_bump(model, z0, **settings)
    with torch.no_grad():
        frames = model.decode(torch.as_tensor(bump["x"], dtype=next(model.parameters()).dtype)).numpy()
    hnn.gifs.write_gif({"add energy": frames[::3]}, gif_path)
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.5), constrained_layout=True)
    for stage, name in enumerate(("flow", "climb grad H", "flow again")):
        sel = bump["stage"] == stage
        ax0.plot(bump["x"][sel, 0], bump["x"][sel, 1], lw=1, label=name)
        ax1.plot(bump["t"][sel], bump["H"][sel], lw=1.5, label=name)
    ax0.set_xlabel("latent z_q")
    ax0.set_ylabel("latent z_p")
    ax0.legend(fontsize=8)
    ax1.set_xlabel("time (frames)")
    ax1.set_ylabel("learned H")
    ax1.set_title(f"H {bump['H_before']:.3g} -> {bump['H_after']:.3g}", fontsize=10)
    save_figure(fig, png_path)
    return {k: bump[k] for k in ("H_before", "H_after", "H_spread_before", "H_spread_after")}
