"""sites: where the camera panel's images and poses come from (data set, workspace, reconstruction site id)

Three nullable columns: `dataset_root` (a nuScenes-layout data set the server may read), `workspace_dir` (the
pipeline workspace) and `recon_site_id` (the reconstruction's site id in it, whose SfM poses give the refined
poses). Sites registered before have none of them: their camera panel shows a notice.

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-02 09:00:00.000000
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this revision: add the three nullable columns."""
    with op.batch_alter_table("sites", schema=None) as batch_op:
        batch_op.add_column(sa.Column("dataset_root", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("workspace_dir", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("recon_site_id", sa.String(length=128), nullable=True))


def downgrade() -> None:
    """Revert this revision."""
    with op.batch_alter_table("sites", schema=None) as batch_op:
        batch_op.drop_column("recon_site_id")
        batch_op.drop_column("workspace_dir")
        batch_op.drop_column("dataset_root")
