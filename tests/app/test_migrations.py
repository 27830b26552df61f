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
    app.extensions["egonet.queue"].stop_consumer()  # the request started one (QUEUE_IN_PROCESS): it beat on no tables


def test_0007_gives_stored_dhg_images_the_authors_order(ctx):
    """On a database at 0006 holding what the code before it stored, and back."""
    import cv2
    import numpy as np

    from app.models import Activity, Frame, Sequence
    from app.services import media
    from egonet import io
    from egonet.dhg import decode_dhg, encode_dhg

    downgrade(revision="0006")
    try:
        rng = np.random.default_rng(0)
        rgb = np.clip(np.linspace(0, 255, 48 * 64).reshape(48, 64, 1) + rng.normal(0, 20, (48, 64, 3)), 0, 255)
        rgb = rgb.astype(np.uint8)
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        depth = np.tile(np.linspace(0.5, 3.0, 64, dtype=np.float32), (48, 1))
        height = np.tile(np.linspace(0.0, 1.5, 48, dtype=np.float32)[:, None], (1, 64))
        # Ours before issue 16: depth, height, gray. An authors' file: gray first, with JPEG-like noise.
        ours_before = np.ascontiguousarray(encode_dhg(depth, height, gray)[..., ::-1])
        authors = np.clip(encode_dhg(depth, height, gray) + rng.integers(-3, 4, (48, 64, 3)), 0, 255).astype(np.uint8)
        flat = np.zeros((48, 64, 3), np.uint8) + np.array([7, 20, 40], np.uint8)  # nothing tells its order: ours
        sequence = Sequence(activity=Activity(name="old"), name="s")
        paths = {}
        for i, (name, dhg) in enumerate((("ours", ours_before), ("authors", authors), ("flat", flat))):
            rgb_i = rgb if name != "flat" else np.full_like(rgb, 50)
            paths[name] = media.store(io.encode_png(dhg), ".png")
            db.session.add(Frame(sequence=sequence, index=i, source_name=f"{name}.png", width=64, height=48,
                                 content_hash=f"h{i}", rgb_path=media.store(io.encode_png(rgb_i), ".png"),
                                 dhg_path=paths[name], meta={}))
        db.session.commit()

        def stored() -> dict[str, str]:
            db.session.expire_all()
            rows = db.session.execute(db.select(Frame.source_name, Frame.dhg_path)).all()
            db.session.rollback()  # no transaction left open to block the next migration's locks
            return {source.removesuffix(".png"): path for source, path in rows}

        upgrade()
        after = stored()
        assert after["authors"] == paths["authors"]  # already the authors' order
        assert after["ours"] != paths["ours"] and after["flat"] != paths["flat"]
        decoded = decode_dhg(io.read_dhg(media.local_path(after["ours"])))
        np.testing.assert_array_equal(decoded.gray, gray)
        np.testing.assert_allclose(decoded.depth, depth, atol=0.016)
        np.testing.assert_allclose(decoded.height, height, atol=0.006)
        assert media.local_path(paths["ours"]).exists()  # left for media-check: another row may share it

        downgrade(revision="0006")
        back = stored()
        assert back["ours"] == paths["ours"] and back["flat"] == paths["flat"]  # the same bytes again
        assert back["authors"] != paths["authors"]  # every image in the old order, as that code read them
    finally:
        upgrade()
    assert stored()["authors"] == paths["authors"]


def test_0018_annotations_of_proposals_only_claim_nothing(ctx, make_user):
    """On a database at 0017: in-progress annotations holding only proposals become "todo", and back."""
    from app.models import Activity, Annotation, Frame, Instance, Sequence, Status

    downgrade(revision="0017")
    try:
        ann = make_user("annotator", "ann")
        sequence = Sequence(activity=Activity(name="a"), name="s")
        kinds = {"proposals": "depth", "own": None, "empty-no-object": "none", "done": "depth"}
        for i, name in enumerate(kinds):
            frame = Frame(sequence=sequence, index=i, source_name=name, width=4, height=3, content_hash=f"h{i}",
                          rgb_path=f"x{i}.png", meta={})
            annotation = Annotation(frame=frame, author_id=ann.id, status=Status.DONE if name == "done" else Status.IN_PROGRESS,
                                    no_action_object=name == "empty-no-object")
            if name != "empty-no-object":
                annotation.instances.append(Instance(position=0, key="k", mask_path="m.png", proposal_source=kinds[name]))
            db.session.add(annotation)
        db.session.commit()

        def statuses() -> dict[str, str]:
            db.session.expire_all()
            rows = db.session.execute(db.select(Frame.source_name, Annotation.status).join(Annotation.frame)).all()
            db.session.rollback()
            return {name: status.value for name, status in rows}

        upgrade()
        assert statuses() == {"proposals": "todo", "own": "in_progress", "empty-no-object": "in_progress", "done": "done"}
        downgrade(revision="0017")
        assert statuses()["proposals"] == "in_progress"
    finally:
        upgrade()
