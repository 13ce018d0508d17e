"""why a run failed and where it stopped; start-pose jitter of experiments

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23 21:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0005'
down_revision = '0004'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.add_column(sa.Column('failure', sa.String(length=24), nullable=True))
        batch.add_column(sa.Column('stopped_at', sa.JSON(), nullable=True))
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('jitter', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.drop_column('jitter')
    with op.batch_alter_table('runs') as batch:
        batch.drop_column('stopped_at')
        batch.drop_column('failure')
