"""Paste generated text into README.md between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``.

The README's results and benchmark sections are written only this way, never by hand.
"""
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
