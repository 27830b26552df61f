"""Dataset browsing, log-in, accounts and the read-only API."""

from app.extensions import db
from app.models import Activity, Frame
from app.services.importing import import_path
from app.services.users import create_user
from tests.app.access import ADMIN, ALL, STAFF
from tests.app.factories import image_folder

RULES = {
    "static": (None, 200),
    "auth.login": (None, {"GET": 200, "POST": 400}),
    "auth.logout": (ALL, 302),
    "users.account": (STAFF, {"GET": 200, "POST": 400}),
    "users.index": (ADMIN, 200),
    "users.create": (ADMIN, 400),
    "users.set_role": (ADMIN, 400),
    "users.deactivate": (ADMIN, 302),
    "users.activate": (ADMIN, 302),
    "users.reset_password": (ADMIN, 200),
    "frames.index": (STAFF, 200),
    "frames.activity": (STAFF, 200),
    "frames.frame": (STAFF, 200),
    "frames.thumbnail": (STAFF, 200),
    "frames.depth": (STAFF, 200),
    "frames.points": (STAFF, 200),
    "frames.media_file": (STAFF, 200),
    "frames.normalised_prediction": (STAFF, 200),
    "frames.colour_bar": (STAFF, 200),
    # the access fixture's checkpoint file is not a checkpoint: staff get the 400 that says so
    "frames.activations_figure": (STAFF, 400),
    "frames.import_points": (ADMIN, 400),  # no file sent: the 400 that asks for one
    "api.activities": (STAFF, 200),
    "api.activity_frames": (STAFF, 200),
    "api.frame": (STAFF, 200),
    "api.csrf_token": (None, 200),
}


def url_values(app, tmp_path) -> dict:
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=2, depth=True, intrinsics=True), activity="cooking")
        frame = db.session.execute(db.select(Frame)).scalars().first()
        activity = db.session.execute(db.select(Activity)).scalar_one()
        account, _ = create_user("access-account", "annotator")
        return {"frame_id": frame.id, "activity_id": activity.id, "name": frame.rgb_path, "filename": "css/app.css",
                "user_id": account.id}
