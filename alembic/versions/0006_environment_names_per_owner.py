"""environment names are unique per owner (built-in names are reserved), not across users

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-23 22:00:00
"""
from __future__ import annotations

from alembic import op


revision = '0006'
down_revision = '0005'
branch_labels = None
depends_on = None

#: how SQLite's reflection names the unnamed unique constraint of 0001, so batch mode can drop it
_NAMES = {"uq": "uq_%(table_name)s_%(column_0_name)s"}


def upgrade() -> None:
    if op.get_bind().dialect.name == "postgresql":
        op.drop_constraint('environments_name_key', 'environments', type_='unique')
        op.create_unique_constraint('uq_environments_owner_name', 'environments', ['owner_id', 'name'])
        return
    with op.batch_alter_table('environments', naming_convention=_NAMES) as batch:
        batch.drop_constraint('uq_environments_name', type_='unique')
        batch.create_unique_constraint('uq_environments_owner_name', ['owner_id', 'name'])


def downgrade() -> None:
    with op.batch_alter_table('environments', naming_convention=_NAMES) as batch:
        batch.drop_constraint('uq_environments_owner_name', type_='unique')
        batch.create_unique_constraint('uq_environments_name', ['name'])
