"""Every generated section that draws verdicts (a table's marks or ranking, a card's choice) records the
seeds they rest on in docs/seeds.json, written by the command that writes the section; one that rests on
fewer than ``pages.MIN_SEEDS`` (3) says why on its page."""
import json

import pytest

import hnn
from hnn_analysis import pages


@pytest.mark.parametrize("name", pages.VERDICTS)
def test_a_verdict_rests_on_three_seeds_or_its_page_says_why(name):
    text = pages.section_text(name)
    assert text is not None, f"{pages.PAGES[name]} has no {name} section"
    if text.strip().startswith("Not measured yet"):     # no numbers, so no verdict yet: say what measures it
        pytest.skip(f"{name} is not measured yet: {pages.REFRESH[name]}")
    entry = pages.recorded_seeds().get(name)
    assert entry is not None and entry["stamp"] == pages.stamp_of(text), (
        f"section {name!r} records no seeds for its stamp {pages.stamp_of(text)}: regenerate it ({pages.REFRESH[name]})")
    if entry["seeds"] < pages.MIN_SEEDS:
        assert entry["why"] and entry["why"] in text, f"{name}: {entry['seeds']} seed(s) and no reason on the page"


def test_a_verdict_section_is_written_with_its_seeds_and_records_them(tmp_path, monkeypatch):
    monkeypatch.setattr(hnn.tasks, "repo_root", lambda: tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "peers.md").write_text("intro\n<!-- peers:begin -->\nold\n<!-- peers:end -->\nrest\n")
    with pytest.raises(ValueError, match="pass the seeds they rest on"):
        pages.update_section("peers", "from `cmd` at commit abcdef1: a table")
    with pytest.raises(ValueError, match="must say why"):
        pages.Seeds(2)
    pages.update_section("peers", "from `cmd` at commit abcdef1: a table", pages.Seeds(1, "one seed costs an hour"))
    text = pages.section_text("peers", tmp_path)
    assert "fewer than 3: one seed costs an hour." in text and "a table" in text
    assert json.loads((tmp_path / "docs" / "seeds.json").read_text()) == {
        "peers": {"seeds": 1, "why": "one seed costs an hour", "stamp": "abcdef1"}}
    # a section that draws no verdict takes none
    (tmp_path / "docs" / "speed.md").write_text("<!-- threads:begin -->\n<!-- threads:end -->\n")
    pages.update_section("threads", "a speed table")
    assert "Seeds" not in pages.section_text("threads", tmp_path)
