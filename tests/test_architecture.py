"""The house: no import cycle between modules or between packages, and no function that takes
more than a dozen parameters (a structure is missing where one does)."""

import ast
from pathlib import Path

from conftest import ROOT

PACKAGE = ROOT / "src" / "spotsim"
#: A function with more parameters than this is a sign that a structure is missing.
MAX_PARAMETERS = 12


def modules() -> dict[str, tuple[Path, bool]]:
    """Every module of the package: dotted name -> (file, is a package's __init__)."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        init = parts[-1] == "__init__"
        out[".".join(parts[:-1] if init else parts)] = (path, init)
    return out


def imports() -> dict[str, set[str]]:
    """Each module's imports of the package's modules, wherever in the module they stand
    (a function's lazy import included)."""
    mods = modules()
    graph = {}
    for name, (path, init) in mods.items():
        base = name.split(".") if init else name.split(".")[:-1]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name in mods)
            elif isinstance(node, ast.ImportFrom):
                target = ".".join(base[:len(base) - node.level + 1] + ([node.module] if node.module else [])) \
                    if node.level else (node.module or "")
                for a in node.names:
                    full = f"{target}.{a.name}"
                    deps.add(full if full in mods else target)
        graph[name] = {d for d in deps if d in mods and d != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The graph's strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_module_imports_itself_through_others():
    """No cycle among the modules' imports."""
    assert cycles(imports()) == []


def test_no_package_imports_itself_through_others():
    """No cycle among the packages (spotsim's subpackages and top-level modules): the layers
    run tables -> contact -> sim -> assemble -> run -> studies, replay, cli."""
    layer = lambda name: name.split(".")[1] if name.count(".") else name
    graph = {}
    for name, deps in imports().items():
        if name == "spotsim":  # the public API's __init__ gathers every layer
            continue
        graph.setdefault(layer(name), set()).update(layer(d) for d in deps if layer(d) != layer(name))
    assert cycles(graph) == []


def test_no_function_takes_more_than_a_dozen_parameters():
    """Every function takes at most MAX_PARAMETERS parameters."""
    wide = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                if n > MAX_PARAMETERS:
                    wide.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.name} ({n})")
    assert wide == []
