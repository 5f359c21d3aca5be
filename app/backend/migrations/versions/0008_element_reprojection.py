"""element_reprojection: the cache of per-element reprojection figures (SRE at 960x540, matched share)

One row per element (deleted with it), valid for the element version and camera-input digest it holds.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-02 10:00:00.000000
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this revision: create the table."""
    op.create_table(
        "element_reprojection",
        sa.Column(
            "element_id", sa.Integer(), sa.ForeignKey("elements.id", ondelete="CASCADE"), primary_key=True
        ),
        sa.Column("element_version", sa.Integer(), nullable=False),
        sa.Column("inputs_digest", sa.String(length=64), nullable=False),
        sa.Column("sre_px", sa.Float(), nullable=True),
        sa.Column("matched_share", sa.Float(), nullable=True),
        sa.Column("images", sa.Integer(), nullable=False),
        sa.Column("notice", sa.Text(), nullable=True),
        sa.Column("computed_at", sa.DateTime(timezone=True), nullable=False),
    )


def downgrade() -> None:
    """Revert this revision."""
    op.drop_table("element_reprojection")
