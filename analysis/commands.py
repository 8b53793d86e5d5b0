"""What every analysis command shares: its common flags and its output tail.

    p = argparse.ArgumentParser(...)
    commands.add_flags(p, out="output folder", jobs="worker processes", update_docs="write docs/x.md")
    ...
    commands.publish(out, "x", results, text, sections={"x": text} if args.update_docs else {})

``add_flags`` adds only the flags it is given a help text for (each command says what its flag
does); ``publish`` writes ``<out>/<stem>.json`` (every number) and ``<out>/<stem>.md`` (the table
built from it) atomically, prints the table, and writes each generated section of README.md or
docs/ it is given (``readme.update_section``).
"""
from __future__ import annotations

import os
from pathlib import Path

import hnn

from hnn.cli import int_at_least
from hnn.io import atomic_write, write_json

from hnn_analysis import readme


def add_flags(parser, *, quick: str | None = None, out: str | None = None, out_default: Path | None = None,
              seeds: str | None = None, seeds_default: int = 1, jobs: str | None = None,
              update_docs: str | None = None) -> None:
    """``--quick --out --seeds --jobs --update-docs`` on ``parser``, each only where its help is given."""
    if quick is not None:
        parser.add_argument("--quick", action="store_true", help=quick)
    if out is not None:
        parser.add_argument("--out", type=Path, default=out_default, help=out)
    if seeds is not None:
        parser.add_argument("--seeds", type=int_at_least(1), default=seeds_default, help=seeds)
    if jobs is not None:
        parser.add_argument("--jobs", type=int_at_least(1), default=1, help=jobs)
    if update_docs is not None:
        parser.add_argument("--update-docs", dest="update_docs", action="store_true", help=update_docs)


def publish(out: Path, stem: str, results: dict, text: str, sections: dict | None = None) -> list[Path]:
    """Write ``out/stem.json`` and ``out/stem.md``, print ``text``, then each ``{section: text}`` of
    ``sections`` into its page; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{stem}.json", results)
    atomic_write(out / f"{stem}.md", lambda tmp: Path(tmp).write_text(text))
    print("\n" + text)
    written = [out / f"{stem}.json", out / f"{stem}.md"]
    for name, section in (sections or {}).items():
        page = readme.update_section(name, section)
        print(f"updated the {name} section of {page}")
        written.append(page)
    return written


def portable_command(argv: list[str], script: str = "analysis/reproduce.py") -> str:
    """The command ``python <script> <argv>`` as a reader can rerun it: paths inside the checkout
    made relative to it, and other absolute paths (one machine's folders) shown as ``DIR``."""
    root, words = hnn.tasks.repo_root().resolve(), []
    for word in argv:
        path = Path(word)
        if path.is_absolute():
            word = os.path.relpath(path, root) if path.resolve().is_relative_to(root) else "DIR"
        words.append(word)
    return " ".join([f"python {script}"] + words)
