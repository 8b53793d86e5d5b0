"""The scene study's record: each scene's measured numbers, kept over sittings, so that a page's cards can be
regenerated a few scenes at a time.

    record = load("scenes")               # its file in docs/ (path(page), committed), or an empty record
    page = merge(record, results)         # the sitting's scenes replace theirs; the results of the whole page
    save("scenes", record)

The whole study of docs/scenes.md trains for over two hours on 2 cores and measures for over an hour more:
longer than one sitting. ``python analysis/scene_study.py --scenes 2body 3body --update-docs`` measures two
scenes, puts them in the record beside the others' last sitting, and writes the page from the record once every
scene of the page is in it. Each scene keeps the sitting that measured it (its command, date, commit, machine
and wall times), and the page's stamp names every sitting, the oldest first: a page is as stale as its oldest
scene. Sittings must share the settings a card compares across scenes (the seeds, the starts, the horizon):
a sitting at other settings is refused, naming both, rather than mixed in.
"""
from __future__ import annotations

import json
from pathlib import Path

import hnn
from hnn.io import atomic_write
from hnn_analysis.scenes.scene_common import PAGES, scenes

# what every sitting of one page must share: the cards and the tables compare scenes on them
SHARED = ("seeds", "grid_seeds", "starts", "horizon", "rollout_seconds", "rollout_calls")


def path(page: str) -> Path:
    """The record of ``page``'s scenes: ``docs/<stem>-record.json``."""
    return hnn.tasks.repo_root() / "docs" / f"{PAGES[page]['stem']}-record.json"


def load(page: str, where: Path | None = None) -> dict:
    """The record at ``where`` (default ``path(page)``), or an empty one."""
    where = where or path(page)
    if not where.exists():
        return {"page": page, "sittings": [], "scenes": {}, "dhnn": None}
    return json.loads(where.read_text())


def save(page: str, record: dict, where: Path | None = None) -> Path:
    """Write ``record`` atomically: a line per sitting and per scene, each compact (half the bytes of indented
    JSON, and a sitting's diff touches its scenes' lines alone)."""
    where = where or path(page)

    def compact(value) -> str:
        return json.dumps(value, separators=(",", ":"))
    lines = ["{", f'"page": {compact(record["page"])},', f'"dhnn": {compact(record.get("dhnn"))},', '"sittings": [',
             ",\n".join(compact(s) for s in record["sittings"]), '],', '"scenes": {',
             ",\n".join(f"{compact(task)}: {compact(entry)}" for task, entry in record["scenes"].items()), "}}"]
    atomic_write(where, lambda tmp: Path(tmp).write_text("\n".join(lines) + "\n"))
    return where


def merge(record: dict, results: dict) -> dict:
    """Put the sitting ``results`` (``scene_stages.run``'s, one page's) into ``record`` in place: its scenes
    replace the record's of the same name, its sitting joins the record's (a sitting none of whose scenes is
    left is dropped). Returns the page's results as the report reads them: every scene of the record, in the
    page's order, with the newest sitting's meta, and ``meta["sittings"]``, the oldest first. A ValueError
    where the sitting's settings (``SHARED``) differ from the record's, naming both and the fix."""
    meta = results["meta"]
    if meta.get("quick"):
        raise ValueError("a --quick smoke run is not recorded: the record holds full-settings scenes only")
    kept = [s for s in record["sittings"] if set(s["scenes"]) - set(results["scenes"])]
    for sitting in kept:
        differ = {key: (sitting["meta"].get(key), meta.get(key)) for key in SHARED
                  if sitting["meta"].get(key) != meta.get(key)}
        if differ:
            words = "; ".join(f"{key} {old} there, {new} here" for key, (old, new) in differ.items())
            raise ValueError(f"the record ({', '.join(sitting['scenes'])}, {sitting['meta'].get('date')}) was measured "
                             f"at other settings: {words}. Study those scenes again at these settings (--scenes "
                             f"{' '.join(sitting['scenes'])}), or these at the record's")
    for sitting in kept:        # the scenes this sitting measures again are no longer the old sitting's
        sitting["scenes"] = [task for task in sitting["scenes"] if task not in results["scenes"]]
    record["sittings"] = kept + [{"meta": meta, "seconds": results["seconds"], "scenes": list(results["scenes"])}]
    record["scenes"].update(results["scenes"])
    if results.get("dhnn") is not None:
        record["dhnn"] = results["dhnn"]
    return page_results(record)


def page_results(record: dict) -> dict:
    """The results the report reads, from ``record``: its scenes in the page's order, the newest sitting's meta
    and seconds, and every sitting (the oldest first) in ``meta["sittings"]``."""
    order = scenes(record["page"])
    newest = record["sittings"][-1]
    sittings = sorted(record["sittings"], key=lambda s: s["meta"].get("date") or "")
    return {"meta": {**newest["meta"], "page": record["page"],
                     "sittings": [{**s["meta"], "scenes": s["scenes"], "seconds": s["seconds"]} for s in sittings]},
            "scenes": {task: record["scenes"][task] for task in sorted(record["scenes"], key=_position(order))},
            "dhnn": record.get("dhnn"), "seconds": newest["seconds"]}


def missing(record: dict) -> list[str]:
    """The page's scenes the record has no numbers of."""
    return [task for task in scenes(record["page"]) if task not in record["scenes"]]


def _position(order: list[str]):
    return lambda task: (order.index(task) if task in order else len(order), task)
