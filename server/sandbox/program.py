"""An uploaded program as the sandbox runs it: its spec, files, environment and command line."""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from typing import Any, Optional

__all__ = ["ENV_FILE", "PATH_FILE", "PROGRAM_FILE", "ProgramSpec", "program_argv", "program_env", "program_files"]

#: file names of the program in its working directory
PROGRAM_FILE = {"python": "program.py", "executable": "program"}
ENV_FILE = "environment.json"
#: a controller program's planned path: ``{"path": [[x, y, theta], ...]}`` (m, m, rad)
PATH_FILE = "path.json"


@dataclass(frozen=True)
class ProgramSpec:
    """An uploaded program, as stored."""

    id: int
    name: str
    kind: str  # "python" | "executable"
    interpreter: Optional[str]
    args: list[str]
    content: bytes


def program_argv(spec: ProgramSpec, interpreters: dict[str, str]) -> list[str]:
    """The command line (the launcher replaces ``{workdir}``, ``{robot_port}``, ...); ValueError if it cannot run."""
    path = "{workdir}/" + PROGRAM_FILE[spec.kind]
    interp = "python3" if spec.kind == "python" else spec.interpreter
    if interp is None:
        return [path, *spec.args]
    if interp not in interpreters:
        raise ValueError(f"interpreter {interp!r} is not available on this testbed "
                         f"(available: {', '.join(sorted(interpreters)) or 'none'})")
    return [interpreters[interp], path, *spec.args]


def program_files(spec: ProgramSpec, env_data: dict[str, Any],
                  path: Optional[list[list[float]]] = None) -> dict[str, dict[str, Any]]:
    """The working directory's files for the job: name -> ``{"base64", "mode"}``; with a controller's
    planned ``path`` (m, m, rad) also :data:`PATH_FILE`."""
    runnable = spec.kind == "executable" and spec.interpreter is None
    files = {
        PROGRAM_FILE[spec.kind]: {"base64": base64.b64encode(spec.content).decode(),
                                  "mode": 0o500 if runnable else 0o400},
        ENV_FILE: {"base64": base64.b64encode(json.dumps(env_data).encode()).decode(), "mode": 0o400},
    }
    if path is not None:
        files[PATH_FILE] = {"base64": base64.b64encode(json.dumps({"path": path}).encode()).decode(), "mode": 0o400}
    return files


def program_env(*, start: list[float], goal: list[float], field_size: tuple[float, float], seed: int,
                robot_radius: float, planning_margin: float, robot_id: str, wall_s: float,
                path: Optional[list[list[float]]] = None,
                fleet: Optional[list[tuple[list[float], list[float]]]] = None) -> dict[str, str]:
    """The program's environment (lengths in m, angles in rad, ``wall_s`` in s); the launcher adds the rest.

    A controller program (``path`` given) also gets ``TWB_PATH_FILE`` and ``TWB_PATH_POINTS``; a
    multi-robot job's program (``fleet``: each robot's (start, goal), robot 0 being ``start``/``goal``)
    ``TWB_ROBOTS`` (their number) and ``TWB_STARTS`` / ``TWB_GOALS`` (``x,y,theta;x,y,theta;...``).
    """
    extra = {} if path is None else {"TWB_PATH_FILE": PATH_FILE, "TWB_PATH_POINTS": str(len(path)),
                                     "TWB_ROLE": "controller"}
    if fleet is not None:
        extra = {"TWB_ROBOTS": str(len(fleet)),
                 "TWB_STARTS": ";".join(",".join(map(_num, s)) for s, _ in fleet),
                 "TWB_GOALS": ";".join(",".join(map(_num, g)) for _, g in fleet)}
    return {**extra,
        "PATH": "/usr/local/bin:/usr/bin:/bin", "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8",
        "PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1",
        "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
        "TWB_ENV_FILE": ENV_FILE,
        "TWB_START": ",".join(map(_num, start)), "TWB_GOAL": ",".join(map(_num, goal)),
        "TWB_SEED": str(seed), "TWB_ROBOT_RADIUS": _num(robot_radius),
        "TWB_PLANNING_MARGIN": _num(planning_margin), "TWB_FIELD_SIZE": ",".join(map(_num, field_size)),
        "TWB_ROBOT_ID": robot_id, "TWB_TIME_LIMIT_S": _num(wall_s),
    }


def _num(v: float) -> str:
    return f"{v:.9g}"
