"""The server's import graph: no cycles, and each layer imports only the layers below it.

Every import counts, also those inside functions and under ``TYPE_CHECKING``:
a cycle hidden behind either is still a cycle to a reader.  Strongly
connected components come from SciPy's graph routines.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
SERVER = ROOT / "server"


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path, modules: set[str]) -> set[str]:
    """The ``server`` modules ``path`` imports (a package import counts as its ``__init__``)."""
    me = _module(path)
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name and name != me:
                out.add(name)
    return out


def server_graph() -> dict[str, set[str]]:
    files = [p for p in SERVER.rglob("*.py") if "static" not in p.parts]
    modules = {_module(p) for p in files}
    return {_module(p): _imports(p, modules) for p in files}


def test_server_has_no_import_cycles():
    graph = server_graph()
    names = sorted(graph)
    index = {n: i for i, n in enumerate(names)}
    rows, cols = zip(*[(index[a], index[b]) for a, deps in graph.items() for b in deps])
    adjacency = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(adjacency, directed=True, connection="strong")
    cycles = [sorted(n for n in names if labels[index[n]] == c) for c in set(labels)]
    assert [c for c in cycles if len(c) > 1] == []


def test_each_layer_imports_only_what_is_below_it():
    graph = server_graph()
    rules = {  # modules (prefixes) -> what they must not import
        "server.store": ("server.api", "server.pipeline", "server.dispatch", "server.testbed", "server.field",
                         "server.app"),
        "server.pipeline": ("server.api", "server.dispatch", "server.testbed", "server.app", "server.embedded"),
        "server.dispatch": ("server.api", "server.testbed", "server.app"),
        "server.field": ("server.api", "server.pipeline", "server.dispatch", "server.testbed"),
        "server.core": ("server.api", "server.store", "server.pipeline", "server.models", "server.testbed"),
        "server.sandbox": ("server.api", "server.store", "server.pipeline", "server.models", "server.testbed"),
    }
    wrong = [(m, d) for m, deps in graph.items() for prefix, banned in rules.items() if m.startswith(prefix)
             for d in deps if d.startswith(banned)]
    assert wrong == []
    routes = {m for m in graph if m.startswith("server.api.routes.")}
    assert [(m, d) for m in routes for d in graph[m] if d in routes] == []  # routes never import each other


def test_the_server_imports_no_simulation_core():
    """numba and the agent's simulation load only where robots run (``twb up``'s embedded field)."""
    code = ("import sys, server.app, server.testbed, server.dispatch; "
            "print(sorted(m for m in ('numba', 'robot_agent.sim', 'robot_agent.host') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"
