"""element pre-accept flags: `preaccepted` (entered as accepted by the model's confidence) and `qa_sample`

A pre-accepted element is stored in state `accepted` with `preaccepted` true, so the review-state machine stays
as it was (a lead approves or returns it); `qa_sample` marks the share of them sampled for the lead's QA queue.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23 21:30:00.000000
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this revision: two flags, false for every existing element."""
    with op.batch_alter_table("elements") as batch:
        batch.add_column(sa.Column("preaccepted", sa.Boolean(), nullable=False, server_default=sa.false()))
        batch.add_column(sa.Column("qa_sample", sa.Boolean(), nullable=False, server_default=sa.false()))


def downgrade() -> None:
    """Revert this revision."""
    with op.batch_alter_table("elements") as batch:
        batch.drop_column("qa_sample")
        batch.drop_column("preaccepted")
