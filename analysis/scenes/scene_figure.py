"""The scene study's Pareto figure: rollout error (the mean over seeds, with its standard error, where
the cell trained at several) against training seconds (the seeds' median) and against rollout seconds
(seed 0's), one row per scene (``figures/scenes-pareto.png``, and docs/figures/ with ``--update-docs``);
every rung, Adam's kinds and the least-squares fits (a kind's colour, its fit's marker: ``scene_rungs``).
"""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402

from hnn.io import atomic_write  # noqa: E402
from hnn_analysis.scenes import scene_measure, scene_rungs  # noqa: E402
from hnn_analysis.scenes.scene_tables import color  # noqa: E402


LEGEND_COLUMNS = 5


def pareto_figure(results: dict, path: Path) -> None:
    """Rollout error (mean over seeds) against training seconds and against rollout seconds, one row per scene."""
    scenes = [t for t, e in results["scenes"].items() if any("rollout" in m for m, _ in _all_cells(e).values())]
    if not scenes:
        return
    fig, axes = plt.subplots(len(scenes), 2, figsize=(9, 2.6 * len(scenes)), squeeze=False)
    legend = {}     # one legend for the figure: a legend in every panel covered its points
    for ax_row, task in zip(axes, scenes):
        cells = _all_cells(results["scenes"][task])
        for ax, xkey, xlabel in ((ax_row[0], "train", "training s (one thread)"), (ax_row[1], None, "rollout s")):
            points = []
            for key, (m, seeds) in cells.items():
                kind = key.split("@")[0]
                ro = m.get("rollout")
                x = (seeds.get("train_seconds_median") or scene_measure.cost_seconds(m)) if xkey else (ro or {}).get("seconds")
                if ro and x:
                    y, se = seeds.get("error_seeds") or (ro["error"], 0.0)
                    points.append((x, y))
                    ax.errorbar(x, y, yerr=se or None, fmt=scene_rungs.marker(kind), ms=3.5, lw=0.8, color=color(kind),
                                label=kind)
            if not points:      # pixels: its rollout comes from the energy protocol, untimed
                ax.axis("off")
                ax.text(0.5, 0.5, f"{task}: no {xlabel} measured", ha="center", va="center", transform=ax.transAxes)
                continue
            front, best = [], float("inf")
            for x, y in sorted(points):
                if y < best:
                    front.append((x, y))
                    best = y
            ax.plot(*zip(*front), color="k", lw=0.8, alpha=0.6)
            ax.set_xscale("log")
            ax.set_yscale("log")
            for axis, values in ((ax.xaxis, [x for x, _ in points]), (ax.yaxis, [y for _, y in points])):
                _log_ticks(axis, min(values), max(values))
            ax.set_xlabel(xlabel)
            ax.set_ylabel(f"{task}: rollout error")
            handles, labels = ax.get_legend_handles_labels()
            legend.update(zip(labels, handles))
    # two lines: as one, the title ran past both edges of the figure
    title = (f"Scene study: rollout error vs cost (black: Pareto front)\nerror: mean ± SE over "
             f"{_seed_words(results)}; training s: the seeds' median; rollout s: seed 0's")
    if results["meta"]["quick"]:
        title = "QUICK smoke run, not the study's settings. " + title
    # the kinds and the fits' rungs: at most LEGEND_COLUMNS to a row, so the legend stays inside the figure;
    # the figure grows by the legend's rows past the first
    columns = min(len(legend), LEGEND_COLUMNS)
    fig.set_figheight(fig.get_figheight() + 0.2 * (math.ceil(len(legend) / columns) - 1))
    inch = 1 / fig.get_figheight()              # one inch in figure coordinates
    fig.suptitle(title, fontsize=10, y=1 - 0.1 * inch, va="top")
    fig.legend(legend.values(), legend.keys(), loc="upper center", ncol=columns, fontsize=8,
               bbox_to_anchor=(0.5, 1 - 0.45 * inch), frameon=False)
    top = 1 - (0.55 + 0.2 * math.ceil(len(legend) / columns)) * inch    # the panels start below the title and legend
    fig.tight_layout(rect=(0, 0, 1, top))
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80, format="png"))
    plt.close(fig)


def _log_ticks(axis, lo: float, hi: float) -> None:
    """Labels a log axis can hold without overlapping: at powers of ten over 2+ decades, also at 2 and
    5 times them over less, at 1-6 and 8 times them under 0.7 of a decade; plain numbers, no minor labels."""
    decades = math.log10(hi / lo) if lo > 0 else math.inf
    subs = (1.0,) if decades > 2 else (1.0, 2.0, 5.0) if decades > 0.7 else (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
    axis.set_major_locator(ticker.LogLocator(10, subs=subs))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:.3g}"))
    axis.set_minor_formatter(ticker.NullFormatter())


def _seed_words(results: dict) -> str:
    meta = results["meta"]
    counts = sorted({len(meta.get("seeds", [0])), len(meta.get("grid_seeds", [0]))})
    return f"{' or '.join(map(str, counts))} seed{'s' if counts[-1] > 1 else ''}"


def _all_cells(entry: dict) -> dict:
    """``{"kind@WIDTHxFRACTION": (seed 0's measured, the seeds' mean ± SE, empty with one seed)}``."""
    cells = {key: (m, (entry.get("grid_seeds") or {}).get(key, {})) for key, m in entry.get("grid", {}).items()}
    for kind, measured in entry["kinds"].items():
        cells[f"{kind}@200x1"] = (next(iter(measured["per_seed"].values())), measured)
    return cells
