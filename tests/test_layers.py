"""The package's layers (``hnn._LAYERS``, described in hnn/__init__.py): every import of every module
in hnn/, top-level or inside a function, goes to its own layer or a lower one, and integrators and
models know nothing of each other."""
import ast
import subprocess
import sys
from pathlib import Path

import hnn

PACKAGE = Path(hnn.__file__).parent
ORDER = {"base": 0, "integrators": 1, "models": 1, "training": 2, "runs": 3}


def _layer_of() -> dict:
    return {module: layer for layer, modules in hnn._LAYERS.items() for module in modules}


def _unit(path: Path) -> str:
    """What ``_LAYERS`` lists for a file: its room's folder for a module in one, else its stem."""
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else path.stem


def _imports(path: Path) -> set[str]:
    """The units of ``hnn`` (top-level modules or rooms) that ``path`` imports anywhere in its code."""
    package = ["hnn", *path.relative_to(PACKAGE).parts[:-1]]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            target = [*base, *(node.module.split(".") if node.module else [])]
            if target[:1] != ["hnn"]:
                continue
            # "from hnn import x" / "from . import x" (at the package's top): x is the unit
            found.update([target[1]] if len(target) > 1 else [alias.name for alias in node.names])
        elif isinstance(node, ast.Import):
            found.update(a.name.split(".")[1] for a in node.names if a.name.startswith("hnn."))
    return found


def _files() -> list[Path]:
    return [p for p in PACKAGE.rglob("*.py") if p.name != "__init__.py" or p.parent != PACKAGE]


def violations(layer_of: dict, imports: dict) -> list[str]:
    """``'a (layer) imports b (layer)'`` for every import against the rules."""
    bad = []
    for module, targets in sorted(imports.items()):
        mine = layer_of[module]
        for target in sorted(targets & set(layer_of)):
            theirs = layer_of[target]
            if ORDER[theirs] > ORDER[mine] or (ORDER[theirs] == ORDER[mine] == 1 and theirs != mine):
                bad.append(f"{module} ({mine}) imports {target} ({theirs})")
    return bad


def test_every_module_has_one_layer():
    modules = {_unit(p) for p in _files()}
    listed = [m for ms in hnn._LAYERS.values() for m in ms]
    assert len(listed) == len(set(listed)), "a module is in two layers"
    assert set(listed) == modules, (f"without a layer: {sorted(modules - set(listed))}; "
                                    f"listed but absent: {sorted(set(listed) - modules)}")


def test_no_module_imports_a_higher_layer_or_across_the_middle():
    layer_of = _layer_of()
    imports = {}
    for path in _files():
        unit = _unit(path)
        imports.setdefault(unit, set()).update(_imports(path) - {unit})
    assert violations(layer_of, imports) == []


def test_the_rooms_are_folders_and_read_their_own_relative_imports():
    """A module in a room that imports a sibling counts as its own room (no violation), one that
    reaches ``..models`` from ``integrators`` counts as the other room."""
    fixed_step = PACKAGE / "integrators" / "fixed_step.py"
    assert _unit(fixed_step) == "integrators" and "errors" in _imports(fixed_step)
    assert "integrators" not in _imports(PACKAGE / "models" / "mlp.py")
    assert {"integrators", "models"} <= _imports(PACKAGE / "kinds.py") | _imports(PACKAGE / "evaluation.py")


def test_the_rules_catch_an_upward_and_a_sideways_import():
    layer_of = {"errors": "base", "integrate": "integrators", "models": "models", "runs": "runs"}
    imports = {"errors": {"runs"}, "integrate": {"models", "errors"}, "models": set(), "runs": {"integrate"}}
    assert violations(layer_of, imports) == ["errors (base) imports runs (runs)",
                                             "integrate (integrators) imports models (models)"]


def test_the_public_names_are_spelled_out_for_type_checkers():
    """``hnn/__init__.py``'s ``if TYPE_CHECKING:`` imports name every public name from its module, as
    ``_PUBLIC`` binds them at run time: go-to-definition and pyright see what ``hnn.rollout`` is."""
    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    block = next(node for node in tree.body if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING")
    spelled = {(node.module, alias.name) for node in block.body if isinstance(node, ast.ImportFrom) and node.module
               for alias in node.names}
    assert spelled == {(module, name) for module, names in hnn._PUBLIC.items() for name in names}


def test_dir_lists_the_public_names_without_loading_torch():
    code = "import sys, hnn; names = dir(hnn); print('rollout' in names, 'torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["True", "False"]
