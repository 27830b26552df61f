"""`flask egonet export-3d` and the frame viewer's points endpoint, on demo frames (depth + intrinsics)."""

import numpy as np
import pytest
from plyfile import PlyData

from app.extensions import db
from app.models import Frame
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import ground_truth, media
from app.services import frames as frames_service
from app.services.demo import create_demo
from egonet import io


@pytest.fixture
def frame_id(app):
    with app.app_context():
        create_demo(frames_per_activity=1, unlabelled_fraction=0, width=64, height=48)
        return db.session.execute(db.select(Frame.id).order_by(Frame.id)).scalars().first()


def add_prediction(frame: Frame, probability: np.ndarray, *, threshold: float) -> Prediction:
    run = TrainingRun(name="r", model_name="egonet-lite", folds=FoldsMode.SINGLE, epochs=1, device="cpu", seed=0, status=RunStatus.DONE)
    db.session.add(run)
    db.session.flush()
    checkpoint = Checkpoint(run_id=run.id, fold="single", path="x.pt", epochs=1, metrics={"threshold": threshold})
    db.session.add(checkpoint)
    db.session.flush()
    prediction = Prediction(run_id=run.id, checkpoint_id=checkpoint.id, frame_id=frame.id, held_out=True,
                            path=media.store(io.encode_probability_png(probability), ".png"))
    db.session.add(prediction)
    db.session.commit()
    return prediction


def test_export_3d_writes_the_marked_cloud(app, frame_id, runner, tmp_path):
    with app.app_context():
        frame = db.session.get(Frame, frame_id)
        truth = ground_truth.mask_of(ground_truth.ground_truths([frame_id])[frame_id])
        depth = frames_service.frame_depth(frame)
        probability = np.zeros(truth.shape, np.float32)
        probability[:, : truth.shape[1] // 2] = 0.4  # the left half, over the best-F threshold 0.3
        prediction_id = add_prediction(frame, probability, threshold=0.3).id
    out = tmp_path / "frame.ply"
    result = runner.invoke(args=["egonet", "export-3d", str(frame_id), "--out", str(out)])
    assert result.exit_code == 0, result.output
    valid = depth > 0
    assert f"{int(valid.sum())} points (every 1. pixel), {int((truth & valid).sum())} labelled" in result.output
    assert f"prediction {prediction_id}, p >= 0.300" in result.output
    ply = PlyData.read(str(out))
    vertex = ply["vertex"]
    assert vertex.count == int(valid.sum())
    assert int(vertex["truth"].sum()) == int((truth & valid).sum())
    assert int(vertex["predicted"].sum()) == int(valid[:, : truth.shape[1] // 2].sum())
    assert any(f"prediction {prediction_id} of run" in c for c in ply.comments)
    # Camera coordinates: z is the stored depth.
    assert np.allclose(np.sort(vertex["z"]), np.sort(depth[valid]), atol=1e-6)

    small = runner.invoke(args=["egonet", "export-3d", str(frame_id), "--out", str(tmp_path / "s.ply"), "--max-points", "300"])
    assert small.exit_code == 0 and PlyData.read(str(tmp_path / "s.ply"))["vertex"].count <= 300
    for args, message in ((["999999"], "no frame with id 999999"), ([str(frame_id), "--prediction", "424242"], "has no prediction 424242")):
        bad = runner.invoke(args=["egonet", "export-3d", *args, "--out", str(tmp_path / "x.ply")])
        assert bad.exit_code != 0 and message in bad.output and "Traceback" not in bad.output


def test_points_endpoint_is_bounded_and_refuses_frames_without_depth(app, frame_id, admin_client):
    response = admin_client.get(f"/frames/{frame_id}/points.bin?max=500")
    assert response.status_code == 200 and response.mimetype == "application/octet-stream"
    data = response.get_data()
    assert data[:4] == b"EGP1"
    count = int.from_bytes(data[4:8], "little")
    assert 0 < count <= 500 and len(data) == 8 + 16 * count
    flags = np.frombuffer(data, np.uint8, offset=8 + 12 * count).reshape(count, 4)[:, 3]
    assert (flags & 1).any() and not (flags & 2).any()  # labelled points, no prediction yet
    for query in ("max=0", "max=100001"):
        bad = admin_client.get(f"/frames/{frame_id}/points.bin?{query}", headers={"Accept": "application/json"})
        body = bad.get_json()
        assert bad.status_code == 400 and list(body["fields"]) == ["max"] and "max" in body["message"]
    with app.app_context():
        frame = db.session.get(Frame, frame_id)
        frame.depth_path = None
        db.session.commit()
    page = admin_client.get(f"/frames/{frame_id}").get_data(as_text=True)
    assert 'id="view3d"' not in page  # no 3D button without depth
    assert admin_client.get(f"/frames/{frame_id}/points.bin").status_code == 404


def test_frame_page_offers_the_3d_view(frame_id, admin_client):
    page = admin_client.get(f"/frames/{frame_id}").get_data(as_text=True)
    assert f'data-points-url="/frames/{frame_id}/points.bin"' in page and "js/frame3d.js" in page
