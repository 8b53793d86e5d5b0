"""Generated pages: text pasted between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` of
README.md or a page of docs/ (``update_section``), the curated figures in docs/figures/, the
staleness check (``stale``) and the seeds behind every verdict a section draws (``Seeds``,
docs/seeds.json). ``python analysis/readme.py`` is the command over it; ``PAGES`` and ``REFRESH``
say which command writes each section.
"""
import json
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import hnn
from hnn.io import atomic_write

# the tasks whose DGNet init comparison (analysis/chains/dgnet_init.py) docs/dgnet.md shows
DGNET_INIT_TASKS = ("spring", "pend")
# the SympNets protocols of the learned maps' benchmark (analysis/benchmarks/maps.py), each a section of docs/maps.md
MAP_PROTOCOLS = ("pendulum", "three_body")
# section name -> the page (relative to the repository) that holds it
PAGES = {"headline": "README.md", "results": "docs/results.md", "full-run": "docs/speed.md",
         "benchmark": "docs/speed.md", "benchmark-pixels": "docs/speed.md", "threads": "docs/speed.md",
         "quick-budgets": "docs/speed.md",
         "speed-accuracy": "docs/integrators.md", "energy-drift": "docs/integrators.md",
         "default-tolerances": "docs/integrators.md", "work-precision": "docs/integrators.md",
         "scenes": "docs/scenes.md", "model-guide": "README.md",
         "measured-guide": "README.md",
         "peers": "docs/peers.md", "stress": "docs/stress.md", "lnn-start": "docs/stress.md",
         "units-scan": "docs/stress.md", "lnn-pinv": "docs/stress.md",
         "arm-balance": "docs/stress.md", "arm-balance-long": "docs/stress.md", "ray-quick": "docs/sweeps.md",
         "ray-full": "docs/sweeps.md",
         "many-models": "docs/speed.md", "fit-floor": "docs/speed.md", "thread-spread": "docs/testing.md", "many-models-gpu": "docs/gpu.md", "gpu-check": "docs/gpu.md",
         "fits-sampling": "docs/fits.md", "fits-tasks": "docs/fits.md", "fits-library": "docs/fits.md",
         "bodies": "docs/bodies.md", "bodies-paper": "docs/bodies.md", "bodies-gravity": "docs/bodies.md", "bodies-lj": "docs/bodies.md", "bodies-rebound": "docs/bodies.md",
         "bodies-scenes": "docs/bodies.md",
         **{f"dgnet-{task}": "docs/dgnet.md" for task in ("spring", "pend", "real", "2body")},
         **{f"dgnet-init-{task}": "docs/dgnet.md" for task in DGNET_INIT_TASKS},
         **{f"maps-{protocol}": "docs/maps.md" for protocol in MAP_PROTOCOLS}}
