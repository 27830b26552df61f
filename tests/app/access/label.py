"""Access rules of the label area (see __init__).

Annotators and admins label (the labelling page, their own annotation,
presence); reviewers and admins review (and fix a done annotation's masks);
all staff run GrabCut and keep undo histories (a reviewer's fix draws too),
see the overview, read annotations and their masks, and export. Bodiless
writes answer 400 (the body or ``?version=`` is missing), and so do the
GrabCut mask without its query; nobody has a stored undo history (404); an
export form without a status goes back to the Label page (302). Only admins
manage the object classes (an empty name is not on the list: 404).
``url_values`` makes a finished export (row and zip) for its page and download.
"""

import io as io_
import zipfile

from app.extensions import db
from app.models import Annotation, Frame, Instance, Role, Status
from app.models.exports import ExportJob, ExportStatus
from app.services.exchange import ExportOptions
from app.services import media
from app.services.storage import store as storage
from app.services.importing import import_path
from app.services.users import create_user
from egonet import io
from tests.app.access import ADMIN, STAFF
from tests.app.factories import image_folder

LABELLERS = frozenset({Role.ANNOTATOR, Role.ADMIN})
REVIEWERS = frozenset({Role.REVIEWER, Role.ADMIN})
EDITORS = LABELLERS | REVIEWERS

RULES = {
    "label.index": (STAFF, 200),
    "label.frame": (LABELLERS, 200),
    "label.next_unlabelled": (LABELLERS, 302),
    "label.review": (REVIEWERS, 200),
    "label.next_review": (REVIEWERS, 302),
    "label.own_annotation": (LABELLERS, 200),
    "label.save_annotation": (LABELLERS, 400),
    "label.add_time": (LABELLERS, 400),
    "label.reopen_annotation": (LABELLERS, 400),
    "label.presence": (LABELLERS, 400),
    "label.fix_annotation": (REVIEWERS, 400),
    "label.history": (EDITORS, 404),
    "label.put_history": (EDITORS, 400),
    "label.annotation": (STAFF, 200),
    "label.annotation_mask": (STAFF, 200),
    "label.annotation_thumbnail": (STAFF, 200),
    "label.instance_mask": (STAFF, 200),
    "label.upload_instance_mask": (LABELLERS, 400),
    "label.review_annotation": (REVIEWERS, 400),
    "label.grabcut_box": (EDITORS, 400),
    "label.grabcut_stroke": (EDITORS, 400),
    "label.grabcut_undo": (EDITORS, 400),
    "label.grabcut_mask": (EDITORS, 400),
    "label.propagate_next": (LABELLERS, 404),
    "label.copy_previous": (LABELLERS, 404),
    "label.filmstrip": (LABELLERS, 200),
    "label.suggest": (LABELLERS, 400),
    "label.accept_proposal": (LABELLERS, 400),
    "label.class_list": (ADMIN, 200),
    "label.add_classes": (ADMIN, 400),
    "label.remove_class": (ADMIN, 404),
    "exports.create": (STAFF, 302),
    "exports.detail": (STAFF, 200),
    "exports.status": (STAFF, 200),
    "exports.download": (STAFF, 200),
}


def url_values(app, tmp_path) -> dict:
    with app.app_context():
        import_path(image_folder(tmp_path / "label-rec", n=2), activity="labelling")
        frame = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().first()
        author, _ = create_user("label-author", Role.ANNOTATOR, "label-author-password")
        path = media.store(io.encode_png(_square(frame.height, frame.width)), ".png")
        annotation = Annotation(frame=frame, author=author, status=Status.DONE, mask_path=path)
        annotation.instances.append(Instance(position=0, key="a", mask_path=path))
        db.session.add(annotation)
        export = ExportJob(status=ExportStatus.DONE, options=ExportOptions().to_dict(), file_name="export-access.zip")
        db.session.add(export)
        db.session.commit()
        with zipfile.ZipFile(zipped := io_.BytesIO(), "w") as archive:
            archive.writestr("annotations.json", "{}")
        storage().put(f"exports/{export.file_name}", zipped.getvalue())
        return {"frame_id": frame.id, "annotation_id": annotation.id, "position": 0, "export_id": export.id}


def _square(height: int, width: int):
    import numpy as np

    mask = np.zeros((height, width), bool)
    mask[height // 4 : height // 2, width // 4 : width // 2] = True
    return mask
