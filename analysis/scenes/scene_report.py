"""The scene study's outputs, built from its results dict (``scene_study.json``), never typed:
``scene_study.md`` (every table: ``scene_tables``), ``figures/scenes-pareto.png`` (``scene_figure``) and,
with ``--update-docs``, docs/scenes.md (section ``scenes``), the README's model guide (section
``model-guide``) and docs/figures/scenes-pareto.png; a study of the scenes of many bodies (page ``bodies``) writes
``scene_study_bodies.*``, docs/bodies.md's section ``bodies-scenes`` and docs/figures/bodies-pareto.png.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import hnn
from hnn.io import atomic_write
from hnn_analysis import commands, pages
from hnn_analysis.scenes import scene_record
from hnn_analysis.scenes.scene_common import PAGES
from hnn_analysis.scenes.scene_figure import pareto_figure
from hnn_analysis.scenes.scene_tables import guide, markdown


def write(results: dict, out: Path, update_docs: bool, page: str = "scenes", record_path: Path | None = None) -> None:
    """The outputs of a study of one page's scenes (``scene_common.PAGES``: its files' names, its sections); with
    ``update_docs``, the sitting's scenes go into the page's record (``scene_record``, at ``record_path``: default
    docs/) and the page is written from the record once it holds every scene of the page."""
    results["meta"]["page"] = page
    names = PAGES[page]
    page_results = None
    if update_docs:
        record = scene_record.load(page, record_path)
        page_results = scene_record.merge(record, results)
        print(f"recorded {', '.join(results['scenes'])} in {scene_record.save(page, record, record_path)}")
        left = scene_record.missing(record)
        if left:
            print(f"not writing the {page} page yet: the record has no numbers of {', '.join(left)}; study them "
                  f"(python analysis/scene_study.py --scenes {' '.join(left)} --jobs 2 --update-docs) and the page "
                  "is written from the record")
            page_results = None
    commands.publish(out, names["stem"], results, markdown(results))
    if page_results is not None:
        table = markdown(page_results)
        texts = {"scenes": table, "bodies-scenes": table}
        if "model-guide" in names["sections"]:
            texts["model-guide"] = guide(page_results)
        for name in names["sections"]:
            print(f"updated the {name} section of {pages.update_section(name, texts[name], seeds_of(page_results))}")
    figure = out / "figures" / names["figure"]
    pareto_figure(results, figure)
    print(f"wrote {out / (names['stem'] + '.json')}, {out / (names['stem'] + '.md')}, {figure}")
    if page_results is not None:       # the page's figure: every scene of the record, drawn here, then copied whole
        drawn = out / "figures" / f"page-{figure.name}"
        pareto_figure(page_results, drawn)
        target = hnn.tasks.repo_root() / "docs" / "figures" / figure.name
        atomic_write(target, lambda tmp: shutil.copyfile(drawn, tmp))
        print(f"updated {target}")


def seeds_of(results: dict) -> pages.Seeds:
    """The fewest seeds a verdict of the study rests on: its per-kind rows, its grid and every scene's card
    (a card counts the seeds of the model it picked), and why where that is fewer than ``pages.MIN_SEEDS``."""
    meta = results["meta"]
    n = len(meta["seeds"])
    grid = len(meta.get("grid_seeds", [0]))     # a study saved before --grid-seeds trained its grid at seed 0
    cards = {task: entry["card"].get("n_seeds", 1) for task, entry in results["scenes"].items() if entry.get("card")}
    fewest = min(n, grid, *cards.values())
    if fewest >= pages.MIN_SEEDS:
        return pages.Seeds(fewest)
    few = ", ".join(f"{task} ({count})" for task, count in cards.items() if count < pages.MIN_SEEDS)
    return pages.Seeds(fewest, f"the per-kind rows carry {n} seed{'s' if n > 1 else ''} and each card chooses from a "
                       f"width x fraction grid trained at {grid} seed{'s' if grid > 1 else ''} (--seeds, --grid-seeds)"
                       + (f"; the cards of {few} rest on fewer seeds" if few else ""))


def main(argv=None) -> None:
    """Rebuild the outputs of a finished study from its ``scene_study.json`` (no measuring)."""
    import json
    p = hnn.cli.Parser(description=main.__doc__)
    p.add_argument("results", type=Path, help="a scene_study.json")
    p.add_argument("--update-docs", action="store_true", help="also docs/scenes.md and the README's model guide")
    args = p.parse_args(argv)
    results = json.loads(args.results.read_text())
    if args.update_docs and results["meta"]["quick"]:
        p.error("that study was a --quick smoke run: docs/ show full-settings studies only")
    write(results, args.results.parent, args.update_docs, results["meta"].get("page", "scenes"))


if __name__ == "__main__":
    main()
