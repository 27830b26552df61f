"""Access rules of the training area (see __init__).

All staff see runs, checkpoints, progress and prediction heatmaps; only
admins start, cancel and resume runs. A bodiless start answers 400 (the form
is missing). ``url_values`` makes one queued run with a finished fold and a
prediction: the matrix cancels it (302) and then resumes it (302), in the
order the routes are registered. Staff download checkpoints and configurations
(the weights hold nothing an annotator's export does not); admins rename,
tag, delete and have frames scored.
"""

import numpy as np

from app.extensions import db
from app.models import Frame
from app.models.training import Checkpoint, FoldsMode, Prediction, TrainingRun
from app.services import media, training
from app.services.importing import import_path
from egonet import io
from tests.app.access import ADMIN, STAFF
from tests.app.factories import image_folder

RULES = {
    "training.index": (STAFF, 200),
    "training.start": (ADMIN, 400),
    "training.status": (STAFF, 200),
    "training.detail": (STAFF, 200),
    "training.cancel": (ADMIN, 302),
    "training.resume": (ADMIN, 302),
    "training.prediction_overlay": (STAFF, 200),
    # The released-weights upload: a bodiless start lacks its fields (400), a chunk its offset (400);
    # the matrix's token names no upload (404).
    "training.weights_upload_start": (ADMIN, 400),
    "training.weights_upload_chunk": (ADMIN, 400),
    "training.weights_upload_finish": (ADMIN, 404),
    "training.weights_upload_cancel": (ADMIN, 404),
    "training.history": (STAFF, 200),
    "training.download_checkpoint": (STAFF, 200),
    "training.run_config": (STAFF, 200),
    "training.edit": (ADMIN, 400),
    "training.frames": (STAFF, 200),
    "training.score_frames": (ADMIN, 302),
    "training.prediction_picture": (STAFF, 200),
    # The matrix's run is queued again by then (resume): deleting it is refused until it is cancelled.
    "training.delete": (ADMIN, {"GET": 409, "POST": 409}),
}


def make_prediction_fixture(frame: Frame) -> dict:
    """A queued run with one checkpoint and a held-out prediction of ``frame`` (call in an app context)."""
    run = TrainingRun(name="access", model_name="egonet-lite", folds=FoldsMode.LOAO, epochs=1, device="cpu", seed=0, config={"train": {}})
    checkpoint = Checkpoint(run=run, fold="training", path="run-0/training.pt", epochs=1, metrics={"max_f": 0.5}, test_frame_ids=[frame.id])
    training.files.put(checkpoint.path, b"a checkpoint's bytes")
    probability = np.linspace(0, 65535, frame.height * frame.width).reshape(frame.height, frame.width).astype(np.uint16)
    prediction = Prediction(run=run, checkpoint=checkpoint, frame=frame, path=media.store(io.encode_png(probability), ".png"), held_out=True)
    db.session.add_all([run, checkpoint, prediction])
    db.session.commit()
    return {"run_id": run.id, "prediction_id": prediction.id, "checkpoint_id": checkpoint.id, "kind": "prediction"}


def url_values(app, tmp_path) -> dict:
    with app.app_context():
        import_path(image_folder(tmp_path / "training-rec", n=1), activity="training")
        frame = db.session.execute(db.select(Frame).order_by(Frame.id.desc())).scalars().first()
        return make_prediction_fixture(frame) | {"upload": "0" * 32}
