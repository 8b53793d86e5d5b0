"""What every analysis command shares: its common flags and its output tail.

    p = argparse.ArgumentParser(...)
    commands.add_flags(p, out="output folder", jobs="worker processes", update_docs="write docs/x.md")
    ...
    commands.publish(out, "x", results, text, sections={"x": text} if args.update_docs else {})

``add_flags`` adds only the flags it is given a help text for (each command says what its flag
does); ``publish`` writes ``<out>/<stem>.json`` (every number) and ``<out>/<stem>.md`` (the table
built from it) atomically, prints the table, and writes each generated section of README.md or
docs/ it is given (``pages.update_section``).
"""
from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import warnings
from pathlib import Path

import hnn

from hnn.settings import int_at_least
from hnn.io import atomic_write, write_json

from hnn_analysis import pages

# each command's ``--quick`` budget in seconds, from nothing (a fresh output folder, no dataset cached,
# installs aside) on a quiet 2-core box: a reader's first run of it, which they watch end to end.
# analysis/benchmarks/quick_budgets.py measures every one against it (docs/speed.md)
QUICK_BUDGETS = {"reproduce": 60, "scene_study": 90, "scene_study --data": 120, "peers": 180, "dgnet": 120,
                 # a reader's first hour beside them: the README's test command and its first check, the Python
                 # of the README and of docs/python.md, each run as written
                 "pytest": 900, "pytest -m quick": 90, "README's Python": 30, "docs/python.md's Duffing": 20}


def budget_words(command: str) -> str:
    """``'budget 60 s from nothing on a quiet 2-core box'``: the words a ``--quick`` help ends with."""
    return f"budget {QUICK_BUDGETS[command]} s from nothing on a quiet 2-core box (docs/speed.md)"


def say_quick(command: str, cuts: list[str]) -> str:
    """Print, before a ``--quick`` run starts, what it cuts (each of ``cuts``: one phrase such as
    ``'300 training steps of 2000'``) and its budget: quick runs every stage on less, and says on
    what. Returns the text printed."""
    text = "\n".join([f"--quick: every stage on small settings, within a budget of {QUICK_BUDGETS[command]} s from "
                       "nothing on a quiet 2-core box; cut:"]
                      + [f"  - {cut}" for cut in cuts])
    print(text, flush=True)
    return text


def add_flags(parser, *, quick: str | None = None, out: str | None = None, out_default: Path | None = None,
              seeds: str | None = None, seeds_default: int | None = 1, jobs: str | None = None,
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


def publish(out: Path, stem: str, results: dict, text: str, sections: dict | None = None,
            seeds: pages.Seeds | None = None) -> list[Path]:
    """Write ``out/stem.json`` and ``out/stem.md``, print ``text``, then each ``{section: text}`` of
    ``sections`` into its page (a section that draws verdicts with the ``seeds`` they rest on); returns
    the files written."""
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{stem}.json", results)
    atomic_write(out / f"{stem}.md", lambda tmp: Path(tmp).write_text(text))
    print("\n" + text)
    written = [out / f"{stem}.json", out / f"{stem}.md"]
    for name, section in (sections or {}).items():
        page = pages.update_section(name, section, seeds if name in pages.VERDICTS else None)
        print(f"updated the {name} section of {page}")
        written.append(page)
    return written


def portable_command(argv: list[str], script: str = "analysis/reproduce.py") -> str:
    """The command ``python <script> <argv>`` as a reader can rerun it: paths inside the checkout
    made relative to it, and other absolute paths (one machine's folders) shown as ``DIR``."""
    return " ".join([f"python {script}"] + [portable_path(word) for word in argv])


def portable_path(word) -> str:
    """``word`` as a reader can use it: a path inside the checkout relative to it, another absolute
    path (one machine's folder) as ``DIR``, anything else as it is."""
    path, root = Path(word), hnn.tasks.repo_root().resolve()
    if not path.is_absolute():
        return str(word)
    return os.path.relpath(path, root) if path.resolve().is_relative_to(root) else "DIR"


def _worker_start() -> None:
    import torch        # here, in the worker: a command's --help loads no torch
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")     # a task records its own warnings; the rest would repeat per task


def _call(task: tuple):
    function, arguments = task
    return function(*arguments)


def run_tasks(tasks: list[tuple], jobs: int, describe) -> list:
    """Each ``(function, arguments)`` of ``tasks`` called, here (``jobs`` 1) or in ``jobs`` worker processes of one
    torch thread (spawned: no torch state copied by fork), as a measurement's independent parts; the results in
    the order given. ``describe(task)`` names a task as it ends, after the progress count."""
    results = [None] * len(tasks)
    progress = hnn.sweeps.sweep.Progress(len(tasks))
    if jobs <= 1:
        for i, task in enumerate(tasks):
            results[i] = _call(task)
            print(f"{progress.advance()} {describe(task)}", flush=True)
        return results
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=context, initializer=_worker_start) as pool:
        running = {pool.submit(_call, task): i for i, task in enumerate(tasks)}
        for future in concurrent.futures.as_completed(running):
            results[running[future]] = future.result()
            print(f"{progress.advance()} {describe(tasks[running[future]])}", flush=True)
    return results