# section name -> the command that regenerates it (the staleness check's fix)
REFRESH = {"headline": "python analysis/reproduce.py --seeds 5 --jobs 2 --update-docs",
           "results": "python analysis/reproduce.py --seeds 5 --jobs 2 --update-docs",
           "full-run": "python analysis/readme.py timing results/results.json (after a full reproduce.py)",
           "benchmark": "python analysis/benchmarks/benchmark.py --update-docs --repeats 3",
           "benchmark-pixels": "python analysis/benchmarks/benchmark_pixels.py --update-docs",
           "threads": "python analysis/benchmarks/threads.py --update-docs",
           "quick-budgets": "python analysis/benchmarks/quick_budgets.py --update-docs",
           "speed-accuracy": "python analysis/integrator_study/speed_accuracy.py --update-docs",
           "energy-drift": "python analysis/integrator_study/energy_drift.py --update-docs",
           "default-tolerances": "python analysis/integrator_study/tolerances.py --update-docs",
           "work-precision": "python analysis/integrator_study/work_precision.py --update-docs",
           "scenes": "python analysis/scene_study.py --jobs 2 --update-docs (or a few scenes a sitting, --scenes ...: "
                     "docs/scene_study-record.json keeps the others')",
           "model-guide": "python analysis/scene_study.py --jobs 2 --update-docs (or a few scenes a sitting, --scenes ...)",
           "measured-guide": "python analysis/scene_study.py --data FILE ... --jobs 2 --update-docs (docs/measured.md)",
           "peers": "python analysis/peers.py --jobs 2 --update-docs",
           "stress": "python analysis/stress.py --update-docs",
           "lnn-start": "python analysis/stress.py --lnn-start --update-docs",
           "units-scan": "python analysis/stress.py --scan --update-docs",
           # the runs that stop early (about 20 minutes on two workers); every one that stopped takes hours
           "lnn-pinv": "python analysis/stress.py --lnn-pinv --lnn-runs lnn/lagrangian/seed4 chain2/lagrangian/seed0 "
                       "chain2/lagrangian/seed2 chain2/lagrangian/seed3 chain3/lagrangian/seed4 chain5/lagrangian/seed1 "
                       "chain5/lagrangian/seed2 chain5/lagrangian/seed4 --lnn-past 200 --update-docs",
           # the arm's own units (the 10 kg arm's p of RMS 24 is what --units auto would rescale): --balance alone
           "arm-balance": "python analysis/arm.py --steps 2000 --mass 10 --balance off auto --units off --out "
                          "results/arm-m10 --update-docs",
           "arm-balance-long": "python analysis/arm.py --steps 4000 --mass 10 --models mechanical hnn --units off --out "
                               "results/arm-m10-4k --update-docs --section arm-balance-long",
           **{f"dgnet-{task}": f"python analysis/chains/dgnet.py --tasks {task} --jobs 2 --update-docs (their 15 trials)"
              for task in ("spring", "pend", "real", "2body")},
           **{f"dgnet-init-{task}": f"python analysis/chains/dgnet.py --tasks {task} --rows DGNet HNN --compare-init "
                                    "--jobs 2 --update-docs (their 15 trials)" for task in DGNET_INIT_TASKS},
           "ray-quick": "python analysis/benchmarks/ray_overhead.py --update-docs",
           "many-models": "python analysis/benchmarks/benchmark_many.py --update-docs",
           "fit-floor": "python analysis/fits/fit_floor.py --update-docs",
           "thread-spread": "python analysis/paper/thread_spread.py --update-docs",
           "many-models-gpu": "python analysis/benchmarks/benchmark_many.py --devices cuda --update-docs (on a GPU)",
           "gpu-check": "python analysis/benchmarks/gpu_check.py --update-docs (on a GPU)",
           "ray-full": "python analysis/benchmarks/ray_overhead.py --full --update-docs",
           "fits-sampling": "python analysis/fits/sampling_hnns.py --update-docs",
           "fits-tasks": "python analysis/fits/fit_tasks.py --jobs 2 --update-docs",
           "fits-library": "python analysis/fits/fit_tasks.py --jobs 2 --update-docs",
           "bodies": "python analysis/bodies.py --update-docs",
           "bodies-paper": "python analysis/bodies.py --paper --seeds 5 --jobs 2 --update-docs",
           "bodies-gravity": "python analysis/bodies.py --scene gravity --update-docs",
           "bodies-lj": "python analysis/bodies.py --scene lj --update-docs",
           "bodies-rebound": "python analysis/benchmarks/nbody_truth.py --update-docs",
           "bodies-scenes": "python analysis/scene_study.py --scenes gravity lattice lj --jobs 2 --update-docs",

           **{f"maps-{protocol}": f"python analysis/benchmarks/maps.py --protocols {protocol} --update-docs"
              for protocol in MAP_PROTOCOLS}}
# sections written from the code's declarations, not measured: name -> (page, the text's maker)
DECLARED = {"kinds": "README.md", "kinds-python": "docs/python.md"}
# the sections that draw verdicts (a table's marks or ranking, a card's choice): each records the seeds
# they rest on in docs/seeds.json when written, and one resting on fewer than MIN_SEEDS says why
VERDICTS = ("headline", "results", "scenes", "model-guide", "measured-guide", "peers", "stress", "lnn-start",
            "units-scan", "lnn-pinv", "arm-balance", "arm-balance-long", "fits-sampling", "fits-tasks", "fits-library",
            "bodies-paper", "bodies-scenes", *(f"dgnet-{task}" for task in ("spring", "pend", "real", "2body")),
            *(f"dgnet-init-{task}" for task in DGNET_INIT_TASKS), *(f"maps-{protocol}" for protocol in MAP_PROTOCOLS))
MIN_SEEDS = 3
SEEDS_FILE = "docs/seeds.json"


@dataclass(frozen=True)
class Seeds:
    """The seeds behind a section's verdicts: ``count``, the fewest that any of its verdicts rests on,
    and ``why`` it is fewer than ``MIN_SEEDS`` (then required: a sentence the page prints)."""
    count: int
    why: str | None = None

    def __post_init__(self):
        if self.count < 1:
            raise ValueError(f"a verdict rests on at least one seed, got {self.count}")
        if self.count < MIN_SEEDS and not self.why:
            raise ValueError(f"a verdict on {self.count} seed(s), fewer than {MIN_SEEDS}, must say why (Seeds(why=...))")

    def line(self) -> str:
        """The sentence the section ends with."""
        if self.count >= MIN_SEEDS:
            return f"Seeds: every verdict here rests on {self.count} or more seeds."
        return f"Seeds: verdicts here rest on {self.count} seed{'s' if self.count > 1 else ''}, fewer than " \
               f"{MIN_SEEDS}: {self.why.rstrip('.')}."


