"""The paper's Figure 3 on the frame page and from `flask egonet activations`."""

import numpy as np
import pytest
import torch

from app.extensions import db
from app.models import Frame
from app.models.training import Checkpoint, FoldsMode, RunStatus, TrainingRun
from app.services import activations, media, training
from app.services.importing import import_path
from egonet import io
from egonet.checkpoint import TrainConfig, checkpoint_state
from egonet.network.builders import build_model
from egonet.predictor import NetworkPredictor
from tests.app.factories import image_folder


def saved_checkpoint(model_name="egonet-lite", options=None, *, write=True) -> Checkpoint:
    """A finished run with one checkpoint of a seeded, untrained model (its file written unless ``write`` is false)."""
    run = TrainingRun(name="tiny", model_name=model_name, model_options=options or {}, folds=FoldsMode.SINGLE, epochs=1,
                      device="cpu", seed=0, status=RunStatus.DONE)
    db.session.add(run)
    db.session.flush()
    checkpoint = Checkpoint(run=run, fold="single", path=f"run-{run.id}/single.pt", epochs=1)
    if write:
        torch.manual_seed(0)
        model = build_model(model_name, **(options or {}))
        config = TrainConfig(model=model_name, model_options=options or {}, height=32, width=40)
        state = checkpoint_state(model, config, fold="single", train_keys=[], test_keys=[], epoch=1, iteration=1,
                                 complete=True, metrics={}, history=[], extra={})
        training.files.save(checkpoint.path, state)
    db.session.add(checkpoint)
    db.session.commit()
    return checkpoint


@pytest.fixture
def frames(ctx, tmp_path):
    """One frame with DHG (computed from depth) and one without."""
    import_path(image_folder(tmp_path / "rgbd", n=1, depth=True, intrinsics=True), activity="room")
    import_path(image_folder(tmp_path / "rgb", n=1, size=(48, 64)), activity="kids")
    with_dhg, without = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().all()
    assert with_dhg.dhg_path and not without.dhg_path
    return with_dhg, without


def test_the_maps_are_the_predictors_on_the_frames_inputs(frames):
    with_dhg, without = frames
    checkpoint = saved_checkpoint()
    found = activations.compute(checkpoint, with_dhg)
    predictor = NetworkPredictor.from_checkpoint(training.files.load(checkpoint.path))
    rgb, dhg = io.read_image(media.local_path(with_dhg.rgb_path)), io.read_dhg(media.local_path(with_dhg.dhg_path))
    expected = predictor.activations(rgb, dhg)
    assert set(found.maps) == {"rgb", "dhg"} and found.channels == {"rgb": 256, "dhg": 256} and not found.absent
    for name in ("rgb", "dhg"):
        np.testing.assert_array_equal(found.maps[name], expected[name])
        assert found.maps[name].shape == (with_dhg.height, with_dhg.width)
    alone = activations.compute(checkpoint, without)
    assert set(alone.maps) == {"rgb"}
    assert alone.absent == {"dhg": "this frame has no DHG image: the DHG pathway cannot run"}
    one = activations.compute(saved_checkpoint("egonet-rgb", {"width_divisor": 64}), with_dhg)
    assert set(one.maps) == {"rgb"} and one.absent == {"dhg": "egonet-rgb has no DHG pathway"}


def test_the_command_writes_figure_3_as_a_png(app, frames, runner, tmp_path):
    with_dhg, without = frames
    checkpoint = saved_checkpoint()
    out = tmp_path / "fig.png"
    result = runner.invoke(args=["egonet", "activations", str(checkpoint.id), str(with_dhg.id), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert f"checkpoint {checkpoint.id} (egonet-lite) on frame {with_dhg.id}" in result.output
    picture = io.decode_image(out.read_bytes(), path=str(out))
    assert picture.shape[0] > 300 and picture.shape[1] > 500
    assert activations.cache_path(checkpoint, with_dhg).read_bytes() == out.read_bytes()  # the page reuses it
    result = runner.invoke(args=["egonet", "activations", "999", str(with_dhg.id)])
    assert result.exit_code != 0 and "no checkpoint with id 999" in result.output
    result = runner.invoke(args=["egonet", "activations", str(checkpoint.id), "999"])
    assert result.exit_code != 0 and "no frame with id 999" in result.output
    dhg_only = saved_checkpoint("egonet-dhg", {"width_divisor": 64})
    result = runner.invoke(args=["egonet", "activations", str(dhg_only.id), str(without.id), "--out", str(tmp_path / "x.png")])
    assert result.exit_code != 0 and f"frame {without.id} has no DHG image and egonet-dhg reads only DHG" in result.output


def test_the_frame_page_shows_a_small_models_maps_and_sends_a_large_one_to_the_command_line(app, frames, admin_client):
    with_dhg, without = frames
    small = saved_checkpoint()
    page = admin_client.get(f"/frames/{with_dhg.id}").get_data(as_text=True)
    assert 'id="activations-checkpoint"' in page and f"checkpoint {small.id}: run #{small.run_id} tiny (egonet-lite)" in page
    assert 'id="activations-figure"' not in page
    page = admin_client.get(f"/frames/{with_dhg.id}?checkpoint={small.id}").get_data(as_text=True)
    url = f"/frames/{with_dhg.id}/activations/{small.id}.png"
    assert f'id="activations-figure" src="{url}"' in page
    with admin_client.get(url) as answer:
        assert answer.status_code == 200 and answer.mimetype == "image/png"
        assert io.decode_image(answer.data, path=url).shape[2] == 3
    assert activations.cache_path(small, with_dhg).exists()
    page = admin_client.get(f"/frames/{without.id}?checkpoint={small.id}").get_data(as_text=True)
    assert "This frame has no DHG image: the DHG pathway cannot run." in page
    with admin_client.get(f"/frames/{without.id}/activations/{small.id}.png") as answer:
        assert answer.status_code == 200

    large = saved_checkpoint("egonet", write=False)  # 138.5 M parameters: counted without building or loading it
    page = admin_client.get(f"/frames/{with_dhg.id}?checkpoint={large.id}").get_data(as_text=True)
    assert (f"egonet (138.5 M parameters) is too large to run in a page request: draw it with "
            f"`flask egonet activations {large.id} {with_dhg.id} --out FILE.png`, then reload") in page
    assert 'id="activations-figure"' not in page
    assert admin_client.get(f"/frames/{with_dhg.id}/activations/{large.id}.png").status_code == 409
    assert admin_client.get(f"/frames/{with_dhg.id}?checkpoint=999").status_code == 404
    app.config["ACTIVATIONS_INLINE_MAX_PARAMS"] = 1_000_000  # below egonet-lite's 1.6 M: only a cached figure is shown
    assert "too large to run in a page request" not in admin_client.get(f"/frames/{with_dhg.id}?checkpoint={small.id}").get_data(as_text=True)
    page = admin_client.get(f"/frames/{without.id}?checkpoint={small.id}").get_data(as_text=True)
    assert "egonet-lite (1.6 M parameters) is too large to run in a page request" not in page  # cached above
    other = saved_checkpoint()
    assert "egonet-lite (1.6 M parameters) is too large to run in a page request" in admin_client.get(
        f"/frames/{without.id}?checkpoint={other.id}").get_data(as_text=True)
