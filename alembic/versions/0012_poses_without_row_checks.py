"""poses without a foreign-key check per row: a trigger deletes a run's poses with it instead

PostgreSQL checks a foreign key with one locking lookup of the run per inserted pose: 1.8 of the 3.0 ms
of the database's CPU that storing a run's ~550 poses by COPY cost (measured).  Poses are only written by
the testbed for a run it holds (with the run's end, or through an open tracker window), so the check never
caught anything; what the key also did, deleting a run's poses with the run, is kept by a trigger.

Revision ID: 0012
Revises: 0011
Create Date: 2026-11-24 00:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0012'
down_revision = '0011'
branch_labels = None
depends_on = None

#: the name batch mode gives SQLite's unnamed key, to drop and make it
_SQLITE_FK = {"fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s"}


def upgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "sqlite":
        with op.batch_alter_table('poses', naming_convention=_SQLITE_FK) as batch:
            batch.drop_constraint('fk_poses_run_id_runs', type_='foreignkey')
        op.execute("CREATE TRIGGER runs_delete_poses AFTER DELETE ON runs "
                   "BEGIN DELETE FROM poses WHERE run_id = OLD.id; END")
    else:
        for fk in sa.inspect(bind).get_foreign_keys('poses'):
            op.drop_constraint(fk['name'], 'poses', type_='foreignkey')
        op.execute("CREATE FUNCTION runs_delete_poses() RETURNS trigger LANGUAGE plpgsql AS "
                   "$$ BEGIN DELETE FROM poses WHERE run_id = OLD.id; RETURN OLD; END $$")
        op.execute("CREATE TRIGGER runs_delete_poses AFTER DELETE ON runs FOR EACH ROW "
                   "EXECUTE FUNCTION runs_delete_poses()")


def downgrade() -> None:
    sqlite = op.get_bind().dialect.name == "sqlite"
    op.execute("DELETE FROM poses WHERE run_id NOT IN (SELECT id FROM runs)")  # the key would refuse them
    op.execute("DROP TRIGGER runs_delete_poses" + ("" if sqlite else " ON runs"))
    if sqlite:
        with op.batch_alter_table('poses', naming_convention=_SQLITE_FK) as batch:
            batch.create_foreign_key('fk_poses_run_id_runs', 'runs', ['run_id'], ['id'], ondelete='CASCADE')
    else:
        op.execute("DROP FUNCTION runs_delete_poses()")
        op.create_foreign_key('poses_run_id_fkey', 'poses', 'runs', ['run_id'], ['id'], ondelete='CASCADE')
