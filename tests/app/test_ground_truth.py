import numpy as np

from app.extensions import db
from app.models import Annotation, Frame, Status
from app.services.ground_truth import ground_truths, labelled_frames, mask_of
from app.services.importing import import_path
from tests.app.factories import image_folder


def test_reviewed_wins_and_unfinished_is_not_ground_truth(ctx, tmp_path, make_user):
    import_path(image_folder(tmp_path / "rec", n=3, masks=True), activity="cooking", mask_status=Status.DONE)
    frames = db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()
    other = db.session.merge(make_user("annotator", "other"))
    # frame 0: a second, reviewed annotation with no action-object wins over the done one
    db.session.add(Annotation(frame=frames[0], author=other, status=Status.REVIEWED, no_action_object=True))
    # frame 1: its only annotation goes back to in progress
    frames[1].annotations[0].status = Status.IN_PROGRESS
    db.session.commit()

    chosen = ground_truths(f.id for f in frames)
    assert set(chosen) == {frames[0].id, frames[2].id}
    assert chosen[frames[0].id].author.username == "other"
    assert not mask_of(chosen[frames[0].id]).any()
    assert mask_of(chosen[frames[2].id]).sum() > 0 and mask_of(chosen[frames[2].id]).shape == (48, 64)
    assert [f.id for f in labelled_frames()] == [frames[0].id, frames[2].id]
    assert labelled_frames([frames[0].sequence.activity_id + 999]) == []
    assert isinstance(mask_of(chosen[frames[2].id]), np.ndarray)
