"""element bounding-box columns renamed bbox_xmin.. (xmin and xmax are system columns in PostgreSQL)

Revision 0001 now creates the new names, so this only renames the columns of databases made by the first
release of 0001 (SQLite ones: on PostgreSQL that release could not run at all).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 19:00:00.000000
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OLD_NAMES = ("xmin", "ymin", "xmax", "ymax")


def _has_old_names() -> bool:
    """Whether the elements table still has the first release's column names."""
    columns = {column["name"] for column in sa.inspect(op.get_bind()).get_columns("elements")}
    return "xmin" in columns


def upgrade() -> None:
    """Apply this revision (RENAME COLUMN keeps the data, and the bbox index follows the columns)."""
    if not _has_old_names():
        return
    for name in OLD_NAMES:
        op.execute(f"ALTER TABLE elements RENAME COLUMN {name} TO bbox_{name}")


def downgrade() -> None:
    """Revert this revision: nothing to undo, since revision 0001 itself now makes the new names."""
