"""robots remember the token that registered them

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 19:30:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('robots') as batch:
        batch.add_column(sa.Column('token_id', sa.Integer(), nullable=True))
        batch.create_foreign_key('fk_robots_token_id', 'tokens', ['token_id'], ['id'], ondelete='SET NULL')


def downgrade() -> None:
    with op.batch_alter_table('robots') as batch:
        batch.drop_constraint('fk_robots_token_id', type_='foreignkey')
        batch.drop_column('token_id')
