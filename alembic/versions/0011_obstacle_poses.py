"""obstacle tracks: a field run's obstacle robots' tracker poses, stored with its poses

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-24 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0011'
down_revision = '0010'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('poses') as batch:
        batch.add_column(sa.Column('obstacle', sa.Integer(), nullable=True))


def downgrade() -> None:
    op.execute("DELETE FROM poses WHERE obstacle IS NOT NULL")  # they would read as the run's robot's poses
    with op.batch_alter_table('poses') as batch:
        batch.drop_column('obstacle')
