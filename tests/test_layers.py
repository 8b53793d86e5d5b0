"""The rooms of the code and the imports between them, read from the source by one walker.

- ``hnn``'s layers (``hnn._LAYERS``, described in hnn/__init__.py): every import of every module in
  hnn/, top-level or inside a function, goes to its own layer or a lower one, and integrators and
  models know nothing of each other.
- ``analysis``'s rooms (``hnn_analysis._ROOMS`` and ``_MAY_IMPORT``, described in analysis/__init__.py):
  every import of every module in analysis/ goes to its own room or one its row names; analysis
  imports hnn, hnn never analysis.
- No circle: the graph of every import of every module of hnn/ and analysis/ (inside functions too,
  where a circle hides) has none.
"""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

import hnn
import hnn_analysis

PACKAGE = Path(hnn.__file__).parent
ANALYSIS = Path(hnn_analysis.__file__).parent
TREES = {"hnn": PACKAGE, "hnn_analysis": ANALYSIS}
ORDER = {"base": 0, "integrators": 1, "models": 1, "training": 2, "runs": 3, "orbits": 4, "sweeps": 5}


# ----------------------------------------------------------------------------------------------
# the walker: every module of a tree by its dotted name, and every import in it


def modules(root: Path, package: str) -> dict[str, Path]:
    """Every module under ``root``, subpackages included, by its dotted name (``hnn.models.mlp``;
    a package's ``__init__.py`` under the package's name)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join((package, *parts[:-1]) if parts[-1] == "__init__" else (package, *parts))] = path
    return out


def imports(name: str, path: Path, known) -> set[str]:
    """The modules of ``known`` (dotted names) that module ``name`` (at ``path``) imports anywhere in its
    code: at the top, in a class, an ``if`` or a function; relative (``from . import x``, ``from ..x
    import y``) and absolute. ``from a import b`` is module ``a.b`` where that is one, else ``a``."""
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = here.rsplit(".", node.level - 1)[0] if node.level > 1 else here if node.level else ""
            base = ".".join(filter(None, (base, node.module)))
            found |= {f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names}
        elif isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
    return (found & set(known)) - {name}


def import_graph(trees: dict[str, Path] = TREES) -> dict[str, set[str]]:
    """``{module: the modules it imports}`` over every module of ``trees`` (``{package: folder}``)."""
    known = {name: path for package, root in trees.items() for name, path in modules(root, package).items()}
    return {name: imports(name, path, known) for name, path in known.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One import circle (``[a, b, ..., a]``) for each group of modules that reach each other
    (Tarjan's strongly connected components, iterative), sorted; empty where the graph has none."""
    index, low, on_stack, stack, found, counter = {}, {}, set(), [], [], [0]

    def connect(start):
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.add(member)
                    if member == node:
                        break
                if len(group) > 1:
                    found.append(_path_around(graph, group))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    return sorted(found)


def _path_around(graph: dict, group: set) -> list[str]:
    """A circle through the first module of ``group``, within ``group`` (breadth first: the shortest)."""
    start = min(group)
    came = {start: None}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for child in sorted(graph[node] & group):
            if child == start:
                path = [node]
                while came[path[-1]] is not None:
                    path.append(came[path[-1]])
                return [*reversed(path), start]
            if child not in came:
                came[child] = node
                queue.append(child)
    raise AssertionError(f"{sorted(group)} is not a circle")


# ----------------------------------------------------------------------------------------------
# hnn's layers


def _hnn_unit(module: str) -> str:
    """What ``_LAYERS`` lists for a module of hnn: its room's folder for a module in one, else its name."""
    return module.split(".")[1]


def hnn_violations(layer_of: dict, graph: dict) -> list[str]:
    """``'a (layer) imports b (layer)'`` for every import between units of ``layer_of`` against the rules:
    upward, or sideways between the two rooms of the middle. ``graph``: ``{unit: the units it imports}``."""
    bad = []
    for module, targets in sorted(graph.items()):
        mine = layer_of[module]
        for target in sorted(set(targets) & set(layer_of) - {module}):
            theirs = layer_of[target]
            if ORDER[theirs] > ORDER[mine] or (ORDER[theirs] == ORDER[mine] == 1 and theirs != mine):
                bad.append(f"{module} ({mine}) imports {target} ({theirs})")
    return bad


def _unit_graph(graph: dict, package: str, unit_of) -> dict[str, set[str]]:
    """``graph`` of the modules of ``package`` folded to their units (``unit_of(module)``)."""
    units = {}
    for module, targets in graph.items():
        if module == package or not module.startswith(package + "."):
            continue
        units.setdefault(unit_of(module), set()).update(
            unit_of(t) for t in targets if t.startswith(package + "."))
    return units


