"""studies: studies, their frames, participants, trials, clicks and events

Revision ID: 0004
Revises: 0003
"""

from alembic import op
import sqlalchemy as sa

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def _time(name: str, *, nullable: bool) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def upgrade():
    op.create_table(
        "study",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("seed", sa.Integer(), nullable=False),
        sa.Column("frames_per_activity", sa.Integer(), nullable=False),
        sa.Column("time_limit_s", sa.Integer(), nullable=False),
        sa.Column("trial_limit_s", sa.Integer(), nullable=True),
        sa.Column("multiple_clicks", sa.Boolean(), nullable=False),
        sa.Column("sigma_px", sa.Float(), nullable=False),
        sa.Column("superpixels", sa.JSON(), nullable=False),
        sa.Column("instructions", sa.Text(), nullable=False),
        sa.Column("consent", sa.Text(), nullable=False),
        sa.Column("created_by_id", sa.Integer(), nullable=True),
        _time("created_at", nullable=False),
        sa.ForeignKeyConstraint(["created_by_id"], ["user.id"], name=op.f("fk_study_created_by_id_user")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study")),
    )

    op.create_table(
        "study_frame",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("frame_id", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(["frame_id"], ["frame.id"], name=op.f("fk_study_frame_frame_id_frame")),
        sa.ForeignKeyConstraint(
            ["study_id"], ["study.id"], name=op.f("fk_study_frame_study_id_study"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_frame")),
        sa.UniqueConstraint("study_id", "frame_id", name=op.f("uq_study_frame_study_id_frame_id")),
        sa.UniqueConstraint("study_id", "position", name=op.f("uq_study_frame_study_id_position")),
    )
    with op.batch_alter_table("study_frame", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_frame_frame_id"), ["frame_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_study_frame_study_id"), ["study_id"], unique=False)

    op.create_table(
        "study_participant",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("number", sa.Integer(), nullable=False),
        sa.Column("entry", sa.Enum("code", "link", name="entrykind", native_enum=False, length=20), nullable=False),
        sa.Column("code", sa.String(length=16), nullable=False),
        sa.Column("link_token", sa.String(length=64), nullable=True),
        _time("link_used_at", nullable=True),
        sa.Column("order_seed", sa.Integer(), nullable=False),
        _time("consented_at", nullable=True),
        _time("started_at", nullable=True),
        _time("deadline", nullable=True),
        _time("finished_at", nullable=True),
        sa.Column(
            "end_reason",
            sa.Enum("completed", "time_up", "declined", name="endreason", native_enum=False, length=20),
            nullable=True,
        ),
        _time("created_at", nullable=False),
        sa.ForeignKeyConstraint(
            ["study_id"], ["study.id"], name=op.f("fk_study_participant_study_id_study"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(["user_id"], ["user.id"], name=op.f("fk_study_participant_user_id_user")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_participant")),
        sa.UniqueConstraint("code", name=op.f("uq_study_participant_code")),
        sa.UniqueConstraint("link_token", name=op.f("uq_study_participant_link_token")),
        sa.UniqueConstraint("study_id", "number", name=op.f("uq_study_participant_study_id_number")),
        sa.UniqueConstraint("user_id", name=op.f("uq_study_participant_user_id")),
    )
    with op.batch_alter_table("study_participant", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_participant_study_id"), ["study_id"], unique=False)

    op.create_table(
        "study_trial",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("study_frame_id", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        _time("shown_at", nullable=True),
        _time("submitted_at", nullable=True),
        sa.Column(
            "outcome",
            sa.Enum("clicked", "none", "timed_out", "expired", name="outcome", native_enum=False, length=20),
            nullable=True,
        ),
        sa.Column("rt_ms", sa.Float(), nullable=True),
        sa.Column("window_width", sa.Integer(), nullable=True),
        sa.Column("window_height", sa.Integer(), nullable=True),
        sa.Column("display_width", sa.Float(), nullable=True),
        sa.Column("display_height", sa.Float(), nullable=True),
        sa.Column("pixel_ratio", sa.Float(), nullable=True),
        sa.ForeignKeyConstraint(
            ["participant_id"],
            ["study_participant.id"],
            name=op.f("fk_study_trial_participant_id_study_participant"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["study_frame_id"],
            ["study_frame.id"],
            name=op.f("fk_study_trial_study_frame_id_study_frame"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_trial")),
        sa.UniqueConstraint("participant_id", "position", name=op.f("uq_study_trial_participant_id_position")),
        sa.UniqueConstraint(
            "participant_id", "study_frame_id", name=op.f("uq_study_trial_participant_id_study_frame_id")
        ),
    )
    with op.batch_alter_table("study_trial", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_trial_participant_id"), ["participant_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_study_trial_study_frame_id"), ["study_frame_id"], unique=False)

    op.create_table(
        "study_click",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("x", sa.Float(), nullable=False),
        sa.Column("y", sa.Float(), nullable=False),
        sa.Column("rt_ms", sa.Float(), nullable=False),
        _time("received_at", nullable=False),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["study_trial.id"], name=op.f("fk_study_click_trial_id_study_trial"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_click")),
        sa.UniqueConstraint("trial_id", "position", name=op.f("uq_study_click_trial_id_position")),
    )
    with op.batch_alter_table("study_click", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_click_trial_id"), ["trial_id"], unique=False)

    op.create_table(
        "study_event",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column(
            "kind",
            sa.Enum(
                "blur", "focus", "visibility", "resize", "undo", "reload", name="eventkind", native_enum=False, length=20
            ),
            nullable=False,
        ),
        sa.Column("client_ms", sa.Float(), nullable=True),
        _time("server_at", nullable=False),
        sa.Column("detail", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["study_trial.id"], name=op.f("fk_study_event_trial_id_study_trial"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_study_event")),
    )
    with op.batch_alter_table("study_event", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_study_event_trial_id"), ["trial_id"], unique=False)


def downgrade():
    for table, columns in (
        ("study_event", ["trial_id"]),
        ("study_click", ["trial_id"]),
        ("study_trial", ["study_frame_id", "participant_id"]),
        ("study_participant", ["study_id"]),
        ("study_frame", ["study_id", "frame_id"]),
    ):
        with op.batch_alter_table(table, schema=None) as batch_op:
            for column in columns:
                batch_op.drop_index(batch_op.f(f"ix_{table}_{column}"))
        op.drop_table(table)
    op.drop_table("study")
