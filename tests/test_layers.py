"""The package's import graph: no module imports a higher layer, and no modules import each other in a cycle.

Every module under ``src/unmesh`` is parsed with :mod:`ast` (nothing is imported) and ALL
its imports are collected: top-level ones, lazy ones inside functions, ``if TYPE_CHECKING:``
ones, relative ones (resolved against the module's package), ``importlib.import_module``
/ ``__import__`` calls with a literal name, and registry strings that name a module exactly
(``unmesh.cli.COMMAND_MODULES``, ``unmesh.gallery.EXAMPLE_MODULES``: importlib loads them).

The rule checked (also written in CONTRIBUTING.md, "Layers"):

* An import names one module: ``import a.b``, ``from a.b import c`` and ``from a import b``
  depend on the module ``a.b.c`` when ``c`` is a module, else on ``a.b`` (its ``__init__``
  when ``a.b`` is a package). Running the parent packages' ``__init__`` that Python does
  before any submodule is not counted, so a package's ``__init__`` re-exporting its own
  submodules is a downward edge, not a cycle.
* A module's layer is that of the longest entry of :data:`LAYERS` that is the module or one
  of its packages (``unmesh.surfels.cloud`` is data model, the rest of ``unmesh.surfels``
  one layer up). A module may import its own layer or lower ones, never a higher one.
* No cycles between modules, same layer or not: a submodule that imports its own package
  (``from unmesh.shells import x`` inside ``unmesh.shells.y``) while the package's
  ``__init__`` imports that submodule back is a cycle; internal modules import their
  siblings directly.
"""

from __future__ import annotations

import ast
from collections import deque
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

#: Layers, bottom to top; each names packages or modules (longest match wins).
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("base", ("unmesh.errors", "unmesh._validate", "unmesh._version", "unmesh._linalg_kernels", "unmesh._threads",
              "unmesh._csr_kernels", "unmesh._csr", "unmesh.sim.threads", "unmesh.scenes", "unmesh.distributed")),
    ("core", ("unmesh.kernels", "unmesh.spatial", "unmesh.surfels.cloud", "unmesh.meshes",
              "unmesh.particles")),
    ("geometry", ("unmesh.surfels", "unmesh.shapes", "unmesh.io")),
    ("surfaces", ("unmesh.mls", "unmesh.scene")),
    ("engines", ("unmesh.render", "unmesh.sim")),
    ("capabilities", ("unmesh.sph", "unmesh.shells", "unmesh.fem", "unmesh.csg", "unmesh.paint",
                      "unmesh.convert", "unmesh.batch")),
    ("applications", ("unmesh", "unmesh.__main__", "unmesh.cli", "unmesh.gallery")),
)


