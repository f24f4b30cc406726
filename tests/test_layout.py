"""The package layout (README "Layout"): each layer imports only from the layers before it, and no module
imports itself back through others. Read from the import statements, so it fails when a change adds an
upward import or a cycle (e.g. the algorithm reaching into `metrics`)."""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "qemjax"
LAYERS = ["_mesh", "_io", "_options", "_kernels", "_costs", "_schedulers", "_record", "_pipeline", "_partition",
          "metrics", "costs", "peers", "shapes", "render", "_sweep", "__init__", "_ahead", "_cli", "__main__"]
# the one import against the layers: `simplify(partition=...)` hands the run to the partitioned driver, which
# runs `simplify` on each part (imported inside the function that dispatches, so importing either stays light)
DISPATCH = {("qemjax._pipeline.api", "qemjax._partition.run")}


def _modules() -> dict[str, tuple[Path, list[str]]]:
    """module name -> (file, the package its relative imports start from)."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ["qemjax", *path.with_suffix("").relative_to(PACKAGE).parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
            package = parts
        else:
            package = parts[:-1]
        out[".".join(parts)] = (path, package)
    return out


def _imports() -> dict[str, set[str]]:
    """module -> the qemjax modules it imports (a name imported from a package counts as the package unless
    it is a submodule)."""
    mods = _modules()
    out = {}
    for name, (path, package) in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name.split(".")[0] == "qemjax"}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
                elif (node.module or "").split(".")[0] == "qemjax":
                    base = node.module
                else:
                    continue
                deps |= {f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names}
        out[name] = {d for d in deps - {name} if (name, d) not in DISPATCH}
    return out


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_module_is_in_a_layer():
    assert {_layer(m) for m in _modules()} <= set(LAYERS)


def test_layers_import_only_earlier_layers():
    upward = []
    for module, deps in _imports().items():
        rank = LAYERS.index(_layer(module))
        upward += [f"{module} imports {d}" for d in deps if LAYERS.index(_layer(d)) > rank]
    assert not upward, "\n".join(sorted(upward))


def test_no_import_cycles():
    graph = _imports()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d):] + [m, d]))
            if d not in state:
                visit(d, path + [m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])
