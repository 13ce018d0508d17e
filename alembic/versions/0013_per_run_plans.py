"""per-run plans: each run's planner seed, planned path and planning time (wall, CPU, repeats, load);
an experiment's planner seed and whether its planner is randomised; a program's declaration of it

Old runs get NULL (their experiment's plan was the one they drove: it stays on the experiment), old
experiments and programs are deterministic.

Revision ID: 0013
Revises: 0012
Create Date: 2026-11-24 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0013'
down_revision = '0012'
branch_labels = None
depends_on = None

_RUN_COLUMNS = ('planner_seed', 'planned_path', 'planning_time_s', 'planning_cpu_s', 'planning_repeats',
                'planning_load')


def upgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.add_column(sa.Column('planner_seed', sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column('planned_path', sa.JSON(), nullable=True))
        batch.add_column(sa.Column('planning_time_s', sa.Float(), nullable=True))
        batch.add_column(sa.Column('planning_cpu_s', sa.Float(), nullable=True))
        batch.add_column(sa.Column('planning_repeats', sa.Integer(), nullable=True))
        batch.add_column(sa.Column('planning_load', sa.Float(), nullable=True))
    with op.batch_alter_table('experiments') as batch:
        batch.add_column(sa.Column('planner_seed', sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column('planner_stochastic', sa.Boolean(), server_default='0', nullable=False))
    with op.batch_alter_table('programs') as batch:
        batch.add_column(sa.Column('stochastic', sa.Boolean(), server_default='0', nullable=False))


def downgrade() -> None:
    with op.batch_alter_table('programs') as batch:
        batch.drop_column('stochastic')
    with op.batch_alter_table('experiments') as batch:
        batch.drop_column('planner_stochastic')
        batch.drop_column('planner_seed')
    with op.batch_alter_table('runs') as batch:
        for name in reversed(_RUN_COLUMNS):
            batch.drop_column(name)
