"""Schema migrations: a database made by the first release of revision 0001 keeps its elements through 0004;
0006 adds the one-active-retrain index to a database that already has jobs."""

from pathlib import Path

import pytest
import sqlalchemy as sa

from app.backend.db import make_engine, upgrade


def test_old_bbox_column_names_are_renamed_with_the_data_kept(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'old.db'}"
    upgrade(url, "0003")
    engine = make_engine(url)
    with engine.begin() as connection:  # make it look like the first release of 0001 made it
        for name in ("xmin", "ymin", "xmax", "ymax"):
            connection.execute(sa.text(f"ALTER TABLE elements RENAME COLUMN bbox_{name} TO {name}"))
        _insert_site(connection)
        connection.execute(
            sa.text(
                "INSERT INTO elements (id, site_id, class, points, xmin, ymin, xmax, ymax, source, state, "
                "deleted, version, created_at, updated_at) VALUES (7, 1, 'divider', '[[1, 2], [3, 4]]', "
                "1, 2, 3, 4, 'human', 'proposed', 0, 1, '2026-11-23', '2026-11-23')"
            )
        )
    upgrade(url)
    with engine.connect() as connection:
        columns = {column["name"] for column in sa.inspect(connection).get_columns("elements")}
        row = connection.execute(sa.text("SELECT bbox_xmin, bbox_ymax FROM elements WHERE id = 7")).one()
        indexes = {index["name"] for index in sa.inspect(connection).get_indexes("elements")}
    engine.dispose()
    assert {"bbox_xmin", "bbox_ymin", "bbox_xmax", "bbox_ymax"} <= columns and "xmin" not in columns
    assert tuple(row) == (1.0, 4.0)
    assert "ix_elements_site_bbox" in indexes


def _insert_site(connection: sa.Connection) -> None:
    """Site 1, as the schema of an earlier migration stores it."""
    connection.execute(
        sa.text(
            "INSERT INTO sites (id, name, site_origin_x, site_origin_y, georeference, raster_dir, created_at) "
            "VALUES (1, 's', 0, 0, '{}', '/r', '2026-11-23')"
        )
    )


def test_preaccept_flags_are_added_false_for_existing_elements(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'before.db'}"
    upgrade(url, "0004")
    engine = make_engine(url)
    with engine.begin() as connection:
        _insert_site(connection)
        connection.execute(
            sa.text(
                "INSERT INTO elements (id, site_id, class, points, bbox_xmin, bbox_ymin, bbox_xmax, bbox_ymax, "
                "source, state, deleted, version, created_at, updated_at) VALUES (3, 1, 'divider', "
                "'[[1, 2], [3, 4]]', 1, 2, 3, 4, 'proposal', 'proposed', 0, 1, '2026-11-23', '2026-11-23')"
            )
        )
    upgrade(url)
    with engine.connect() as connection:
        row = connection.execute(sa.text("SELECT preaccepted, qa_sample FROM elements WHERE id = 3")).one()
    engine.dispose()
    assert tuple(row) == (0, 0)


def test_one_active_retrain_index_keeps_the_first_of_duplicate_active_retrains(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'jobs.db'}"
    upgrade(url, "0005")
    engine = make_engine(url)
    with engine.begin() as connection:
        _insert_site(connection)
        for job_id, kind, state in (
            (1, "retrain", "running"),
            (2, "retrain", "queued"),
            (3, "lift", "queued"),
        ):
            connection.execute(
                sa.text(
                    "INSERT INTO jobs (id, site_id, kind, params, state, progress, message, cancel_requested, "
                    "created_by, created_at, updated_at) VALUES "
                    f"({job_id}, 1, '{kind}', '{{}}', '{state}', 0, '', 0, 'x', '2026-11-23', '2026-11-23')"
                )
            )
    upgrade(url)
    with engine.connect() as connection:
        states = dict(connection.execute(sa.text("SELECT id, state FROM jobs ORDER BY id")).all())
        indexes = {index["name"] for index in sa.inspect(connection).get_indexes("jobs")}
    with pytest.raises(sa.exc.IntegrityError), engine.begin() as connection:
        connection.execute(sa.text("UPDATE jobs SET state = 'queued' WHERE id = 2"))
    engine.dispose()
    assert states == {1: "running", 2: "failed", 3: "queued"}
    assert "uq_jobs_one_active_retrain" in indexes
