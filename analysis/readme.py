"""Paste generated text into README.md between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``.

The README's results, timing and benchmark sections are written only this way, never by hand:

    python analysis/readme.py timing results-fresh/results.json   # the stage times of a saved run
"""
import argparse
import json
from pathlib import Path

import hnn
from hnn.runs import atomic_write


def update_section(name: str, text: str) -> Path:
    readme = hnn.tasks.repo_root() / "README.md"
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    content = readme.read_text()
    if begin not in content or end not in content:
        raise ValueError(f"{readme} has no {begin} ... {end} section to update")
    head, rest = content.split(begin, 1)
    tail = rest.split(end, 1)[1]
    atomic_write(readme, lambda tmp: Path(tmp).write_text(f"{head}{begin}\n{text.rstrip()}\n{end}{tail}"))
    return readme


def timing_text(results: dict) -> str:
    """The stage-time table of a ``reproduce.py`` results dict, with the command that made it."""
    from reproduce import stage_table

    meta = results["meta"]
    lines = stage_table(results)
    if not lines:
        raise ValueError("these results hold no stage times (was anything trained?)")
    return "\n".join([f"`{meta['command']}` on {meta['date']} (commit {meta['commit']}, {meta['mode']}, "
                      f"{meta['cores']} cores, torch {meta['torch']}):", ""] + lines) + "\n"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=["timing"], help="timing: the full-run section from a results.json")
    p.add_argument("results", type=Path, help="a results.json written by analysis/reproduce.py")
    args = p.parse_args(argv)
    update_section("full-run", timing_text(json.loads(args.results.read_text())))
    print(f"updated the full-run section of README.md from {args.results}")


if __name__ == "__main__":
    main()
