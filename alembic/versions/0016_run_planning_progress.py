"""each run's planning progress: an anytime planner's best path length so far against its planning time
(``[[t_s, length_m], ...]``, OMPL's progress properties), of the run's own repetition

Older runs keep NULL: only their experiment's first repetition's progress was kept (in its planning_info).

Revision ID: 0016
Revises: 0015
Create Date: 2026-11-28 02:00:00
"""
from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = '0016'
down_revision = '0015'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.add_column(sa.Column('planning_progress', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.drop_column('planning_progress')
