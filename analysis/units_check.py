"""Which published runs' data ``--units auto`` (the default, ``hnn.units``) would rescale: none, or this says which.

    python analysis/units_check.py [--quick]       # the RMS sizes of every published run's training data

The default moved from ``--units off`` to ``--units auto``, which rescales where the RMS of q or p lies
outside [0.1, 10] or that of dq/dt or dp/dt outside [0.01, 100] (``hnn.units.AUTO_FAR``), or where the
columns of one part spread in size over 10x (``hnn.units.COLUMN_SPREAD``; angles aside). A published
number moves only where auto rescales its run's data, so this builds the data of every run the published
tables train and prints their sizes: each task's defaults, the paper's rows (``analysis/reproduce.py``'s
plan), the peers' tables on the chains (``analysis/peers.py``'s plan: CHNN's protocol at N = 1, 2, 3, 5 and
the LNN's) and the two-link arm at the masses docs/arm.md and docs/stress.md measure (its 10 kg sections
run with ``--units off``: ``analysis/pages.py``). A run whose model reads its q as angles
(``periodic``) is judged without q, as auto judges it. The measured task scales its data itself
(``experiment-measured/data.py``, ``Scale``: q and its rate of RMS 1), so its sizes are 1 by construction;
a shipped file is listed as its example. Exits 1 naming the runs auto would rescale.
"""
from __future__ import annotations

import argparse
import sys

import hnn
from hnn.specs import run_specs
from hnn.units import AUTO_FAR, COLUMN_SPREAD, auto_bounds, rescale_reason, sized_arrays, sizes, spreads
from hnn_analysis.chains import peer_plan
from hnn_analysis.paper import study

# the arm's masses the published pages measure, and whether their command pins --units off (docs/stress.md's
# "Balanced loss" sections study --balance in the arm's own units; docs/arm.md's tables are of that loss)
ARM_MASSES = {1.0: False, 3.0: False, 10.0: True}
MEASURED_EXAMPLE = {"data": "experiment-measured/systems/real_linear_h_1.txt", "time": "t", "q": "x", "v": "v",
                    "trial": "trial"}


def _sources(quick: bool) -> list[tuple[str, hnn.RunConfig, bool]]:
    """``(label, config, pinned off)`` of every published training configuration, one per distinct dataset and
    angle reading (the runs of one dataset differ in seeds of the inits, widths and steps, which auto does not read)."""
    out = [(f"{task} (default)", hnn.tasks.task_config(task, {}), False)
           for task in hnn.available_tasks() if task not in ("measured",)]
    tasks = ["spring", "pend"] if quick else [t for t in hnn.available_tasks() if t not in ("measured", "arm", "chain")]
    for job in study.plan(study.table_rows(tasks, False, [0]), [0], hnn.tasks.repo_root() / "results" / "runs", None):
        out.append((f"reproduce {job.key}", job.config, False))
    if not quick:
        settings = {"kinds": peer_plan.kinds(), **peer_plan.FULL}
        out += [(f"peers {job.key}", job.config, False) for job in peer_plan.plan(settings, hnn.tasks.repo_root(), 0)]
        out += [(f"arm --mass {mass:g}", hnn.tasks.task_config("arm", {"mass": mass}), pinned)
                for mass, pinned in ARM_MASSES.items()]
        out.append(("measured (a shipped file)", hnn.tasks.task_config("measured", MEASURED_EXAMPLE), False))
    return out


def check(quick: bool = False) -> list[dict]:
    """One row per distinct (dataset, angle reading, objective arrays) of the published runs: its label, sizes
    and whether auto rescales it."""
    rows, seen, data = [], set(), {}
    for label, config, pinned in _sources(quick):
        objective = config.make_objective()
        if hnn.MODEL_KINDS[config.kind].family == "pixel":
            rows.append({"label": label, "sizes": None, "auto": "as given (pixels: no q and p)"})
            continue
        # what the run's model reads: its q as angles or not (auto then judges without q)
        periodic = bool(getattr(hnn.kinds.model_from_spec(run_specs(config).model), "periodic", False))
        key = (config.dataset_key(), periodic, objective.arrays)
        if key in seen:
            continue
        seen.add(key)
        if config.dataset_key() not in data:
            data[config.dataset_key()] = config.dataset()
        prepared = objective.prepare(data[config.dataset_key()])
        x, dxdt = sized_arrays(prepared, objective)
        far = rescale_reason(x, dxdt, periodic, prepared.get("state", "canonical")) is not None
        rows.append({"label": label + (" (angles)" if periodic else ""), "sizes": sizes(x, dxdt, periodic),
                     "spread": max(spreads(x, dxdt).values(), default=1.0),
                     "auto": ("rescales: its command pins --units off" if pinned else "RESCALES") if far else "as given",
                     "moves": far and not pinned})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the spring's and the pendulum's rows only (seconds)")
    args = parser.parse_args(argv)
    rows = check(args.quick)
    print(f"--units auto leaves {auto_bounds()} (hnn.units.AUTO_FAR = {AUTO_FAR}) whose columns' sizes spread "
          f"by {COLUMN_SPREAD:g}x at most within each part\n")
    print("| training data | RMS q | RMS p (or qdot) | RMS dq/dt | RMS dp/dt | widest spread | --units auto |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for row in rows:
        s = row["sizes"] or {}
        cells = [f"{s[name]:.3g}" if name in s else "-" for name in ("q", "p", "dq/dt", "dp/dt")]
        spread = f"{row['spread']:.3g}x" if "spread" in row else "-"
        print(f"| {row['label']} | " + " | ".join(cells) + f" | {spread} | {row['auto']} |")
    moved = [row["label"] for row in rows if row.get("moves")]
    print(f"\n{len(rows)} training sets; " + (f"auto rescales {len(moved)}, whose published numbers would move: "
                                             f"{', '.join(moved)}" if moved else "auto rescales none that a published "
                                             "number rests on"))
    return 1 if moved else 0


if __name__ == "__main__":
    sys.exit(main())
