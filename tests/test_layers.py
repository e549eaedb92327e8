"""The layers of etobs, read from the source: no import circle, every import points down.

Every ``import`` and ``from ... import`` statement of every file under ``src/etobs``
counts, wherever it stands: an import inside a function (a lazy import) is a dependency
like any other. One exemption, from the circle check only: imports under ``if
TYPE_CHECKING:`` never run; they are how a module below names, for its annotations, the
type of the object above that passes itself down (the problem to its assembly and calls,
a result to its tables and metrics). They still obey the package layers. Imports by
string (``importlib.import_module``, the spec's ``factory = "module:function"``) are not
seen.

The units of the layer table are the packages (``etobs.hybrid`` and everything in it is
``hybrid``), the top-level modules (``etobs.errors`` is ``errors``) and ``etobs``'s own
``__init__``, the public API (``etobs``).
"""

import ast
import itertools
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
SRC = ROOT / "src"

#: The layer table, top to bottom: a unit imports only units of the layers below its own;
#: units of one layer do not import each other. The design's "Layers" block
#: (../shared/design.md), with the units it does not place (``compile``, ``examples``,
#: the shared modules) where the code has them, and ``runtime`` too: the design puts it
#: just above ``codegen``, the code has it read problems of ``estimation`` and factories of
#: ``examples``; ``codegen`` writes what the runtime's sensor node runs, from its rule specs
#: and packet format, so it sits above ``runtime``. ``report`` does not exist yet.
LAYERS = (
    ("etobs", "__main__"),  # the public API (imported lazily, PEP 562) and `python -m etobs`
    ("cli",),
    ("plot",),
    ("tuning", "codegen"),
    ("experiments", "runtime"),
    ("design", "examples"),
    ("estimation",),
    ("hybrid", "model"),  # hybrid knows nothing of observers; the model nothing of solvers
    ("compile",),
    ("_spec",),  # the shared top-level modules, from here down
    ("_progress", "_validate", "_version", "formulas"),
    ("errors",),
)
#: Units that may import matplotlib (the numerics never do, nor their lazy imports).
PLOTTING = ("plot",)


