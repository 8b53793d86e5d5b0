"""The prose agrees with the code: every file of the checkout and every ``hnn.``/``hnn_analysis.``
name that the README, docs/ and the docstrings and comments of hnn/, analysis/ and the tasks
mention exists; the rollout methods docs/python.md lists are hnn.SOLVERS; and the README and
docs/testing.md hold no hand-written test counts or run times (those are printed by the commands
that measure them, or written into a generated section)."""
import importlib
import re

import pytest

import hnn

REPO = hnn.tasks.repo_root()
PROSE = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
CODE = [p for folder in ("hnn", "analysis") for p in sorted((REPO / folder).rglob("*.py"))] + \
    sorted(REPO.glob("experiment-*/*.py")) + sorted(REPO.glob("experiment-*/*.md"))
# a path under one of the checkout's folders, as prose names it (not inside a longer word or path)
PATH = re.compile(r"(?<![\w/.-])((?:hnn|analysis|tests|docs|experiment-[a-z0-9]+)/[\w/.-]*\.(?:py|md|json|txt))")
NAME = re.compile(r"(?<![\w./-])((?:hnn|hnn_analysis)(?:\.[A-Za-z_]\w*)+)")
# mentions that name no file of ours, on purpose: other projects' files, a placeholder
NOT_OURS = {"experiment-2body/train_dgnet.py",        # DGNet's own repository's script (analysis/chains/dgnet.py)
            "docs/x.md"}                              # the placeholder of a --update-docs help text


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` is a module, or an attribute path from the longest importable prefix."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            if not hasattr(obj, part):
                return False
            obj = getattr(obj, part)
        return True
    return False


def _generated_removed(text: str) -> str:
    """``text`` without its generated sections (``<!-- x:begin -->`` ... ``<!-- x:end -->``)."""
    return re.sub(r"<!-- ([\w-]+):begin -->.*?<!-- \1:end -->", "", text, flags=re.S)


@pytest.mark.parametrize("path", PROSE + CODE, ids=lambda p: str(p.relative_to(REPO)))
def test_every_file_and_name_the_text_mentions_exists(path):
    text = path.read_text()
    missing = sorted({m.rstrip(".") for m in PATH.findall(text)} - NOT_OURS
                     - {m.rstrip(".") for m in PATH.findall(text) if (REPO / m.rstrip(".")).exists()})
    assert not missing, f"{path.name} names files the checkout does not have: {missing}"
    unresolved = sorted({m for m in NAME.findall(text) if not _resolves(m)})
    assert not unresolved, f"{path.name} names what hnn does not have: {unresolved}"


def test_the_checks_catch_a_missing_file_and_a_moved_name():
    assert PATH.findall("see `analysis/benchmark_orbits.py` and tests/test_tasks.py.") == [
        "analysis/benchmark_orbits.py", "tests/test_tasks.py"]
    assert not (REPO / "analysis/benchmark_orbits.py").exists()
    assert NAME.findall("``hnn.paper.PAPER`` or hnn.tasks.PAPER; truth-vs-hnn.gif") == ["hnn.paper.PAPER",
                                                                                        "hnn.tasks.PAPER"]
    assert not _resolves("hnn.paper.PAPER") and _resolves("hnn.tasks.PAPER") and _resolves("hnn.models.tanh_mlp")


def test_the_rollout_methods_docs_python_lists_are_the_registered_solvers():
    text = (REPO / "docs" / "python.md").read_text()
    listed = re.search(r"`hnn\.rollout\(f, x0, t_eval, method=([^`]*?), \.\.\.\)`", text).group(1)
    assert set(re.findall(r"'(\w+)'", listed)) == set(hnn.SOLVERS)


@pytest.mark.parametrize("page", ["README.md", "docs/testing.md"])
def test_no_hand_written_test_counts_or_run_times(page):
    prose = _generated_removed((REPO / page).read_text())
    counts = re.findall(r"\b\d[\d,]* (?:tests|passed|skipped)\b", prose)
    times = re.findall(r"\b(?:about |took |in )\d[\d.,]* ?(?:s|seconds|minutes?|min)\b", prose)
    assert not counts and not times, (counts, times)


# an absolute path of some machine, as a command line or prose would hold it (a flag's value, a quoted path)
MACHINE_PATH = re.compile(r"(?:^|[\s`'\"(=])(/(?:work|home|root|tmp|private|Users|mnt|scratch|data|var|opt)/[\w./-]*)")


@pytest.mark.parametrize("path", PROSE, ids=lambda p: str(p.relative_to(REPO)))
def test_no_page_holds_a_machines_path(path):
    # the commands write their own command lines into generated sections: a folder outside the
    # checkout shows as DIR (hnn_analysis.commands.portable_command), never as one machine's path
    found = MACHINE_PATH.findall(path.read_text())
    assert not found, f"{path.name} holds a machine's path: {found[:3]}; regenerate it, or write DIR"


def test_the_machine_path_check_catches_a_flags_value_and_leaves_urls_and_repo_paths(tmp_path):
    runs = tmp_path.resolve() / "runs"          # a folder of this machine, whatever its OS calls it
    assert MACHINE_PATH.findall(f"`python analysis/x.py --runs {runs} --out={tmp_path.resolve()}`") == [
        str(runs), str(tmp_path.resolve())]
    assert not MACHINE_PATH.findall("https://github.com/greydanus/hnn and docs/speed.md and --out DIR")


_NUMBERS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8, "nine": 9}


def test_the_counts_the_prose_gives_of_the_package_are_the_codes():
    """The number of ``hnn.__all__``'s names in ``hnn``'s docstring, and of the package's levels in
    docs/README.md (``hnn._LAYERS``, where the two rooms ``integrators`` and ``models`` share one level)."""
    said = re.search(r"gives the (\d+) names of ``__all__``", hnn.__doc__)
    assert said and int(said.group(1)) == len(hnn.__all__), (said and said.group(0), len(hnn.__all__))
    levels = len(hnn._LAYERS) - 1
    text = (REPO / "docs" / "README.md").read_text()
    said = re.search(r"the package in (\w+) levels", text)
    assert said and _NUMBERS.get(said.group(1)) == levels, (said and said.group(0), levels)
    for name in hnn._LAYERS:
        assert name in text.split("**Layout.**")[1].split("\n\n")[0], f"docs/README.md's layout omits {name}"
