"""Planning an experiment with its uploaded program: run it sandboxed, check what it sent.

Called by :func:`server.runner.plan_experiment` once per experiment (under
the testbed's planning lock).  The program's output and its robot-port
conversation go to the log of the run that executed it; the path it sent
must go from the start to the goal clear of obstacles by the robot radius
(:func:`server.validation.check_program_path`), like an explicit path.
"""

from __future__ import annotations

import asyncio
import math
from typing import TYPE_CHECKING, Any, Callable, Optional

from .models import Experiment, Program
from .sandbox import ProgramSpec
from .validation import FIELD_SIZE, SUBFIELD_SIZE, PreflightError, check_program_path

if TYPE_CHECKING:
    from .testbed import Testbed

__all__ = ["ProgramFailed", "plan_with_program"]

LineLog = Callable[[str, str, Optional[float], bool], None]


class ProgramFailed(Exception):
    """The program gave no usable path; the run (and the experiment's queued runs) end ``failed``.

    ``info`` is what is known about the execution (for ``planning_info``).
    """

    def __init__(self, reason: str, info: Optional[dict[str, Any]] = None) -> None:
        super().__init__(reason)
        self.info = info or {}


async def plan_with_program(testbed: "Testbed", exp: Experiment, *, run_id: Optional[int] = None,
                            robot_id: str = "robot", platform: str = "BeBot",
                            on_line: Optional[LineLog] = None) -> dict[str, Any]:
    """``{"path", "planning_time_s", "info"}`` from the experiment's program; raises :class:`ProgramFailed`."""
    settings = testbed.settings
    if not settings.uploads_enabled:
        raise ProgramFailed("uploads are disabled on this testbed")

    def load() -> Optional[ProgramSpec]:
        with testbed.sessions() as s:
            p = s.get(Program, exp.program_id)
            return None if p is None else ProgramSpec(p.id, p.name, p.kind, p.interpreter, list(p.args or []),
                                                      p.content)

    spec = await asyncio.to_thread(load)
    if spec is None:
        raise ProgramFailed("the experiment's program no longer exists")
    start = list(exp.start)
    if len(start) < 3:  # the heading the gripper places the robot with (runner)
        start.append(math.atan2(exp.goal[1] - start[1], exp.goal[0] - start[0]))
    outcome = await testbed.sandbox.run(
        spec, env_data=exp.environment_data, start=start, goal=list(exp.goal),
        field_size=SUBFIELD_SIZE if exp.field == "sub" else FIELD_SIZE, seed=exp.seed,
        robot_radius=exp.robot_radius, planning_margin=exp.planning_margin, robot_id=robot_id, platform=platform)
    if on_line is not None:
        for direction, line in outcome.log:
            on_line(direction, line, None, False)
    info = {"program": {**outcome.info, "run_id": run_id}}
    if outcome.path is None:
        raise ProgramFailed(outcome.reason or "program sent no path", info)
    try:
        await testbed.in_pool(check_program_path, exp.environment_data, start, list(exp.goal), outcome.path,
                              exp.robot_radius)
    except PreflightError as exc:
        reason = f"program's path is unusable: {exc}"
        if on_line is not None:
            on_line("s", reason, None, False)
        raise ProgramFailed(reason, info) from None
    return {"path": outcome.path, "planning_time_s": outcome.planning_time_s, "info": info}
