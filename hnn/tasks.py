"""Find a task's modules by name: the one place where the package knows the repo layout.

Task ``name`` lives in ``<repo>/experiment-<name>/`` (``data.py`` and ``train.py``). Folder
names have hyphens, so the modules are loaded by path, each under a unique module name.
"""
from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

TASKS = ("spring", "pend", "real", "2body", "3body", "pixels")


def repo_root() -> Path:
    """The checkout that holds the ``experiment-*`` folders (``HNN_REPO`` overrides)."""
    root = Path(os.environ.get("HNN_REPO", Path(__file__).resolve().parent.parent))
    if not any(root.glob("experiment-*")):
        raise FileNotFoundError(
            f"no experiment-* folders under {root}: the tasks live in the repository, not in the "
            "installed package; install it with `pip install -e .` from a checkout, or set HNN_REPO")
    return root


def available_tasks() -> list[str]:
    """Names of the tasks present in this checkout, in the paper's order."""
    root = repo_root()
    return [t for t in TASKS if (root / f"experiment-{t}" / "data.py").exists()]


ANALYSIS = "hnn_analysis"   # the import name of the checkout's analysis/ folder (pyproject maps it)


def import_analysis() -> ModuleType:
    """The analysis package ``hnn_analysis``: the ``analysis/`` folder beside this ``hnn`` when there
    is one (a checkout, installed or not), else the installed package.

    ``pip install -e .`` maps the name to the folder; this also covers a checkout run without that
    install, or installed before the mapping existed. The commands in ``analysis/`` call it before
    importing each other, so ``python analysis/<command>.py`` works either way.
    """
    if ANALYSIS not in sys.modules:
        folder = Path(__file__).resolve().parent.parent / "analysis"
        if (folder / "__init__.py").is_file():
            _load(ANALYSIS, folder / "__init__.py", package=folder)
    return importlib.import_module(ANALYSIS)


def _load(mod_name: str, path: Path, package: Path | None = None) -> ModuleType:
    """The file ``path`` executed as module ``mod_name`` (a package searching ``package`` if given)."""
    locations = None if package is None else [str(package)]
    spec = importlib.util.spec_from_file_location(mod_name, path, submodule_search_locations=locations)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules[mod_name]
        raise
    return mod


def load_task(name: str, module: str = "data") -> ModuleType:
    """``experiment-<name>/<module>.py`` as a module (cached, so each is loaded once)."""
    path = repo_root() / f"experiment-{name}" / f"{module}.py"
    if not path.exists():
        raise ValueError(f"unknown task {name!r} (no {path}); available: {available_tasks()}")
    mod_name = f"hnn_task_{name}_{module}"
    if mod_name in sys.modules:
        return sys.modules[mod_name]
    return _load(mod_name, path)
