"""The schema comes only from Alembic revisions, and they match the models."""

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from flask_migrate import downgrade, upgrade
from sqlalchemy import inspect

from app.extensions import db


def script_directory(app):
    return ScriptDirectory.from_config(app.extensions["migrate"].migrate.get_config())


def test_one_head(ctx):
    assert len(script_directory(ctx).get_heads()) == 1


def test_upgraded_database_matches_the_models(ctx):
    with db.engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"compare_type": True})
        assert context.get_current_revision() == script_directory(ctx).get_current_head()
        assert compare_metadata(context, db.metadata) == []


def test_downgrade_to_base_and_back(ctx):
    downgrade(revision="base")
    assert set(inspect(db.engine).get_table_names()) <= {"alembic_version"}
    upgrade()
    assert {"frame", "annotation", "user"} <= set(inspect(db.engine).get_table_names())


def test_create_app_never_creates_tables(tmp_path):
    from app import create_app

    app = create_app({"SQLALCHEMY_DATABASE_URI": f"sqlite:///{tmp_path / 'empty.sqlite3'}", "TESTING": True},
                     instance_path=str(tmp_path / "instance"))
    with app.app_context():
        app.test_client().get("/api/activities")
        assert inspect(db.engine).get_table_names() == []
