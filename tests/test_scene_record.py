"""The scene study's record: a page's scenes studied over several sittings, each scene from the last sitting that
studied it, and the page written only once every scene is there."""
import json

import pytest

from hnn_analysis.scenes import scene_common, scene_record, scene_report, scene_tables

PAGE = scene_common.scenes("scenes")


def _sitting(scenes, commit, date, **changed):
    meta = {"seeds": [0, 1, 2], "grid_seeds": [0, 1, 2], "starts": 8, "horizon": 10, "rollout_seconds": None,
            "rollout_calls": None, "quick": False, "date": date, "commit": commit, "torch": "2.13.0+cpu", "cores": 2,
            "cpu": "AVX512", "jobs": 2, "command": f"python analysis/scene_study.py --scenes {' '.join(scenes)}",
            **changed}
    return {"meta": meta, "seconds": {"training": 10.0, "measure": 20.0, "cards": 0.0, "total": 30.0},
            "scenes": {task: {"card": {"n_seeds": 3}, "commit": commit} for task in scenes}}


def test_two_sittings_make_one_page_in_its_order_with_each_sitting_named_oldest_first(tmp_path):
    record = scene_record.load("scenes", scene_record.path("scenes").with_name("no-such-record.json"))
    later, first = PAGE[:2], PAGE[2:]
    scene_record.merge(record, _sitting(first, "aaaaaaa", "2026-12-07"))
    assert scene_record.missing(record) == later
    page = scene_record.merge(record, _sitting(later, "bbbbbbb", "2026-12-08"))
    assert scene_record.missing(record) == [] and list(page["scenes"]) == PAGE
    assert all(page["scenes"][task]["commit"] == ("bbbbbbb" if task in later else "aaaaaaa") for task in PAGE)
    text = scene_tables.stamp(page)
    # the stale-page check reads the first commit a stamp names: the oldest sitting's
    assert text.index("commit aaaaaaa") < text.index("commit bbbbbbb")
    assert f": {', '.join(later)}. Wall time" in text and "over 2 sittings" in text
    # the saved record (a compact line per sitting and per scene) reads back as the same record and page
    saved = scene_record.load("scenes", scene_record.save("scenes", record, tmp_path / "record.json"))
    assert saved == json.loads(json.dumps(record))
    assert scene_record.page_results(saved)["scenes"] == json.loads(json.dumps(page["scenes"]))


def test_a_scene_studied_again_replaces_its_numbers_and_a_sitting_left_with_none_is_dropped():
    record = {"page": "scenes", "sittings": [], "scenes": {}, "dhnn": None}
    scene_record.merge(record, _sitting(PAGE[:1], "aaaaaaa", "2026-12-07"))
    scene_record.merge(record, _sitting(PAGE, "bbbbbbb", "2026-12-08"))
    assert [s["meta"]["commit"] for s in record["sittings"]] == ["bbbbbbb"]
    assert "over" not in scene_tables.stamp(scene_record.page_results(record))     # one sitting: its own stamp
    scene_record.merge(record, _sitting(PAGE[:1], "ccccccc", "2026-12-09"))
    assert [s["scenes"] for s in record["sittings"]] == [PAGE[1:], PAGE[:1]]
    assert record["scenes"][PAGE[0]]["commit"] == "ccccccc"


def test_a_sitting_at_other_settings_is_refused_naming_both():
    record = {"page": "scenes", "sittings": [], "scenes": {}, "dhnn": None}
    scene_record.merge(record, _sitting(PAGE[:1], "aaaaaaa", "2026-12-07"))
    with pytest.raises(ValueError, match=r"seeds \[0, 1, 2\] there, \[0\] here"):
        scene_record.merge(record, _sitting(PAGE[1:], "bbbbbbb", "2026-12-08", seeds=[0]))
    with pytest.raises(ValueError, match="--quick smoke run is not recorded"):
        scene_record.merge(record, _sitting(PAGE[1:], "bbbbbbb", "2026-12-08", quick=True))
    assert list(record["scenes"]) == PAGE[:1]         # nothing of a refused sitting got in


def test_update_docs_writes_the_page_only_once_the_record_holds_every_scene(tmp_path, monkeypatch):
    written = []
    monkeypatch.setattr(scene_report, "markdown", lambda results: "table of " + ",".join(results["scenes"]))
    monkeypatch.setattr(scene_report, "guide", lambda results: "guide")
    monkeypatch.setattr(scene_report, "pareto_figure", lambda results, path: None)
    monkeypatch.setattr(scene_report.pages, "update_section", lambda name, text, seeds: written.append((name, text)))
    monkeypatch.setattr(scene_report, "atomic_write", lambda target, write: written.append(("figure", target)))
    record = tmp_path / "record.json"
    scene_report.write(_sitting(PAGE[2:], "aaaaaaa", "2026-12-07"), tmp_path / "out", True, record_path=record)
    assert written == [] and json.loads(record.read_text())["sittings"][0]["scenes"] == PAGE[2:]
    scene_report.write(_sitting(PAGE[:2], "bbbbbbb", "2026-12-08"), tmp_path / "out", True, record_path=record)
    assert ("scenes", "table of " + ",".join(PAGE)) in written and ("model-guide", "guide") in written
    assert any(name == "figure" for name, _ in written)
    # the sitting's own files hold its own scenes alone
    assert list(json.loads((tmp_path / "out" / "scene_study.json").read_text())["scenes"]) == PAGE[:2]
