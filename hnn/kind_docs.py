"""How a model kind is told to a reader: ``KindDoc``, the prose a row of ``hnn.kinds.MODEL_KINDS``
carries, and the three texts made of it: ``--model``'s help, the README's model list and
docs/python.md's paragraphs (``python analysis/readme.py kinds`` writes both pages;
``tests/test_kind_docs.py`` checks that every registered kind is described and on both pages).

Torch-free on purpose: ``train.py --help`` lists the kinds before torch loads.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class KindDoc:
    """A model kind, for a reader: ``line`` (the README's one line and ``--model``'s help), what it
    ``assumes``, its ``coordinates``, the ``integrator`` to roll it out with, and ``when`` to use it."""
    line: str
    assumes: str
    coordinates: str
    integrator: str
    when: str


def model_help(names, docs: dict, prefix: str = "") -> str:
    """``--model``'s help: each of ``names`` with the one line of kind ``prefix + name`` in ``docs``
    (kind -> ``KindDoc`` or None; a kind without one: its name alone)."""
    found = [docs.get(prefix + name) for name in names]
    return "model kind: " + "; ".join(f"{name} ({doc.line})" if doc else name for name, doc in zip(names, found))


def readme_lines(described: Iterable[tuple[str, KindDoc]]) -> str:
    """The README's list: one line per ``(kind, doc)``."""
    return "\n".join(f"- `{kind}`: {doc.line}." for kind, doc in described)


def python_paragraphs(described: Iterable[tuple[str, KindDoc]]) -> str:
    """docs/python.md's section: a paragraph per ``(kind, doc)``."""
    return "\n\n".join(f"**`{kind}`**: {doc.line}. *Assumes* {doc.assumes}. *Coordinates*: {doc.coordinates}. "
                       f"*Roll it out with* {doc.integrator}. *Use it for* {doc.when}."
                       for kind, doc in described)
