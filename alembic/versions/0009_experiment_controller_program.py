"""an uploaded program as an experiment's controller (closed loop over the robot port)

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-25 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0009'
down_revision = '0008'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('controller_program_id', sa.Integer(), nullable=True))
        batch.create_foreign_key('fk_experiments_controller_program_id', 'programs', ['controller_program_id'],
                                 ['id'], ondelete='SET NULL')


def downgrade() -> None:
    with op.batch_alter_table('experiments') as batch:
        batch.drop_constraint('fk_experiments_controller_program_id', type_='foreignkey')
        batch.drop_column('controller_program_id')