def test_every_module_of_hnn_has_one_layer():
    units = {_hnn_unit(m) for m in modules(PACKAGE, "hnn") if m != "hnn"}
    listed = [m for ms in hnn._LAYERS.values() for m in ms]
    assert len(listed) == len(set(listed)), "a module is in two layers"
    assert set(listed) == units, (f"without a layer: {sorted(units - set(listed))}; "
                                  f"listed but absent: {sorted(set(listed) - units)}")


def test_no_module_of_hnn_imports_a_higher_layer_or_across_the_middle():
    layer_of = {module: layer for layer, ms in hnn._LAYERS.items() for module in ms}
    assert hnn_violations(layer_of, _unit_graph(import_graph(), "hnn", _hnn_unit)) == []


def test_the_walker_reads_rooms_relative_imports_and_imports_inside_functions():
    """A module in a room that imports a sibling counts as its own room (no violation); ``from ..errors``
    from ``integrators`` is the errors module; an import inside a function counts like one at the top."""
    graph = import_graph()
    assert "hnn.errors" in graph["hnn.integrators.fixed_step"]
    assert not any(t.startswith("hnn.integrators") for t in graph["hnn.models.mlp"])
    assert {"hnn.kinds", "hnn.objectives"} <= graph["hnn.config"]        # both imported inside a method
    assert "hnn_analysis.paper.figures" in graph["hnn_analysis.paper.registry"]      # "from pkg import module"


TOP_UNITS = {unit for layer in ("runs", "orbits", "sweeps") for unit in hnn._LAYERS[layer]}


@pytest.mark.parametrize("module", sorted(m.split(".", 1)[1] for m in modules(PACKAGE, "hnn")
                                          if m != "hnn" and _hnn_unit(m) in TOP_UNITS))
