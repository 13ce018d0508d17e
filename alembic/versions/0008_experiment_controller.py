"""the robots' path-tracking controller of an experiment and its parameters

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-24 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0008'
down_revision = '0007'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('controller', sa.String(length=64), nullable=False, server_default='schema'))
        batch.add_column(sa.Column('controller_params', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.drop_column('controller_params')
        batch.drop_column('controller')
