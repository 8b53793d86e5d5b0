"""The paper's tables as markdown, built from ``results.json`` (never typed): ``tables_markdown``
(every task, ours beside the paper's, marked, with the stage times) and ``headline_markdown`` (the
README's table, mean +- standard error across seeds); ``compare`` marks one number against the
paper's +-."""
from __future__ import annotations

import math

import numpy as np

import hnn
from hnn.tasks import PAPER
from hnn_analysis.pages import stage_table
from hnn_analysis.pages import generated_by

MODELS = ("baseline", "hnn")            # the paper's pair, each task's table rows
METRICS = (("train_loss", "Train loss"), ("test_loss", "Test loss"))
MARKS = {"within": "✓", "better": "↓", "worse": "↑"}
QUICK_NOTE = ("No marks against the paper: a QUICK run trains a few hundred steps where the paper trained 2,000-10,000, "
              "so a gap to the paper says how short the run was, not how the code compares. Its ratios can be "
              "astronomical (a pixel baseline's energy MSE of millions of times the paper's, say): the energy MSE "
              "squares the energy error along a whole rollout, and an undertrained field drifts far from the "
              "true orbit. Drop --quick for the paper's settings and marks.")
STEPS_NOTE = ("No marks against the paper: --steps {steps} trains {steps} steps a model where the paper trained "
              "2,000-10,000, so a gap to the paper says how long the run was, not how the code compares. Drop "
              "--steps for the paper's settings and marks.")
LEGEND = ("Marks: ✓ within the paper's ± (|ours − paper| ≤ the paper's ±); ↓ lower than the paper beyond "
          "its ± (better); ↑ higher than the paper beyond its ± (worse).")


def _fmt(pair) -> str:
    return "n/a" if pair is None else f"{pair[0]:.4e} ± {pair[1]:.2e}"


def _ratio(ours, paper) -> str:
    if ours is None or paper is None:
        return ""
    ratio = ours[0] / paper[0]
    return f"{ratio:.2f}x" if ratio >= 0.01 else f"{ratio:.1e}x"


def compare(ours, paper, spread: float | None = None) -> str | None:
    """``'within'`` when |ours - paper| <= the band (the paper's ±, or ``spread`` where that is
    larger; equality up to rounding counts as within), else ``'better'`` (lower) or ``'worse'``
    (higher); None when either is missing. ``ours`` and ``paper`` are ``(mean, ±)`` pairs.
    """
    if ours is None or paper is None:
        return None
    gap, band = abs(ours[0] - paper[0]), max(abs(paper[1]), abs(spread or 0.0))
    if gap <= band or math.isclose(gap, band, rel_tol=1e-9):
        return "within"
    return "better" if ours[0] < paper[0] else "worse"


def paper_settings(meta: dict) -> bool:
    """Whether a results.json's runs trained at the paper's settings (no ``--quick``, no ``--steps``): only
    then is a number marked against the paper's (``QUICK_NOTE``, ``STEPS_NOTE``)."""
    return not meta.get("quick") and meta.get("steps") is None


def _marked(ours, paper, unmarked: bool = False) -> str:
    """``ours`` with its mark against the paper's; none where the settings are not the paper's (``unmarked``)."""
    verdict = None if unmarked else compare(ours, paper)
    return _fmt(ours) + (f" {MARKS[verdict]}" if verdict else "")


def _seed_values(row: dict, kind: str, key: str) -> list[float]:
    """One metric of one model at every seed of a row (the first seed alone when it has no ``per_seed``)."""
    runs = row.get("per_seed") or {"only": row}
    return [r[kind][key][0] for r in runs.values() if r[kind].get(key)]