def stamp_of(text: str) -> str | None:
    """The commit a section's text names first (its stamp), or None."""
    found = re.search(r"commit[: ]+`?([0-9a-f]{7,40})\b", text)
    return found.group(1) if found else None


def recorded_seeds(root: Path | None = None) -> dict:
    """docs/seeds.json: ``{section: {"seeds", "why", "stamp"}}`` as the commands wrote them."""
    path = (root or hnn.tasks.repo_root()) / SEEDS_FILE
    return json.loads(path.read_text()) if path.exists() else {}


def _record_seeds(name: str, seeds: Seeds, text: str) -> None:
    record = recorded_seeds()
    record[name] = {"seeds": seeds.count, "why": seeds.why, "stamp": stamp_of(text)}
    atomic_write(hnn.tasks.repo_root() / SEEDS_FILE,
                 lambda tmp: Path(tmp).write_text(json.dumps(dict(sorted(record.items())), indent=1) + "\n"))


# a commit whose message holds a line "Numbers-unchanged: <why>" says it moves no generated number
# (imports, messages, flags that change what is printed): it leaves the stamps current
UNCHANGED = "Numbers-unchanged:"
# the code whose changes can move a generated number (git pathspecs)
CODE = ("hnn", "experiment-*")
# the few figures the README shows (about 1.2 MB in all), copied from a full run's figures/
CURATED = ("spring-fields.png", "real-fields.png", "2body-orbits.png", "3body-orbits.png",
           "pixels-compare-static.png")


def _page(name: str) -> str:
    return PAGES.get(name) or DECLARED.get(name, "README.md")


def kinds_text(name: str) -> str:
    """Section ``kinds`` (the README's line per kind) or ``kinds-python`` (docs/python.md's paragraph
    per kind): every kind of ``hnn.MODEL_KINDS``, in its order, as its row's ``doc`` describes it."""
    described = hnn.kinds.described()
    missing = [kind for kind, doc in described if doc is None]
    if missing:
        raise ValueError(f"model kind(s) {', '.join(missing)} registered but not described: give its row of "
                         "hnn.MODEL_KINDS (hnn/kinds.py) a doc=KindDoc(...)")
    return hnn.kind_docs.readme_lines(described) if name == "kinds" else hnn.kind_docs.python_paragraphs(described)


def declared_out_of_date(root: Path | None = None) -> list[str]:
    """One line per ``DECLARED`` section that is not what the code makes today, with its fix."""
    texts = {name: section_text(name, root) for name in DECLARED}
    try:
        kinds_text("kinds")
    except ValueError as err:
        return [str(err)]
    return [f"{DECLARED[name]} ({name}) is not what the rows of hnn.MODEL_KINDS make; refresh it: "
            "python analysis/readme.py kinds"
            for name, text in texts.items() if text is not None and text.strip() != kinds_text(name).strip()]


def update_section(name: str, text: str, seeds: Seeds | None = None) -> Path:
    """Replace section ``name`` of its page (``PAGES``, ``DECLARED``) with ``text``; returns the page.
    A section of ``VERDICTS`` needs its ``seeds``: its text ends with their line, and docs/seeds.json
    records them under the text's stamp."""
    if name in VERDICTS:
        if seeds is None:
            raise ValueError(f"section {name!r} draws verdicts: pass the seeds they rest on (pages.Seeds)")
        text = f"{text.rstrip()}\n\n{seeds.line()}"
    page = hnn.tasks.repo_root() / _page(name)
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    content = page.read_text() if page.exists() else ""
    if begin not in content or end not in content:
        raise ValueError(f"{page} has no {begin} ... {end} section to update; add the two markers where it goes")
    head, rest = content.split(begin, 1)
    tail = rest.split(end, 1)[1]
    atomic_write(page, lambda tmp: Path(tmp).write_text(f"{head}{begin}\n{text.rstrip()}\n{end}{tail}"))
    if seeds is not None:
        _record_seeds(name, seeds, text)
    return page


def section_text(name: str, root: Path | None = None) -> str | None:
    """The text of section ``name`` on its page, or None when the page or its markers are missing."""
    page = (root or hnn.tasks.repo_root()) / _page(name)
    content = page.read_text() if page.exists() else ""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    if begin not in content or end not in content:
        return None
    return content.split(begin, 1)[1].split(end, 1)[0]


def _git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)


