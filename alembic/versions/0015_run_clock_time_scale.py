"""each run's clock mode and time scale: how its robot's clock treated a closed-loop controller
(``lockstep`` or ``free``) and the experiment seconds per wall second it ran at (NULL: as fast as possible)

Older runs keep NULL in both: they ran before the testbed recorded them (free-running, at a time scale
nobody wrote down).

Revision ID: 0015
Revises: 0014
Create Date: 2026-11-27 20:00:00
"""
from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = '0015'
down_revision = '0014'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.add_column(sa.Column('clock', sa.String(length=8), nullable=True))
        batch.add_column(sa.Column('time_scale', sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.drop_column('time_scale')
        batch.drop_column('clock')
