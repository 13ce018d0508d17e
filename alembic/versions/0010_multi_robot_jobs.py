"""multi-robot jobs: an experiment's robots, the fleet member of each logged pose

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-26 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0010'
down_revision = '0009'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('robots', sa.JSON(), nullable=True))
    with op.batch_alter_table('poses') as batch:
        batch.add_column(sa.Column('robot', sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('poses') as batch:
        batch.drop_column('robot')
    with op.batch_alter_table('experiments') as batch:
        batch.drop_column('robots')