def _modules() -> dict[str, Path]:
    """Every module of ``src/etobs`` by dotted name (a package by its ``__init__.py``)."""
    out = {}
    for path in sorted((SRC / "etobs").rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _type_checking_nodes(tree: ast.Module) -> set[int]:
    """``id`` of every node under an ``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``)."""
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else getattr(test, "attr", None)
            if name == "TYPE_CHECKING":
                for stmt in node.body:
                    inside.update(id(n) for n in ast.walk(stmt))
    return inside


def _target(name: str) -> str | None:
    """The module of ``etobs`` that importing ``name`` runs (the longest importable prefix)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports(module: str) -> list[tuple[str, int, bool, str]]:
    """Every import of ``module`` into ``etobs``: ``(target module, line, under TYPE_CHECKING, names)``.

    ``from P import x`` imports the module ``P.x`` when there is one, else ``P``. Anything
    else is read from the statement: third-party modules are ``("", line, ..., name)``.
    """
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    typing_only = _type_checking_nodes(tree)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, up level - 1
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, *([base] if base else [])])
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        for name in names:
            target = _target(name) if name.split(".")[0] == "etobs" else None
            out.append((target or "", node.lineno, id(node) in typing_only, name))
    return out


def unit(module: str) -> str:
    """The unit of the layer table that ``module`` belongs to (module docstring)."""
    parts = module.split(".")
    return "etobs" if len(parts) == 1 else parts[1]


def _rank() -> dict[str, int]:
    return {u: i for i, layer in enumerate(LAYERS) for u in layer}


def test_the_layer_table_places_every_package_and_top_level_module_once():
    units = [u for layer in LAYERS for u in layer]
    assert len(units) == len(set(units)), "a unit is in two layers"
    present = {unit(m) for m in MODULES}
    assert set(units) == present, (
        f"not in LAYERS: {sorted(present - set(units))}; in LAYERS but gone: {sorted(set(units) - present)}"
    )


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` (iterative: no recursion limit)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, successors = work[-1]
            for nxt in successors:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    components.append(sorted(component))
    return components


def _shortest_circle(graph: dict[str, set[str]], component: set[str]) -> list[str]:
    """A shortest circle through the members of ``component``: ``[a, b, ..., a]`` (breadth first)."""
    best: list[str] = []
    for start in sorted(component):
        parent: dict[str, str] = {}
        frontier, last = [start], None
        while frontier and last is None:
            following = []
            for node in frontier:
                successors = sorted(graph[node] & component)
                if start in successors:
                    last = node
                    break
                for nxt in successors:
                    if nxt not in parent:
                        parent[nxt] = node
                        following.append(nxt)
            frontier = following
        if last is None:
            continue
        path = [last]
        while path[-1] != start:
            path.append(parent[path[-1]])
        circle = [*reversed(path), start]
        if not best or len(circle) < len(best):
            best = circle
    return best


def test_strongly_connected_components_finds_a_circle_and_only_it():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert sorted(_strongly_connected(graph)) == [["a", "b", "c"], ["d"], ["e"]]
    graph["c"].add("b")
    assert _shortest_circle(graph, {"a", "b", "c"}) == ["b", "c", "b"]


def test_no_import_circle_between_modules():
    graph = {m: set() for m in MODULES}
    lines: dict[tuple[str, str], int] = {}
    for m in MODULES:
        for target, line, typing_only, _ in imports(m):
            if target and target != m and not typing_only:
                graph[m].add(target)
                lines.setdefault((m, target), line)
    circles = [c for c in _strongly_connected(graph) if len(c) > 1]
    shown = []
    for c in circles:
        path = _shortest_circle(graph, set(c))
        steps = " -> ".join(f"{a} (line {lines[a, b]})" for a, b in itertools.pairwise(path))
        shown.append(f"{len(c)} modules, among them {steps} -> {path[-1]}")
    assert not circles, "import circles (lazy imports included):\n" + "\n".join(shown)


def test_every_import_points_down_the_layer_table():
    rank = _rank()
    wrong = []
    for m in MODULES:
        for target, line, _, _ in imports(m):
            if not target:
                continue
            a, b = unit(m), unit(target)
            if a != b and rank[b] <= rank[a]:
                where = "in the same layer as" if rank[b] == rank[a] else "in a layer above"
                wrong.append(f"{m} (line {line}) imports {target}: `{b}` is {where} `{a}`")
    assert not wrong, "imports against the layers (tests/test_layers.py, LAYERS):\n" + "\n".join(wrong)


def test_only_the_plotting_package_imports_matplotlib():
    wrong = [
        f"{m} (line {line}) imports {name}"
        for m in MODULES
        if unit(m) not in PLOTTING
        for target, line, _, name in imports(m)
        if not target and name.split(".")[0] == "matplotlib"
    ]
    assert not wrong, "\n".join(wrong)


def test_importing_the_numerics_loads_no_plotting_cli_or_matplotlib():
    # The static tests above see etobs's own imports; this one sees those of the
    # libraries it imports too (python-control, say, would load matplotlib).
    code = (
        "import sys, etobs, etobs.hybrid, etobs.estimation, etobs.model, etobs.examples;"
        "print(sorted(m for m in sys.modules if m.startswith(('etobs.plot', 'etobs.cli', 'matplotlib'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _readme_layers() -> str:
    """The "Layers" list item of docs/development.md (the README's front page links it), its lines joined."""
    text = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    found = re.search(r"^- Layers\b.*?(?=^\s*$|^- )", text, flags=re.MULTILINE | re.DOTALL)
    assert found, 'docs/development.md has no "- Layers" line'
    return " ".join(found.group(0).split())


def test_the_readme_layer_line_names_every_unit_in_the_table_order():
    named = [w for w in re.findall(r"`([^`]+)`", _readme_layers()) if w in _rank()]
    assert named == [u for layer in LAYERS for u in layer], (
        f"docs/development.md's Layers line names {named}; LAYERS (tests/test_layers.py) has "
        f"{[list(layer) for layer in LAYERS]}"
    )


@pytest.mark.parametrize("layer", LAYERS, ids=lambda layer: "+".join(layer))
def test_the_readme_layer_line_keeps_each_layer_together(layer):
    # siblings are written "`a`, `b`" between arrows: the arrows split the line into layers
    text = _readme_layers()
    groups = [set(re.findall(r"`([^`]+)`", part)) & set(_rank()) for part in text.split("→")]
    assert set(layer) in [g for g in groups if g], f"{layer} is not one group between arrows in: {text}"
