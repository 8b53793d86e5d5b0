"""The package's layers (``hnn._LAYERS``, described in hnn/__init__.py): every import of every module
in hnn/, top-level or inside a function, goes to its own layer or a lower one, and integrators and
models know nothing of each other."""
import ast
from pathlib import Path

import hnn

PACKAGE = Path(hnn.__file__).parent
ORDER = {"base": 0, "integrators": 1, "models": 1, "training": 2, "runs": 3}


def _layer_of() -> dict:
    return {module: layer for layer, modules in hnn._LAYERS.items() for module in modules}


def _imports(path: Path) -> set[str]:
    """The hnn modules that ``path`` imports anywhere in its code."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1 and node.module:                 # from .x import y
                found.add(node.module.split(".")[0])
            elif node.level == 1:                               # from . import x, y
                found.update(alias.name for alias in node.names)
            elif node.level == 0 and node.module and node.module.split(".")[0] == "hnn":
                parts = node.module.split(".")
                found.update([parts[1]] if len(parts) > 1 else [alias.name for alias in node.names])
        elif isinstance(node, ast.Import):
            found.update(a.name.split(".")[1] for a in node.names if a.name.startswith("hnn.") )
    return found


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
    modules = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__"}
    listed = [m for ms in hnn._LAYERS.values() for m in ms]
    assert len(listed) == len(set(listed)), "a module is in two layers"
    assert set(listed) == modules, (f"without a layer: {sorted(modules - set(listed))}; "
                                    f"listed but absent: {sorted(set(listed) - modules)}")


def test_no_module_imports_a_higher_layer_or_across_the_middle():
    layer_of = _layer_of()
    imports = {p.stem: _imports(p) for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    assert violations(layer_of, imports) == []


def test_the_rules_catch_an_upward_and_a_sideways_import():
    layer_of = {"errors": "base", "integrate": "integrators", "models": "models", "runs": "runs"}
    imports = {"errors": {"runs"}, "integrate": {"models", "errors"}, "models": set(), "runs": {"integrate"}}
    assert violations(layer_of, imports) == ["errors (base) imports runs (runs)",
                                             "integrate (integrators) imports models (models)"]