def stale(names=None, root: Path | None = None) -> list[str]:
    """One line per generated section whose numbers may be older than the code: its stamp (the first
    ``commit <hash>`` in it) names a commit that lacks the last change to ``hnn/`` or ``experiment-*/``
    (but for commits whose message has a ``Numbers-unchanged: <why>`` line, and merges),
    or it has no stamp at all; each line says how to refresh it. Empty outside a git checkout."""
    root = root or hnn.tasks.repo_root()
    # merges left out: a merge's changes are its branch's commits, each with its own message
    last = _git(root, "log", "-1", "--no-merges", "--format=%h %cs", "--invert-grep", f"--grep=^{UNCHANGED}",
                "--", *CODE)
    if last.returncode != 0 or not last.stdout.strip():
        return []
    change, day = last.stdout.split()
    lines = []
    for name in names or PAGES:
        text = section_text(name, root)
        if text is None or "Not measured yet" in text:
            continue
        found = stamp_of(text)
        where = f"{PAGES[name]} ({name})"
        if found is None:
            lines.append(f"{where} names no commit; refresh it: {REFRESH[name]}")
        elif _git(root, "merge-base", "--is-ancestor", change, found).returncode != 0:
            lines.append(f"{where} is stamped {found}, older than the last change to hnn/ or "
                         f"experiment-*/ ({change}, {day}): its numbers may not be what the code makes today; "
                         f"refresh it: {REFRESH[name]}")
    return lines


def warn_stale(names=None) -> None:
    """Print ``stale(names)``'s lines as warnings (a command calls it before it writes those pages)."""
    for line in stale(names):
        print(f"warning: {line}", flush=True)


def update_results(tables: str, headline: str, fig_dir: Path | None, seeds: Seeds) -> list[Path]:
    """docs/results.md, the README's headline table and (from ``fig_dir``) docs/figures/; ``seeds``: the
    fewest seeds of any row."""
    written = [update_section("results", tables, seeds), update_section("headline", headline, seeds)]
    if fig_dir is not None:
        target = hnn.tasks.repo_root() / "docs" / "figures"
        target.mkdir(parents=True, exist_ok=True)
        for name in CURATED:
            if (Path(fig_dir) / name).exists():
                atomic_write(target / name, lambda tmp, name=name: shutil.copyfile(Path(fig_dir) / name, tmp))
                written.append(target / name)
    return written


def _s(value) -> str:
    return "" if value is None else f"{value:.1f}"


def stage_table(results: dict) -> list[str]:
    """Markdown lines: the seconds of each stage per task, and the wall times."""
    seconds = results.get("seconds", {})
    if not seconds.get("tasks"):
        return []
    jobs = seconds.get("jobs", 1)
    lines = ["**Time per stage** (seconds in this invocation; data = dataset load or generation inside "
             "train.py, train = the training loop, summed over seeds; reused = a saved run with the same args)", "",
             "| task | data | train baseline | train hnn | evaluate | figures |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for task, s in seconds["tasks"].items():
        train = [_s(s["train"].get(label)) if label in s["train"] else "reused" for label in ("baseline", "hnn")]
        lines.append(f"| {task} | {_s(s.get('data')) if s.get('data') is not None else 'reused'} | "
                     f"{train[0]} | {train[1]} | {_s(s.get('evaluate'))} | {_s(s.get('figures'))} |")
    if seconds.get("backend") == "ray":
        overlap = f"Ray tasks of {seconds.get('threads_per_job')} thread{'s' if seconds.get('threads_per_job') != 1 else ''} each, so runs overlap"
    elif jobs > 1:
        overlap = f"{jobs} worker processes of {seconds.get('threads_per_job')} threads, so runs overlap"
    else:
        overlap = "in this process"
    lines += ["", f"Wall time: training {_s(seconds.get('training'))} s ({overlap}), evaluation and figures "
                  f"{_s(seconds.get('evaluation'))} s, total {_s(seconds.get('total'))} s."]
    return lines




def timing_text(results: dict) -> str:
    """The stage-time table of a ``reproduce.py`` results dict, with the command that made it."""
    meta = results["meta"]
    lines = stage_table(results)
    if not lines:
        raise ValueError("these results hold no stage times (was anything trained?)")
    details = f"{meta['mode']}, {meta['cores']} cores{', ' + meta['cpu'] if meta.get('cpu') else ''}, torch {meta['torch']}"
    return "\n".join([generated_by(meta, details) + ":", ""] + lines) + "\n"


def generated_by(meta: dict, details: str) -> str:
    """``Generated by `command` on date (commit X, details)``: how a generated page names what made it (``meta``:
    ``provenance()`` and its ``command``; ``details``: the machine, versions and settings that page adds)."""
    date = f" on {meta['date']}" if meta.get("date") else ""      # JSON written before provenance had a date
    return f"Generated by `{meta['command']}`{date} (commit {meta.get('commit', '?')}, {details})"
