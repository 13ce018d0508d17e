"""The repository's import graph: no cycles anywhere, and each layer imports only the layers below it.

Every import counts, also those inside functions and under ``TYPE_CHECKING``:
a cycle hidden behind either is still a cycle to a reader.  Strongly
connected components come from SciPy's graph routines.  The layers
(docs/design.md, "Layers"), bottom up::

    contract  ->  planners  ->  robot_agent.engine  ->  robot_agent.host, robot_agent.gym, server, client_sdk  ->  twb, bench
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("contract", "planners", "robot_agent", "server", "client_sdk", "twb", "bench")

#: what each layer may import of the project besides itself (a layer is a package, or a sub-package of the agent)
LAYERS: dict[str, set[str]] = {
    "contract": set(),
    "planners": {"contract"},
    "robot_agent": set(),  # the package's own __init__
    "robot_agent.engine": {"contract", "planners"},
    "robot_agent.host": {"contract", "planners", "robot_agent.engine"},
    "robot_agent.gym": {"contract", "planners", "robot_agent.engine"},  # Gymnasium environments on the engine
    "client_sdk": {"contract", "planners"},  # users install the SDK without the server or the agent
    "server": {"contract", "planners", "robot_agent.engine", "robot_agent.host"},
    "twb": {"contract", "planners", "robot_agent.engine", "robot_agent.host", "robot_agent.gym", "server",
            "client_sdk"},
    "bench": {"contract", "planners", "robot_agent.engine", "robot_agent.host", "robot_agent.gym", "server",
              "client_sdk", "twb"},
}


def _module(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(root: Path, path: Path, modules: set[str]) -> set[str]:
    """The project modules ``path`` imports (a package import counts as its ``__init__``)."""
    me = _module(root, path)
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


def import_graph(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Module -> the project modules it imports, over every ``.py`` file of ``packages`` under ``root``."""
    files = [p for pkg in packages for p in (root / pkg).rglob("*.py") if "static" not in p.parts]
    modules = {_module(root, p) for p in files}
    return {_module(root, p): _imports(root, p, modules) for p in files}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles of ``graph``: its strongly connected components of more than one module."""
    names = sorted(graph)
    index = {n: i for i, n in enumerate(names)}
    pairs = [(index[a], index[b]) for a, deps in graph.items() for b in deps]
    if not pairs:
        return []
    rows, cols = zip(*pairs)
    adjacency = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(adjacency, directed=True, connection="strong")
    found = [sorted(n for n in names if labels[index[n]] == c) for c in set(labels)]
    return sorted(c for c in found if len(c) > 1)


def layer_of(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "robot_agent" and len(parts) > 1 else parts[0]


def layer_breaches(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Imports of a layer that :data:`LAYERS` does not allow it."""
    return sorted((m, d) for m, deps in graph.items() for d in deps
                  if layer_of(d) != layer_of(m) and layer_of(d) not in LAYERS[layer_of(m)])


def test_the_repository_has_no_import_cycles():
    assert cycles(import_graph()) == []


def test_the_check_finds_a_cycle_added_on_purpose(tmp_path):
    """The same check on a copy of two real modules with one import added that closes a cycle: found."""
    for pkg in ("contract", "robot_agent/engine"):
        (tmp_path / pkg).mkdir(parents=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "robot_agent" / "__init__.py").write_text("")
    (tmp_path / "contract" / "frames.py").write_text((ROOT / "contract" / "frames.py").read_text())
    noise = (ROOT / "robot_agent" / "engine" / "noise.py").read_text()
    (tmp_path / "robot_agent" / "engine" / "noise.py").write_text(noise + "\nfrom contract import frames\n")
    (tmp_path / "robot_agent" / "engine" / "compiled.py").write_text("")
    graph = import_graph(tmp_path, ("contract", "robot_agent"))
    assert cycles(graph) == []
    # the deliberate cycle: the contract reaching up into the engine, inside a function, as hidden as it gets
    (tmp_path / "contract" / "frames.py").write_text((ROOT / "contract" / "frames.py").read_text()
                                                     + "\ndef _late():\n    from robot_agent.engine import noise\n")
    graph = import_graph(tmp_path, ("contract", "robot_agent"))
    assert cycles(graph) == [["contract.frames", "robot_agent.engine.noise"]]
    assert layer_breaches(graph) == [("contract.frames", "robot_agent.engine"),  # the package's __init__ too
                                     ("contract.frames", "robot_agent.engine.noise")]


@pytest.mark.slow
def test_each_layer_imports_only_the_layers_below_it():
    graph = import_graph()
    assert {layer_of(m) for m in graph} <= set(LAYERS)
    assert layer_breaches(graph) == []


def test_inside_the_server_each_layer_imports_only_what_is_below_it():
    graph = {m: deps for m, deps in import_graph().items() if m.startswith("server")}
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


@pytest.mark.slow
def test_the_server_imports_no_simulation_core():
    """numba and the agent's simulation load only where robots run (``twb up``'s embedded field, the workers)."""
    code = ("import sys, server.app, server.testbed, server.dispatch; "
            "print(sorted(m for m in sys.modules if m == 'numba' or m.startswith(('robot_agent.host', "
            "'robot_agent.engine.')) and m not in ('robot_agent.engine.run_data', 'robot_agent.engine.tasks')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


@pytest.mark.slow
def test_the_sdk_imports_neither_the_server_nor_the_agent():
    """Users install the SDK alone: importing it (studies included) loads only the contract and the planners."""
    code = ("import sys, client_sdk, client_sdk.study; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'server', 'robot_agent', 'twb', 'numba'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def _string_sets(text: str, suffix: str) -> list[set[str]]:
    """The collections of string literals written in ``text`` (Python: tuples, lists, sets; JavaScript: arrays)."""
    import re

    if suffix == ".py":
        found = []
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                found.append({e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)})
        return found
    return [set(re.findall(r"""["']([a-z_]+)["']""", m)) for m in re.findall(r"\[([^\[\]]*)\]", text)]


@pytest.mark.slow
def test_the_run_vocabulary_is_written_once():
    """No module but contract/vocabulary.py spells out the terminal statuses or the modes as a collection: the
    server, the SDK, the study tooling, the tests and the dashboard (from GET /api/v1/meta) take them from it."""
    from contract.vocabulary import TERMINAL

    terminal = {str(s) for s in TERMINAL}
    copies = []
    files = [p for pkg in (*PACKAGES, "tests") for p in (ROOT / pkg).rglob("*.py")]
    files += list((ROOT / "server" / "static" / "js").glob("*.js"))
    for path in files:
        if path == ROOT / "contract" / "vocabulary.py" or "migrations" in path.parts:
            continue
        for strings in _string_sets(path.read_text(), path.suffix):
            if len(strings & terminal) >= 3:
                copies.append(f"{path.relative_to(ROOT)}: {sorted(strings)}")
    assert copies == []
