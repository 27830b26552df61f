"""crowd studies: open link, status, conditions, practice and catch frames, platform ids, checks, display, completion codes

Existing studies stay as they were: open, no open link, no conditions, the
explicit click width they were made with, every frame a main frame.

Revision ID: 0009
Revises: 0011
"""

from alembic import op
import sqlalchemy as sa

revision = "0009"
down_revision = "0011"
branch_labels = None
depends_on = None

EMPTY_JSON = sa.text("'{}'")


def _enum(name: str, *values: str) -> sa.Enum:
    return sa.Enum(*values, name=name, native_enum=False, length=20)


def _time(name: str) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=True)


def study_columns() -> tuple[sa.Column, ...]:
    return (
        sa.Column("status", _enum("studystatus", "open", "paused", "closed"), nullable=False, server_default="open"),
        sa.Column("version", sa.Integer(), nullable=False, server_default="1"),
        sa.Column("sigma_scaled", sa.Boolean(), nullable=False, server_default=sa.false()),
        sa.Column("activity_order", _enum("activityorder", "shuffled", "counterbalanced"), nullable=False, server_default="shuffled"),
        sa.Column("open_link_token", sa.String(length=64), nullable=True),
        sa.Column("cap", sa.Integer(), nullable=True),
        sa.Column("arrivals", sa.Integer(), nullable=False, server_default="0"),
        sa.Column("completion_code", sa.String(length=64), nullable=True),
        sa.Column("failed_code", sa.String(length=64), nullable=True),
        sa.Column("redirect_url", sa.String(length=2000), nullable=True),
        sa.Column("comprehension", sa.JSON(), nullable=False, server_default=EMPTY_JSON),
        sa.Column("display", sa.JSON(), nullable=False, server_default=EMPTY_JSON),
    )


def participant_columns() -> tuple[sa.Column, ...]:
    return (
        sa.Column("condition_id", sa.Integer(), nullable=True),
        sa.Column("external_id", sa.String(length=64), nullable=True),
        sa.Column("platform", sa.String(length=20), nullable=True),
        sa.Column("external", sa.JSON(), nullable=False, server_default=EMPTY_JSON),
        sa.Column("user_agent", sa.String(length=512), nullable=True),
        sa.Column("environment", sa.JSON(), nullable=True),
        _time("instructions_done_at"),
        sa.Column("comprehension_attempts", sa.Integer(), nullable=False, server_default="0"),
        _time("comprehension_passed_at"),
        sa.Column("completion_code", sa.String(length=64), nullable=True),
    )


def upgrade():
    with op.batch_alter_table("study", schema=None) as batch_op:
        for column in study_columns():
            batch_op.add_column(column)
        batch_op.create_unique_constraint(batch_op.f("uq_study_open_link_token"), ["open_link_token"])

    op.create_table(
        "study_condition",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("overrides", sa.JSON(), nullable=False),
        sa.Column("quota", sa.Integer(), nullable=True),
        sa.ForeignKeyConstraint(
            ["study_id"], ["study.id"], name=op.f("fk_study_condition_study_id_study"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_condition")),
        sa.UniqueConstraint("study_id", "name", name=op.f("uq_study_condition_study_id_name")),
        sa.UniqueConstraint("study_id", "position", name=op.f("uq_study_condition_study_id_position")),
    )
    with op.batch_alter_table("study_condition", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_condition_study_id"), ["study_id"], unique=False)

    with op.batch_alter_table("study_frame", schema=None) as batch_op:
        batch_op.add_column(sa.Column("kind", _enum("framekind", "main", "practice", "catch"), nullable=False, server_default="main"))
        batch_op.add_column(sa.Column("catch_position", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("region", sa.JSON(), nullable=True))

    with op.batch_alter_table("study_participant", schema=None) as batch_op:
        for column in participant_columns():
            batch_op.add_column(column)
        batch_op.create_index(batch_op.f("ix_study_participant_condition_id"), ["condition_id"], unique=False)
        batch_op.create_foreign_key(
            batch_op.f("fk_study_participant_condition_id_study_condition"),
            "study_condition",
            ["condition_id"],
            ["id"],
            ondelete="SET NULL",
        )
        batch_op.create_unique_constraint(
            batch_op.f("uq_study_participant_study_id_external_id"), ["study_id", "external_id"]
        )

    with op.batch_alter_table("study_trial", schema=None) as batch_op:
        batch_op.add_column(sa.Column("hit", sa.Boolean(), nullable=True))


def downgrade():
    with op.batch_alter_table("study_trial", schema=None) as batch_op:
        batch_op.drop_column("hit")

    with op.batch_alter_table("study_participant", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("uq_study_participant_study_id_external_id"), type_="unique")
        batch_op.drop_constraint(batch_op.f("fk_study_participant_condition_id_study_condition"), type_="foreignkey")
        batch_op.drop_index(batch_op.f("ix_study_participant_condition_id"))
        for column in reversed(participant_columns()):
            batch_op.drop_column(column.name)

    with op.batch_alter_table("study_frame", schema=None) as batch_op:
        for name in ("region", "catch_position", "kind"):
            batch_op.drop_column(name)

    with op.batch_alter_table("study_condition", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_study_condition_study_id"))
    op.drop_table("study_condition")

    with op.batch_alter_table("study", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("uq_study_open_link_token"), type_="unique")
        for column in reversed(study_columns()):
            batch_op.drop_column(column.name)