def module_files() -> dict[str, Path]:
    """Every module of the package, by dotted name (a package by its ``__init__``)."""
    out = {}
    for path in sorted((SRC / "unmesh").rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = module_files()


def is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def layer_of(name: str) -> tuple[int, str]:
    """(index, layer name) of a module; raises when no entry of :data:`LAYERS` covers it."""
    best: tuple[int, int, str] | None = None
    for index, (layer, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (name == prefix or name.startswith(prefix + ".")) and (best is None or len(prefix) > best[0]):
                best = (len(prefix), index, layer)
    if best is None or (best[0] == len("unmesh") and name not in ("unmesh",)):
        raise LookupError(f"{name} has no layer: add it (or its package) to LAYERS in tests/test_layers.py "
                          f"and to the layer table in CONTRIBUTING.md")
    return best[1], best[2]


def _known(name: str) -> str | None:
    """The longest prefix of ``name`` that is a module of the package."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in MODULES:
            return candidate
        parts.pop()
    return None


def _docstring_nodes(tree: ast.Module) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                ids.add(id(first.value))
    return ids


def imports_of(name: str, source: str | None = None) -> list[tuple[str, int]]:
    """(imported module, line) for every import in module ``name`` (its file, or ``source``) that targets the package."""
    tree = ast.parse(MODULES[name].read_text() if source is None else source, filename=str(MODULES[name]))
    package = name if is_package(name) else name.rpartition(".")[0]
    skip = _docstring_nodes(tree)   # docstrings and import_module arguments: not registry strings
    found: list[tuple[str, int]] = []

    def add(target: str | None, line: int) -> None:
        if target is not None and target != name:
            found.append((target, line))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(_known(alias.name), node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                add(sub if sub in MODULES else _known(base), node.lineno)
        elif isinstance(node, ast.Call):
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if fname in ("import_module", "__import__") and node.args and isinstance(node.args[0], ast.Constant) \
                    and isinstance(node.args[0].value, str):
                target = node.args[0].value
                skip.add(id(node.args[0]))     # counted here, not again as a registry string
                if target.startswith("."):
                    level = len(target) - len(target.lstrip("."))
                    base_parts = package.split(".")
                    base_parts = base_parts[: len(base_parts) - (level - 1)]
                    target = ".".join(base_parts + ([target.lstrip(".")] if target.lstrip(".") else []))
                add(_known(target), node.lineno)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            if node.value in MODULES and node.value.startswith("unmesh."):
                add(node.value, node.lineno)
    return found


def import_graph() -> dict[str, dict[str, int]]:
    """module -> {imported module: first line}."""
    graph: dict[str, dict[str, int]] = {}
    for name in MODULES:
        edges: dict[str, int] = {}
        for target, line in imports_of(name):
            edges.setdefault(target, line)
        graph[name] = edges
    return graph


def _strongly_connected(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    comps: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    comp.append(member)
                    if member == node:
                        break
                comps.append(sorted(comp))
    return comps


def _shortest_cycle(graph: dict[str, dict[str, int]], start: str, members: set[str]) -> list[str]:
    """Shortest path start -> ... -> start inside one strongly connected component."""
    prev: dict[str, str] = {}
    queue = deque([start])
    seen = {start}
    while queue:
        node = queue.popleft()
        for child in sorted(graph[node]):
            if child not in members:
                continue
            if child == start:
                path = [node]
                while path[-1] != start:
                    path.append(prev[path[-1]])
                return [start, *reversed(path[:-1]), start]
            if child not in seen:
                seen.add(child)
                prev[child] = node
                queue.append(child)
    raise AssertionError(f"{start} is on no cycle")


def upward_imports(graph: dict[str, dict[str, int]]) -> list[str]:
    problems = []
    for name, edges in sorted(graph.items()):
        here, here_name = layer_of(name)
        for target, line in sorted(edges.items()):
            there, there_name = layer_of(target)
            if there > here:
                problems.append(f"{name} ({here_name}) imports {target} (higher layer {there_name}) "
                                f"at {MODULES[name].relative_to(SRC.parent)}:{line}")
    return problems


def import_cycles(graph: dict[str, dict[str, int]]) -> list[str]:
    problems = []
    for comp in _strongly_connected(graph):
        if len(comp) < 2:
            continue
        members = set(comp)
        covered: set[str] = set()
        for a in comp:
            for b in comp:
                if a < b and b in graph[a] and a in graph[b]:
                    problems.append(f"{a} ↔ {b} ({MODULES[a].relative_to(SRC.parent)}:{graph[a][b]}, "
                                    f"{MODULES[b].relative_to(SRC.parent)}:{graph[b][a]})")
                    covered |= {a, b}
        for a in comp:
            if a not in covered:
                cycle = _shortest_cycle(graph, a, members)
                problems.append("cycle: " + " → ".join(cycle))
                covered |= set(cycle)
    return problems


def test_every_module_has_a_layer():
    missing = []
    for name in MODULES:
        try:
            layer_of(name)
        except LookupError as exc:
            missing.append(str(exc))
    assert not missing, "\n".join(missing)


def test_no_upward_imports():
    problems = upward_imports(import_graph())
    assert not problems, "upward imports:\n" + "\n".join(problems)


def test_no_import_cycles():
    problems = import_cycles(import_graph())
    assert not problems, "import cycles:\n" + "\n".join(problems)


def test_checker_sees_lazy_relative_and_dynamic_imports():
    # The checker itself, on modules it must read correctly: the CLI's registry strings,
    # the gallery's example registry, and a lazy import inside a function.
    graph = import_graph()
    assert "unmesh.gallery.cli" in graph["unmesh.cli"]          # COMMAND_MODULES string
    assert "unmesh.gallery.examples.render" in graph["unmesh.gallery"]  # EXAMPLE_MODULES string
    assert "unmesh.sim.cli" in graph["unmesh.gallery.registry"]  # lazy, inside ExampleContext.run_scene
    assert "unmesh.scenes" in graph["unmesh.gallery.registry"]   # `from unmesh import scenes`: the submodule


def test_checker_resolves_relative_lazy_and_string_imports():
    source = (
        "from . import energy\n"                     # sibling submodule
        "from .topology import ShellTopology\n"      # name from a sibling
        "from .. import errors\n"                    # parent package's submodule
        "from . import FiberState\n"                 # a name of the package __init__
        "def f():\n"
        "    import importlib\n"
        "    from unmesh.render.camera import Camera\n"
        "    importlib.import_module('unmesh.sph.cli')\n"
        "    return ('unmesh.fem.cli', 'not unmesh.io')\n"
    )
    found = [target for target, _ in imports_of("unmesh.shells.forces", source)]
    assert found == ["unmesh.shells.energy", "unmesh.shells.topology", "unmesh.errors", "unmesh.shells",
                     "unmesh.render.camera", "unmesh.sph.cli", "unmesh.fem.cli"]
    assert [t for t, _ in imports_of("unmesh.shells", "from . import forces\nfrom .forces import x\n")] == \
        ["unmesh.shells.forces", "unmesh.shells.forces"]


def test_checker_reports_upward_imports_and_cycles_by_name():
    fake = {"unmesh.errors": {"unmesh.render.camera": 3}, "unmesh.render.camera": {"unmesh.errors": 1},
            "unmesh.shells.a": {"unmesh.shells.b": 1}, "unmesh.shells.b": {"unmesh.shells.c": 1},
            "unmesh.shells.c": {"unmesh.shells.a": 1}}
    for name in fake:
        MODULES.setdefault(name, SRC / "unmesh" / (name.split(".", 1)[1].replace(".", "/") + ".py"))
    try:
        up = upward_imports(fake)
        assert len(up) == 1 and up[0].startswith("unmesh.errors (base) imports unmesh.render.camera (higher layer engines)")
        cycles = import_cycles(fake)
        assert cycles[0].startswith("unmesh.errors ↔ unmesh.render.camera")
        assert "cycle: unmesh.shells.a → unmesh.shells.b → unmesh.shells.c → unmesh.shells.a" in cycles
    finally:
        for name in ("unmesh.shells.a", "unmesh.shells.b", "unmesh.shells.c"):
            MODULES.pop(name, None)
