"""The speed / accuracy study's report: its full table, the summary of docs/integrators.md and the
Pareto plot of each task (error against seconds, log-log, one line per method and dtype).
"""
from __future__ import annotations

import math
from pathlib import Path

from hnn.io import atomic_write
from hnn_analysis.integrator_study.speed_measure import DTYPES, study_settings
from hnn_analysis.pages import generated_by
from hnn_analysis.provenance import machine

def _fmt(value, spec=".2e") -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def _peer_versions(meta: dict) -> str:
    """``', scipy 1.17.1, torchdiffeq 0.2.5'``: the peers' packages the rows ran (absent from older records)."""
    return "".join(f", {name} {version}" for name, version in meta.get("peers", {}).items() if version)


def _details(meta: dict) -> str:
    """The study's machine, versions, threads, mode and seconds, for its pages' provenance."""
    return (f"{machine(meta)}, torch {meta['torch']}{_peer_versions(meta)}, {meta['threads']} thread(s), {meta['mode']}, "
            f"{meta['seconds']:.0f} s")


def markdown(results: dict) -> str:
    meta = results["meta"]
    lines = [generated_by(meta, _details(meta)) + ". Error: max |x - x_ref| against DOP853 at rtol 1e-12 "
             "(float64, same field); drift: max |H(t) - H(0)| (learned H for the HNN, true H otherwise); "
             "seconds: median wall time of one batched rollout.", ""]
    for task, rows in results["tasks"].items():
        cfg = study_settings(task)
        lines += [f"**{task}** ({cfg['batch']} start states, t in [0, {cfg['T']:g}])", "",
                  "| model | method | setting | dtype | seconds | nfev | error | energy drift |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in rows:
            if r["status"] != "ok":
                lines.append(f"| {r['model']} | {r['method']} | {r['setting']} | {r['dtype']} | {r['status']} | | | |")
                continue
            lines.append(f"| {r['model']} | {r['method']} | {r['setting']} | {r['dtype']} | {r['seconds']:.3f} | "
                         f"{r['nfev']} | {_fmt(r['error'])} | {_fmt(r['energy_drift'])} |")
        lines.append("")
    lines += ["**Extremes** (float64)", "", "| case | method | setting | outcome | seconds | error | relative energy error |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in results["extremes"]:
        outcome = "ok" if r["status"] == "ok" else f"{r['status']}: {r.get('message', '')}"
        lines.append(f"| {r['case']} | {r['method']} | {r['setting']} | {outcome} | {_fmt(r.get('seconds'), '.3f')} | "
                     f"{_fmt(r.get('error'))} | {_fmt(r.get('rel_energy_error'))} |")
    for note in results["notes"]:
        lines += ["", f"Note: {note}"]
    return "\n".join(lines) + "\n"


TARGET = 1e-4      # the summary's accuracy target: max error against the reference


def summary_markdown(results: dict) -> str:
    """docs/integrators.md's table: per task, model and method, the fastest float64 setting reaching
    ``TARGET``, and the smallest error each dtype reached (its floor), then the extremes."""
    meta = results["meta"]
    lines = [generated_by(meta, _details(meta)) + f"; every row in `{meta.get('out', 'results/speed_accuracy')}/speed_accuracy.md`. "
             f"Fastest: the quickest float64 setting with max error <= {TARGET:g} against DOP853 rtol 1e-12 of the "
             "same field (seconds, evaluations of the field, energy drift max |H(t) - H(0)|: the learned H for the "
             "HNN, the true H otherwise). Floor: the smallest error any setting reached in each dtype.", "",
             "| task | model | method | fastest setting | seconds | nfev | error | energy drift | floor float32 | floor float64 |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for task, rows in results["tasks"].items():
        for model in dict.fromkeys(r["model"] for r in rows):
            for method in dict.fromkeys(r["method"] for r in rows):
                mine = [r for r in rows if r["model"] == model and r["method"] == method and r["status"] == "ok"]
                if not mine:
                    continue
                good = [r for r in mine if r["dtype"] == "float64" and r["error"] <= TARGET]
                best = min(good, key=lambda r: r["seconds"]) if good else None
                floors = [_fmt(min((r["error"] for r in mine if r["dtype"] == d), default=None)) for d in DTYPES]
                cells = (f"{best['setting']} | {best['seconds']:.3f} | {best['nfev']} | {_fmt(best['error'])} | "
                         f"{_fmt(best['energy_drift'])}") if best else "not reached | | | |"
                lines.append(f"| {task} | {model} | {method} | {cells} | {floors[0]} | {floors[1]} |")
    text = "\n".join(lines) + "\n"
    extremes_part = markdown(results).split("**Extremes**", 1)[1]
    return text + "\n**Extremes**" + extremes_part


def pareto_plot(task: str, rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    models = list(dict.fromkeys(r["model"] for r in rows))
    fig, axes = plt.subplots(1, len(models), figsize=(5 * len(models), 4), squeeze=False)
    for ax, model in zip(axes[0], models):
        for (method, dtype) in sorted({(r["method"], r["dtype"]) for r in rows if r["model"] == model}):
            pts = sorted((r["seconds"], r["error"]) for r in rows if r["model"] == model and r["method"] == method
                         and r["dtype"] == dtype and r["status"] == "ok" and r["error"] > 0)
            if pts:
                ax.loglog(*zip(*pts), "o-" if dtype == "float64" else "x--", label=f"{method} {dtype}", ms=4)
        ax.set(title=f"{task}: {model}", xlabel="wall time of the rollout (s)", ylabel="max error vs DOP853 rtol 1e-12")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
