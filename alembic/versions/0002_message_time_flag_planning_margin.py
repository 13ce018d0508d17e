"""message time flag, planning margin

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-21 08:49:04.360490
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('experiments', schema=None) as batch_op:
        batch_op.add_column(sa.Column('planning_margin', sa.Float(), server_default='0', nullable=False))

    with op.batch_alter_table('messages', schema=None) as batch_op:
        batch_op.add_column(sa.Column('t_estimated', sa.Boolean(), server_default='0', nullable=False))



def downgrade() -> None:
    with op.batch_alter_table('messages', schema=None) as batch_op:
        batch_op.drop_column('t_estimated')

    with op.batch_alter_table('experiments', schema=None) as batch_op:
        batch_op.drop_column('planning_margin')