def across(values: list[float]) -> tuple[float, float] | None:
    """``(mean, standard error)`` of per-seed numbers; the error is 0.0 for one seed, None for none."""
    if not values:
        return None
    return float(np.mean(values)), float(np.std(values, ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0


def _across_seeds(row: dict, kind: str, key: str) -> str:
    """Mean ± standard error over seeds of one metric, or '' for a single seed."""
    values = _seed_values(row, kind, key) if "per_seed" in row else []
    if len(values) < 2:
        return ""
    mean, se = across(values)
    return f"{mean:.4e} ± {se:.2e} (n={len(values)})"


def tables_markdown(results: dict) -> str:
    """The three tables, ours beside the paper's, and the stage times, from a results dict (``results.json``)."""
    meta = results["meta"]
    lines = []
    if meta.get("quick"):
        lines += [f"**QUICK smoke run ({meta.get('steps')} steps per model): not the paper's settings, so the "
                  "numbers are not comparable with the paper's.**", ""]
    unmarked = not paper_settings(meta)        # no marks: a quick run, or one of other --steps
    note = QUICK_NOTE if meta.get("quick") else STEPS_NOTE.format(steps=meta.get("steps")) if unmarked else LEGEND
    lines += [generated_by(meta, f"seed {meta['seed']}, torch {meta['torch']}, {meta['mode']}")
              + f". Ratio = ours / paper. {note}", ""]
    seeds = ("seeds (n of them, from seed " f"{meta['seed']}): mean ± standard error of the seeds' means"
             if len(meta["seeds"]) > 1 else "")
    for key, title in METRICS:
        lines += [f"**{title}** (mean ± std/sqrt(rows), seed {meta['seed']})", "",
                  f"| task | model | paper | ours | ratio |{' across ' + seeds + ' |' if seeds else ''}",
                  f"| --- | --- | --- | --- | --- |{' --- |' if seeds else ''}"]
        for task, row in results["tasks"].items():
            for kind in MODELS:
                paper, ours = PAPER.get(row.get("task", task), {}).get(key, {}).get(kind), row[kind].get(key)
                extra = f" {_across_seeds(row, kind, key)} |" if seeds else ""
                lines.append(f"| {task} | {kind} | {_fmt(paper)} | {_marked(ours, paper, unmarked)} | "
                             f"{_ratio(ours, paper)} |{extra}")
        lines.append("")
    lines += [f"**Energy MSE** (mean ± batch-means standard error over 5 groups, seed {meta['seed']})", "",
              "| task | model | paper | ours, paper protocol | ratio | ours, corrected protocol |"
              + (f" paper protocol across {seeds} |" if seeds else ""),
              "| --- | --- | --- | --- | --- | --- |" + (" --- |" if seeds else "")]
    for task, row in results["tasks"].items():
        for kind in MODELS:
            paper = PAPER.get(row.get("task", task), {}).get("energy_mse", {}).get(kind)
            ours, fixed = row[kind].get("energy_mse_paper"), row[kind].get("energy_mse_corrected")
            extra = f" {_across_seeds(row, kind, 'energy_mse_paper')} |" if seeds else ""
            lines.append(f"| {task} | {kind} | {_fmt(paper)} | {_marked(ours, paper, unmarked)} | {_ratio(ours, paper)} | "
                         f"{_fmt(fixed) if fixed else 'same as paper'} |{extra}")
    lines += _extra_kinds_table(results, seeds)
    notes = [f"- **{task}**: {row['note']}" for task, row in results["tasks"].items() if row.get("note")]
    if notes:
        lines += ["", "Rows beyond the paper's setting (compared with the paper's row of the same task):"] + notes
    lines += ["", "Protocols:"]
    for task, row in results["tasks"].items():
        if row.get("note"):
            continue
        for text in row.get("protocols", {}).values():
            lines.append(f"- {task}, {text}")
    skipped = results.get("skipped", {})
    for task in skipped:
        lines += ["", f"Skipped {task}: {skipped[task]}"]
    present = meta.get("available", hnn.tasks.paper_tasks())
    missing = [t for t in hnn.tasks.paper_tasks() if t not in present]
    if missing:
        lines += ["", f"Not yet in this checkout: {', '.join(missing)}."]
    stages = stage_table(results)
    if stages:
        lines += [""] + stages
    return "\n".join(lines) + "\n"


def _extra_kinds_table(results: dict, seeds: str) -> list[str]:
    """The rows of the model kinds beyond the paper's pair (``--models``), beside that task's HNN."""
    rows = [(name, kind) for name, row in results["tasks"].items() for kind in row
            if kind not in MODELS and isinstance(row[kind], dict) and "test_loss" in row[kind]]
    if not rows:
        return []
    meta = results["meta"]
    lines = ["", f"**Other model kinds** (`--models`; not in the paper; seed {meta['seed']}; the HNN row repeated "
             "for comparison)", "",
             "| task | model | train loss | test loss | energy MSE, paper protocol | energy MSE, corrected |"
             + (" test loss across " + seeds + " |" if seeds else ""),
             "| --- | --- | --- | --- | --- | --- |" + (" --- |" if seeds else "")]
    for name in dict.fromkeys(name for name, _ in rows):
        row = results["tasks"][name]
        for kind in ["hnn"] + [k for n, k in rows if n == name]:
            r = row[kind]
            extra = f" {_across_seeds(row, kind, 'test_loss')} |" if seeds else ""
            fixed = r.get("energy_mse_corrected")
            lines.append(f"| {name} | {kind} | {_fmt(r.get('train_loss'))} | {_fmt(r.get('test_loss'))} | "
                         f"{_fmt(r.get('energy_mse_paper'))} | {_fmt(fixed) if fixed else 'same as paper'} |{extra}")
    return lines


def _g(value: float, digits: int) -> str:
    return f"{value:.{digits}g}"


def headline_markdown(results: dict) -> str:
    """The README's short table: test loss and energy MSE (paper's protocol) beside the paper's, as the
    mean ± standard error across the seeds; a mark compares with the paper's ± or, where it is larger,
    the seeds' standard error. A line under the table names the numbers whose spread across seeds
    (standard deviation) is wider than the paper's ±."""
    meta = results["meta"]
    counts = sorted({len(row.get("per_seed") or [0]) for row in results["tasks"].values()})
    over = f"{counts[0]} seeds" if len(counts) == 1 else f"{' or '.join(map(str, counts))} seeds (the table says which)"
    lines = [f"Mean ± standard error across {over} from seed {meta['seed']}, full settings, `{meta['command']}` "
             f"(commit {meta['commit']}, {meta['date']}). {LEGEND} Where our seeds' standard error is larger than "
             "the paper's ±, it is the band. All numbers, seed by seed: [docs/results.md](docs/results.md).", "",
             "| task | model | seeds | test loss, paper | test loss, ours | energy MSE, paper | energy MSE, ours |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    wide = []
    for name, row in results["tasks"].items():
        paper = PAPER.get(row.get("task", name), {})
        for kind in MODELS:
            cells = []
            for key, ours_key, what in (("test_loss", "test_loss", "test loss"),
                                        ("energy_mse", "energy_mse_paper", "energy MSE")):
                ref, values = paper.get(key, {}).get(kind), _seed_values(row, kind, ours_key)
                ours = across(values)
                verdict = compare(ours, ref, spread=ours[1] if ours else None)
                mean = "n/a" if ours is None else _g(ours[0], 3) + (f" ± {_g(ours[1], 2)}" if len(values) > 1 else "")
                cells += ["n/a" if ref is None else _g(ref[0], 3), mean + (f" {MARKS[verdict]}" if verdict else "")]
                if ref is not None and len(values) > 1 and np.std(values, ddof=1) > ref[1]:
                    wide.append((np.std(values, ddof=1) / ref[1], f"{name} {kind} {what} "
                                 f"({_g(min(values), 2)} to {_g(max(values), 2)})"))
            seeds = len(row.get("per_seed") or [0])
            lines.append(f"| {name} | {kind} | {seeds} | " + " | ".join(cells) + " |")
    if wide:
        wide.sort(reverse=True)
        lines += ["", "Wider across seeds than the paper's ± (standard deviation over it, widest first): "
                  + "; ".join(f"{text} {ratio:.0f}x" if ratio >= 10 else f"{text} {ratio:.1f}x"
                              for ratio, text in wide) + "."]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# the command
