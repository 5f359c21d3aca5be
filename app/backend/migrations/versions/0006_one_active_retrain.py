"""at most one retrain queued or running per site: a partial unique index on jobs(site_id)

The auto-retrain check ("no retrain of the site queued or running, enough new corrections") and the insert of
the job are then safe across server processes: the database refuses a second active retrain of a site. Any
active retrain left by an older server beyond the first per site is marked failed first (it could not be told
apart from an interrupted one; at start-up the runner marks those failed anyway).

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-24 00:45:00.000000
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

INDEX = "uq_jobs_one_active_retrain"
ACTIVE_RETRAIN = sa.text("kind = 'retrain' AND state IN ('queued', 'running')")


def upgrade() -> None:
    """Apply this revision: fail duplicate active retrains, then add the index."""
    op.execute(
        "UPDATE jobs SET state = 'failed', message = 'interrupted: a second active retrain of the site' "
        "WHERE kind = 'retrain' AND state IN ('queued', 'running') AND id NOT IN "
        "(SELECT MIN(id) FROM jobs WHERE kind = 'retrain' AND state IN ('queued', 'running') GROUP BY site_id)"
    )
    op.create_index(
        INDEX, "jobs", ["site_id"], unique=True, sqlite_where=ACTIVE_RETRAIN, postgresql_where=ACTIVE_RETRAIN
    )


def downgrade() -> None:
    """Revert this revision."""
    op.drop_index(INDEX, table_name="jobs")
