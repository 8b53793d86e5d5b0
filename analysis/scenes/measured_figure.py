"""The figure of a measured scene: each held-out tail's measured positions beside each model's prediction
from the tail's first sample, over the whole tail (``analysis/score.py --plot`` draws it for a run of
``experiment-measured``, one model or one of each kind).

    tails_figure({"hnn": mm.Model(...)}, held, out / "tails.png", "real_pend_h_1")
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hnn_analysis.plotting import save_figure
from hnn_analysis.scenes import measured_metrics as mm

import matplotlib.pyplot as plt  # noqa: E402  (after plotting: the Agg backend)

TAILS = 4           # the figure shows at most this many trials' tails


def tails_figure(models: dict, held: mm.Heldout, path, title: str) -> Path:
    """One column per held-out tail (the first ``TAILS``), one row per position: the measurement (dashed)
    and each of ``models`` (``{label: measured_metrics.Model}``) rolled out from the tail's first sample,
    in the file's units; a prediction that leaves the plot is clipped to the measurement's range."""
    rec = held.rec
    n, tails = rec.q.shape[1], held.tails[:TAILS]
    fig, axes = plt.subplots(n, len(tails), squeeze=False, figsize=(4.2 * len(tails), 2.3 * n + 0.6),
                             constrained_layout=True)
    for j, rows in enumerate(tails):
        t = rec.t[rows] - rec.t[rows[0]]
        predicted = {label: model.rollout(rec, rows[:1], t)[0][0] for label, model in models.items()}
        for i in range(n):
            ax, q = axes[i, j], rec.q[rows, i]
            ax.plot(t, q, color="black", ls="--", lw=1.2, label="measured")
            for label, q_hat in predicted.items():
                ax.plot(t, q_hat[:, i], lw=1.2, label=label)
            pad = 0.25 * (np.ptp(q) or 1.0)
            ax.set_ylim(q.min() - pad, q.max() + pad)
            ax.set(xlabel=f"s from the tail's start (trial {rec.trial[rows[0]]:g})" if i == n - 1 else None,
                   ylabel=rec.q_names[i] if j == 0 else None)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{title}: held-out tails, measured against each model's prediction from the tail's first sample")
    return save_figure(fig, path)
