"""an experiment's configuration label and problem name (what GET /api/v1/comparisons groups runs by)

Old experiments get the names a job gets by default (planners.compared.job_configuration and
problem_label), as far as their rows tell: the planner (or ``program #id``, ``explicit path``) without its
parameters — the row keeps them with the defaults filled in, so which were given is not known —, the
controller when it is not ``schema``, the profile overrides; ``<environment> <plan>`` when the start and
goal are a plan of the environment, else the start and goal rounded to cm, ``<environment> <n> robots``
for a multi-robot job.  The derivation is written out here, as of this revision, so the migration never
changes with the code.

Independent of revision 0013's columns (per-run plans).

Revision ID: 0014
Revises: 0013
Create Date: 2026-11-27 00:00:00
"""
from __future__ import annotations

import json
import math
from typing import Any, Optional

import sqlalchemy as sa
from alembic import op


revision = '0014'
down_revision = '0013'
branch_labels = None
depends_on = None

_LABEL, _PROBLEM = 64, 100


def _json(v: Any) -> Any:
    return json.loads(v) if isinstance(v, str) else v


def _short(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _label(planner: Optional[str], program: Optional[int], controller: Optional[str],
           controller_program: Optional[int], overrides: Any) -> str:
    name = planner or (f"program #{program}" if program is not None else "explicit path")
    if controller_program is not None:
        name += f"/controller program #{controller_program}"
    elif controller and controller != "schema":
        name += f"/{controller}"
    overrides = _json(overrides)
    if overrides:
        name += " · " + ",".join(f"{k}={v:g}" for k, v in sorted(overrides.items()))
    return _short(name, _LABEL)


def _same(a: Any, b: Any) -> bool:
    if not a or not b or len(a) < 2 or len(b) < 2 or any(abs(float(p) - float(q)) > 1e-6 for p, q in zip(a, b[:2])):
        return False
    ta = float(a[2]) if len(a) > 2 and a[2] is not None else None
    tb = float(b[2]) if len(b) > 2 and b[2] is not None else None
    if ta is None or tb is None:
        return ta is None and tb is None
    return abs(math.remainder(ta - tb, 2 * math.pi)) <= 1e-6


def _problem(environment: str, env_data: Any, start: Any, goal: Any, robots: Any) -> str:
    robots, start, goal = _json(robots), _json(start), _json(goal)
    if robots:
        return _short(f"{environment} {len(robots)} robots", _PROBLEM)
    for p in (_json(env_data) or {}).get("plans") or []:
        if _same(start, p.get("start")) and _same(goal, p.get("goal")):
            return _short(f"{environment} {p.get('name')}", _PROBLEM)
    if not start or not goal:
        return _short(environment, _PROBLEM)
    return _short(f"{environment} ({float(start[0]):.2f},{float(start[1]):.2f})→"
                  f"({float(goal[0]):.2f},{float(goal[1]):.2f})", _PROBLEM)


def upgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('label', sa.String(length=64), nullable=True))
        batch.add_column(sa.Column('problem', sa.String(length=100), nullable=True))
    bind = op.get_bind()
    rows = bind.execute(sa.text(
        "SELECT id, planner, program_id, controller, controller_program_id, profile_overrides, environment, "
        "environment_data, start, goal, robots FROM experiments")).all()
    names = [{"id": r.id, "label": _label(r.planner, r.program_id, r.controller, r.controller_program_id,
                                          r.profile_overrides),
              "problem": _problem(r.environment, r.environment_data, r.start, r.goal, r.robots)} for r in rows]
    if names:
        bind.execute(sa.text("UPDATE experiments SET label = :label, problem = :problem WHERE id = :id"), names)


def downgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.drop_column('problem')
        batch.drop_column('label')