def test_each_top_module_of_hnn_imports_first_in_a_fresh_interpreter(module):
    """Imported before anything else (as a worker process or a user's script does), a module of the top
    layers loads, and so does the whole package after it: ``from . import x`` of a module not yet loaded
    asks ``hnn.__getattr__``, which loads every layer, so a module that takes a name from a module
    still half loaded would fail here."""
    result = subprocess.run([sys.executable, "-c", f"import hnn.{module}, hnn; hnn.HNN"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]


def test_the_hnn_rules_catch_an_upward_and_a_sideways_import():
    layer_of = {"errors": "base", "integrate": "integrators", "models": "models", "runs": "runs"}
    graph = {"errors": {"runs"}, "integrate": {"models", "errors"}, "models": set(), "runs": {"integrate"}}
    assert hnn_violations(layer_of, graph) == ["errors (base) imports runs (runs)",
                                               "integrate (integrators) imports models (models)"]


# ----------------------------------------------------------------------------------------------
# analysis's rooms


def _analysis_unit(module: str) -> str:
    """What ``hnn_analysis._ROOMS`` lists for a module of analysis: its folder, or its own name at the top."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def analysis_violations(room_of: dict, may_import: dict, graph: dict) -> list[str]:
    """``'a (room) imports b (room)'`` for every import between units of ``room_of`` to a room that
    the importer's row of ``may_import`` does not name (its own room always allowed)."""
    bad = []
    for unit, targets in sorted(graph.items()):
        mine = room_of[unit]
        for target in sorted(set(targets) & set(room_of) - {unit}):
            theirs = room_of[target]
            if theirs != mine and theirs not in may_import[mine]:
                bad.append(f"{unit} ({mine}) imports {target} ({theirs})")
    return bad


def test_every_module_of_analysis_has_one_room_and_every_rule_names_rooms():
    units = {_analysis_unit(m) for m in modules(ANALYSIS, "hnn_analysis")}
    listed = [m for ms in hnn_analysis._ROOMS.values() for m in ms]
    assert len(listed) == len(set(listed)), "a module is in two rooms"
    assert set(listed) == units, (f"without a room: {sorted(units - set(listed))}; "
                                  f"listed but absent: {sorted(set(listed) - units)}")
    assert set(hnn_analysis._MAY_IMPORT) == set(hnn_analysis._ROOMS)
    assert all(set(rooms) <= set(hnn_analysis._ROOMS) for rooms in hnn_analysis._MAY_IMPORT.values())


def test_no_module_of_analysis_imports_a_room_its_rule_does_not_name():
    room_of = {unit: room for room, units in hnn_analysis._ROOMS.items() for unit in units}
    graph = import_graph()
    # a top-level module is its own unit; "hnn_analysis" itself (its __init__) the unit "__init__"
    units = _unit_graph({("hnn_analysis.__init__" if m == "hnn_analysis" else m): t for m, t in graph.items()},
                        "hnn_analysis", _analysis_unit)
    assert analysis_violations(room_of, hnn_analysis._MAY_IMPORT, units) == []


def test_analysis_imports_hnn_and_hnn_never_analysis():
    graph = import_graph()
    assert not [f"{m} imports {t}" for m, ts in graph.items() if m.split(".")[0] == "hnn"
                for t in ts if t.split(".")[0] == "hnn_analysis"]
    assert any(t.split(".")[0] == "hnn" for m, ts in graph.items() if m.startswith("hnn_analysis") for t in ts)


def test_the_analysis_rules_catch_an_import_the_table_does_not_name():
    room_of = {"commands": "shared", "scenes": "scenes", "paper": "paper", "chains": "chains"}
    may_import = {"shared": (), "paper": ("shared",), "scenes": ("shared", "paper"), "chains": ("shared",)}
    graph = {"commands": set(), "paper": {"commands"}, "scenes": {"paper", "commands"}, "chains": {"scenes", "paper"}}
    assert analysis_violations(room_of, may_import, graph) == ["chains (chains) imports paper (paper)",
                                                               "chains (chains) imports scenes (scenes)"]
    graph["commands"] = {"paper"}
    assert "commands (shared) imports paper (paper)" in analysis_violations(room_of, may_import, graph)


COMMAND_LINES = 150
# command files still longer, each with why: a ratchet (the test fails once one is short enough, so the
# list only shrinks); none is left
LONGER_YET: set = set()


def command_files(root: Path = ANALYSIS) -> dict[str, int]:
    """``{path under the repository: lines}`` of every command file of analysis/: a module with a ``main``."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        if any(isinstance(node, ast.FunctionDef) and node.name == "main" for node in tree.body):
            found[path.relative_to(root.parent).as_posix()] = len(path.read_text().splitlines())
    return found


def test_every_command_file_is_short_the_machinery_lives_in_library_modules():
    """A command parses, calls and publishes; what it calls lives in a module without a ``main``."""
    commands = command_files()
    assert {"analysis/paper/reproduce.py", "analysis/scenes/scene_study.py", "analysis/chains/peers.py"} <= set(commands)
    assert not {path: n for path, n in commands.items() if n > COMMAND_LINES and path not in LONGER_YET}
    assert not {path for path in LONGER_YET if commands.get(path, 0) <= COMMAND_LINES}, "now short: drop it from the list"


def test_command_files_finds_a_long_command(tmp_path):
    (tmp_path / "analysis").mkdir()
    (tmp_path / "analysis" / "lib.py").write_text("x = 1\n" * 400)
    (tmp_path / "analysis" / "cmd.py").write_text("def main():\n    pass\n" + "x = 1\n" * 200)
    assert command_files(tmp_path / "analysis") == {"analysis/cmd.py": 202}


# ----------------------------------------------------------------------------------------------
# no circle anywhere


def test_the_walker_reads_every_module_of_hnn_and_analysis():
    graph = import_graph()
    assert len(graph) == len(list(PACKAGE.rglob("*.py"))) + len(list(ANALYSIS.rglob("*.py")))
    assert {"hnn.cli", "hnn.models.mlp", "hnn_analysis", "hnn_analysis.paper.reproduce"} <= set(graph)


def test_no_import_circle_in_hnn_and_analysis():
    assert circles(import_graph()) == []


def test_the_walker_finds_a_planted_circle_through_a_subpackage_and_a_function(tmp_path):
    """A circle ``b -> sub.a -> b`` where ``b`` imports inside a function and ``a`` relatively."""
    pkg = tmp_path / "toy" / "sub"
    pkg.mkdir(parents=True)
    (tmp_path / "toy" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from .a import A\n")
    (pkg / "a.py").write_text("from ..b import B\nA = 1\n")
    (tmp_path / "toy" / "b.py").write_text("B = 2\n\n\ndef later():\n    from toy.sub import a\n    return a\n")
    (tmp_path / "toy" / "c.py").write_text("from . import b\n")
    graph = import_graph({"toy": tmp_path / "toy"})
    assert graph == {"toy": set(), "toy.sub": {"toy.sub.a"}, "toy.sub.a": {"toy.b"}, "toy.b": {"toy.sub.a"},
                     "toy.c": {"toy.b"}}
    assert circles(graph) == [["toy.b", "toy.sub.a", "toy.b"]]
    (tmp_path / "toy" / "b.py").write_text("B = 2\n")
    assert circles(import_graph({"toy": tmp_path / "toy"})) == []


@pytest.mark.parametrize("graph, expected", [
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [["a", "b", "c", "a"]]),
    ({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"c"}, "e": set()}, [["a", "b", "a"], ["c", "d", "c"]]),
    ({"a": {"b", "c"}, "b": {"c"}, "c": set()}, []),
], ids=["three", "two-circles", "diamond"])
def test_circles_on_synthetic_graphs(graph, expected):
    assert circles(graph) == expected


# ----------------------------------------------------------------------------------------------
# hnn's public face


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
