"""The package layout shows the architecture (docs/architecture.md, "Package layout"):
the root of ``openfdk`` holds only ``__init__`` (and ``__main__``) and subpackages, and
the import graph has no cycles.

The graph is read from the source with ``ast``: a node per module, an edge for every
``import``/``from … import`` of an openfdk module anywhere in the file (top level or inside
a function, where imports are deferred to keep start-up light), the strongly connected
components by Tarjan's algorithm. At the top level there must be none; with the deferred
imports counted too, none but :data:`KNOWN_CYCLES` (each is work in progress of another
part of the code, listed so that no new cycle can join them unnoticed)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "openfdk"

#: cycles through deferred imports that remain, each a set of modules: a component of
#: the graph may be one of these or part of one, nothing else
KNOWN_CYCLES = [
    {"forces.curve_muscle", "forces.hill", "forces.millard"},
    {"fdk.settings", "model.builder", "model.coordinate_joint", "model.coordinates_section", "model.modelfile",
     "model.settings"},
    {"io.opensim.actuators", "io.opensim.contact", "io.opensim.document", "io.opensim.passive_forces",
     "io.opensim.to_model", "io.opensim.tree"},
    {"contact.mesh_cache", "contact.sections", "io.fingerprint", "io.modelfile", "io.opensim.overlay"},
    {"analysis.inverse_dynamics", "analysis.jobs", "analysis.run", "analysis.tree_trial", "fdk.analysis",
     "kinematics.analysis", "study.chunks", "trial", "trial.checkpoint", "trial.checkpoint_format", "trial.driver"},
    {"fixtures.full_body_muscles", "fixtures.full_body_osim"},
    {"bench.fuzz_inputs", "bench.fuzz_kinds"},
]


def modules():
    """{dotted name: (path, is package)} of every module of the package."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def import_graph(top_level_only=False):
    """{module: set of openfdk modules it imports} (names without the ``openfdk.`` prefix)."""
    mods = modules()

    def resolve(name):  # the module a dotted name refers to (a name imported from it -> it)
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, (path, is_package) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        package = name if is_package else name.rpartition(".")[0]
        nodes = tree.body if top_level_only else ast.walk(tree)
        targets = set()
        for node in nodes:
            if isinstance(node, ast.Import):
                targets |= {resolve(a.name) for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    origin = ".".join(base + ([node.module] if node.module else []))
                else:
                    origin = node.module or ""
                for a in node.names:
                    sub = f"{origin}.{a.name}"
                    targets.add(sub if sub in mods else resolve(origin))
        graph[name] = {t for t in targets if t and t.startswith("openfdk") and t != name}
    short = lambda m: m.removeprefix("openfdk.")  # noqa: E731
    return {short(m): {short(t) for t in ts} for m, ts in graph.items()}


def cycles(graph):
    """The strongly connected components of more than one module (Tarjan)."""
    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))
    index, low, on_stack, stack, found = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"d"}}
    assert cycles(graph) == [{"a", "b", "c"}]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_at_the_top_level_of_modules():
    assert cycles(import_graph(top_level_only=True)) == []


def test_no_import_cycle_but_the_known_ones():
    graph = import_graph()
    assert "results.run" in graph["plots.run"] and "results.columns" in graph["viewer.results"]  # edges are read
    new = [sorted(c) for c in cycles(graph) if not any(c <= known for known in KNOWN_CYCLES)]
    assert new == []
    # the cycles issue 29 named are gone
    for a, b in (("plots.run", "results.run"), ("study.case", "study.summary"), ("model.modelfile", "model.visuals"),
                 ("cli.commands", "cli.outputs"), ("results.run", "viewer")):
        assert not any({a, b} <= c for c in cycles(graph)), (a, b)


def test_the_package_root_holds_only_init_and_subpackages():
    loose = sorted(p.name for p in PACKAGE.iterdir()
                   if p.suffix == ".py" and p.name not in ("__init__.py", "__main__.py"))
    assert loose == []
    for d in (p for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"):
        # a subpackage, or package data without Python (data/)
        assert (d / "__init__.py").is_file() or not list(d.rglob("*.py")), d.name


def test_the_public_api_is_unchanged():
    import openfdk
    from openfdk.api import Result
    from openfdk.cli import main
    from openfdk.results.run import RunResults

    assert callable(openfdk.run) and callable(openfdk.read_results) and callable(openfdk.load_model)
    assert callable(main) and issubclass(Result, RunResults)
    assert hasattr(Result, "plot") and hasattr(Result, "view") and not hasattr(RunResults, "plot")
