"""Tests for egonet.train: folds, configuration, checkpoints and resuming, and learning on demo data."""

import itertools
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from egonet import synth
from egonet.checkpoint import CHECKPOINT_FORMAT, DEFAULT_LR, TrainConfig, load_checkpoint, model_from_checkpoint
from egonet.data import Sample
from egonet.dhg import encode_dhg
from egonet.errors import Cancelled
from egonet.predictor import NetworkPredictor
from egonet.train import Fold, cross_validate, make_folds, resolve_device

ROOT = Path(__file__).resolve().parents[2]


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

# The smallest setting that still trains: tiny frames, the lite model, batch 2, CPU.
TINY = {"model": "egonet-lite", "height": 24, "width": 32, "batch_size": 2, "device": "cpu", "eval_every": 0}


def tiny_samples(n=4, groups=("a", "b")):
    samples = []
    for i in range(n):
        rng = np.random.default_rng(i)
        rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
        mask = np.zeros((24, 32), bool)
        mask[8 + i % 3 : 16, 10:20] = True
        rgb[mask] = 250
        samples.append(Sample(rgb=rgb, dhg=rgb[..., ::-1].copy(), mask=mask, group=groups[i % len(groups)], key=100 + i))
    return samples


# --------------------------------------------------------------------------- folds and configuration


def test_leave_one_activity_out_tests_each_activity_once():
    folds = make_folds(["a", "a", "b", "c", "b"], mode="loao")
    assert [(f.name, f.train, f.test) for f in folds] == [
        ("a", [2, 4, 3], [0, 1]),
        ("b", [0, 1, 3], [2, 4]),
        ("c", [0, 1, 2, 4], [3]),
    ]


def test_a_single_split_holds_out_the_end_of_each_activity():
    (fold,) = make_folds(["a"] * 5 + ["b"] * 2 + ["c"], mode="single", test_fraction=0.2)
    assert fold.name == "single"
    assert fold.test == [4, 6] and fold.train == [0, 1, 2, 3, 5, 7]


def test_all_trains_one_model_on_every_frame_and_holds_none_out(tmp_path):
    (fold,) = make_folds(["a", "a", "b"], mode="all")
    assert (fold.name, fold.train, fold.test) == ("all", [0, 1, 2], [])
    maps = []
    (result,) = cross_validate(tiny_samples(), TrainConfig(**(TINY | {"eval_every": 1}), folds="all", epochs=2),
                               out_dir=tmp_path, on_map=lambda fold, sample, p: maps.append(sample.key))
    assert maps == [] and result.test_keys == [] and sorted(result.train_keys) == [100, 101, 102, 103]
    assert result.metrics["train_frames"] == 4 and result.metrics["test_frames"] == 0 and "max_f" not in result.metrics
    state = load_checkpoint(tmp_path / "all.pt")
    assert state["complete"] and state["fold"] == "all" and [h["epoch"] for h in state["history"]] == [1, 2]
    assert all("max_f" not in h for h in state["history"])


def test_folds_that_cannot_be_made_say_why():
    with pytest.raises(ValueError, match="at least two activities"):
        make_folds(["a", "a"], mode="loao")
    with pytest.raises(ValueError, match="at least two labelled frames"):
        make_folds(["a", "b"], mode="single")
    with pytest.raises(ValueError, match="mode must be one of"):
        make_folds(["a"], mode="kfold")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"model": "resnet"}, "unknown name 'resnet'; choose one of .*egonet-lite"),
        ({"folds": "kfold"}, "folds must be one of loao, single, all"),
        ({"epochs": 0}, "epochs must be an integer >= 1"),
        ({"lr": -1.0}, r"lr must be a number in \(0.0"),
        ({"device": "tpu"}, "device must be one of auto, cpu, cuda"),
        ({"height": 4}, "height must be an integer >= 8"),
        ({"test_fraction": 1.0}, "test_fraction"),
    ],
)
def test_bad_configurations_name_the_option(options, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**options)


def test_the_configuration_survives_plain_types_and_resolves_the_learning_rate():
    config = TrainConfig(model="egonet", epochs=3, model_options={"dropout": 0.3})
    again = TrainConfig.from_dict(json.loads(json.dumps(config.to_dict())))
    assert again == config
    assert config.learning_rate == DEFAULT_LR["egonet"] and TrainConfig(lr=0.5).learning_rate == 0.5
    with pytest.raises(ValueError, match="unknown training options nope"):
        TrainConfig.from_dict({"nope": 1})


def test_devices_resolve_to_the_cpu_here():
    assert resolve_device("cpu") == torch.device("cpu")
    if not torch.cuda.is_available():
        assert resolve_device("auto") == torch.device("cpu")
        with pytest.raises(ValueError, match="no CUDA GPU"):
            resolve_device("cuda")


# --------------------------------------------------------------------------- checkpoints


def test_a_run_writes_its_config_and_a_complete_checkpoint_per_fold(tmp_path):
    reports, maps = [], []
    results = cross_validate(
        tiny_samples(),
        TrainConfig(**TINY, epochs=1),
        out_dir=tmp_path,
        on_progress=reports.append,
        on_map=lambda fold, sample, p: maps.append((fold, sample.key, p)),
    )
    assert [r.name for r in results] == ["a", "b"]
    written = json.loads((tmp_path / "config.json").read_text())
    assert written["config"]["lr"] == DEFAULT_LR["egonet-lite"] and [f["fold"] for f in written["folds"]] == ["a", "b"]
    state = load_checkpoint(tmp_path / "a.pt")
    assert state["format"] == CHECKPOINT_FORMAT and state["fold"] == "a" and state["complete"]
    assert state["test_keys"] == [100, 102] and state["train_keys"] == [101, 103]
    assert TrainConfig.from_dict(state["config"]) == TrainConfig(**TINY, epochs=1)
    assert set(state["metrics"]) >= {"max_f", "ap", "aop_max_f", "aop_ap", "loss", "train_loss"}
    assert "momentum_buffer" in str(state["optimizer"]["state"].keys()) or state["optimizer"]["state"]
    # Every held-out frame's map, at the frame's size, once.
    assert sorted(key for _, key, _ in maps) == [100, 101, 102, 103]
    assert all(p.shape == (24, 32) and p.dtype == np.float32 for _, _, p in maps)
    # Progress: steps count up to the total, with a loss once training started.
    assert reports[-1].phase == "done" and reports[-1].step == reports[-1].steps == 2
    assert any(r.loss is not None for r in reports) and 0 <= reports[1].fraction <= 1


def test_a_checkpoint_rebuilds_the_model_that_wrote_it(tmp_path):
    samples = tiny_samples()
    (result,) = cross_validate(samples, TrainConfig(**TINY, epochs=1), out_dir=tmp_path, folds=[Fold("x", [0, 1, 2], [3])])
    model = model_from_checkpoint(load_checkpoint(result.checkpoint))
    again = model_from_checkpoint(load_checkpoint(result.checkpoint))
    probability = NetworkPredictor(model, size=(24, 32)).predict(samples[3].rgb, samples[3].dhg)
    assert probability.shape == (24, 32) and probability.dtype == np.float32
    assert 0 <= probability.min() and probability.max() <= 1
    assert np.array_equal(probability, NetworkPredictor(again, size=(24, 32)).predict(samples[3].rgb, samples[3].dhg))
    # The checkpoint knows its training size.
    assert np.array_equal(probability, NetworkPredictor.from_checkpoint(load_checkpoint(result.checkpoint)).predict(samples[3].rgb, samples[3].dhg))


def stop_in_epoch(epoch):
    def callback(progress):
        if progress.epoch == epoch and progress.loss is not None:
            raise Cancelled

    return callback


def test_an_interrupted_fold_resumes_from_its_file_exactly(tmp_path):
    samples = tiny_samples(6)
    fold = [Fold("x", [0, 1, 2, 3], [4, 5])]
    config = TrainConfig(**TINY, epochs=2)
    (straight,) = cross_validate(samples, config, out_dir=tmp_path / "straight", folds=fold)
    with pytest.raises(Cancelled):
        cross_validate(samples, config, out_dir=tmp_path / "resumed", folds=fold, on_progress=stop_in_epoch(2))
    assert load_checkpoint(tmp_path / "resumed" / "x.pt")["epoch"] == 1  # the last finished epoch
    reports = []
    (resumed,) = cross_validate(samples, config, out_dir=tmp_path / "resumed", folds=fold, on_progress=reports.append)
    # Epoch 1 is counted as done, not run again.
    assert {r.epoch for r in reports} == {0, 2} and min(r.step for r in reports if r.epoch == 2) == 2
    a, b = load_checkpoint(straight.checkpoint), load_checkpoint(resumed.checkpoint)
    assert b["epoch"] == 2 and b["iteration"] == a["iteration"] == 4 and b["complete"]
    for name, tensor in a["state_dict"].items():
        assert torch.allclose(tensor.float(), b["state_dict"][name].float(), atol=1e-6), name
    assert [h["train_loss"] for h in b["history"]] == pytest.approx([h["train_loss"] for h in a["history"]], abs=1e-6)
    assert resumed.metrics["max_f"] == pytest.approx(straight.metrics["max_f"], abs=1e-6)


def test_a_finished_fold_continues_for_more_epochs_from_its_checkpoint(tmp_path):
    samples = tiny_samples()
    fold = [Fold("x", [0, 1, 2], [3])]
    cross_validate(samples, TrainConfig(**TINY, epochs=1), out_dir=tmp_path / "a", folds=fold)
    start = load_checkpoint(tmp_path / "a" / "x.pt")
    (more,) = cross_validate(samples, TrainConfig(**TINY, epochs=2), out_dir=tmp_path / "b", folds=fold, start=start)
    state = load_checkpoint(more.checkpoint)
    assert state["epoch"] == 2 and state["iteration"] == 4 and len(state["history"]) == 2
    assert state["history"][0] == start["history"][0]


def old_forward(model, rgb: torch.Tensor, dhg_old: torch.Tensor) -> torch.Tensor:
    """The lite model's probability as the code before issue 16 computed it, written out by hand.

    DHG reached the network in the order it was stored then (depth, height,
    gray), and the coordinate maps came columns first: 2 col / (W - 1) - 1,
    then 2 row / (H - 1) - 1, at the pixels the final resize maps each grid cell to.
    """
    with torch.no_grad():
        features = [model.rgb_stream(model.rgb_norm(rgb)), model.dhg_stream(model.dhg_norm(dhg_old))]
        n, _, h, w = features[0].shape
        height, width = rgb.shape[-2:]
        cols = torch.arange(w) * ((width - 1) / (w - 1)) / (width - 1) * 2 - 1
        rows = torch.arange(h) * ((height - 1) / (h - 1)) / (height - 1) * 2 - 1
        x = cols.view(1, 1, 1, w).expand(n, 1, h, w)
        y = rows.view(1, 1, h, 1).expand(n, 1, h, w)
        logits = model.head(torch.cat([*features, x, y], dim=1))
        logits = torch.nn.functional.interpolate(logits, size=(height, width), mode="bilinear", align_corners=True)
    return logits.softmax(1)[:, 1]


def test_an_old_checkpoint_keeps_the_conventions_it_was_trained_with(tmp_path):
    samples = tiny_samples()
    fold = [Fold("x", [0, 1, 2], [3])]
    (result,) = cross_validate(samples, TrainConfig(**TINY, epochs=1), out_dir=tmp_path / "new", folds=fold)
    state = load_checkpoint(result.checkpoint)
    assert state["model"]["options"]["coord_order"] == "rows-first"
    assert state["model"]["options"]["dhg_order"] == "gray-height-depth"
    # A checkpoint written before issue 16 records neither order.
    old = dict(state, model={"name": "egonet-lite", "options": {"coords": "normalized", "dropout": 0.5}})
    model = model_from_checkpoint(old)
    assert (model.config.options["coord_order"], model.dhg_order) == ("cols-first", "depth-height-gray")
    # Its frames' DHG images are now stored gray first (migration 0007 reversed them): it still sees what it learnt on.
    rgb, dhg_old = samples[3].rgb, samples[3].dhg
    dhg_now = np.ascontiguousarray(dhg_old[..., ::-1])
    predicted = NetworkPredictor.from_checkpoint(old).predict(rgb, dhg_now)
    to_tensor = lambda a: torch.from_numpy(np.ascontiguousarray(a.transpose(2, 0, 1)))[None].float() / 255  # noqa: E731
    expected = old_forward(model, to_tensor(rgb), to_tensor(dhg_old))[0].numpy()
    np.testing.assert_allclose(predicted, expected, atol=1e-5)
    # Read with today's conventions, the same weights would answer differently.
    assert not np.allclose(NetworkPredictor.from_checkpoint(state).predict(rgb, dhg_now), expected, atol=1e-3)
    # Training it on keeps its conventions, and the new checkpoint records them.
    (more,) = cross_validate(samples, TrainConfig(**TINY, epochs=2), out_dir=tmp_path / "more", folds=fold, start=old)
    options = load_checkpoint(more.checkpoint)["model"]["options"]
    assert (options["coord_order"], options["dhg_order"]) == ("cols-first", "depth-height-gray")


def test_asking_for_fewer_epochs_than_a_checkpoint_has_is_an_error(tmp_path):
    samples = tiny_samples()
    fold = [Fold("x", [0, 1, 2], [3])]
    cross_validate(samples, TrainConfig(**TINY, epochs=2), out_dir=tmp_path, folds=fold)
    with pytest.raises(ValueError, match="trained 2 epochs already"):
        cross_validate(samples, TrainConfig(**TINY, epochs=1), out_dir=tmp_path / "b", folds=fold, start=load_checkpoint(tmp_path / "x.pt"))


def test_a_file_that_is_not_a_checkpoint_is_refused(tmp_path):
    path = tmp_path / "x.pt"
    torch.save({"weights": torch.zeros(1)}, path)
    with pytest.raises(ValueError, match="not an EgoNet checkpoint"):
        load_checkpoint(path)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    with pytest.raises(ValueError, match="cannot read the checkpoint"):
        load_checkpoint(tmp_path / "junk.pt")


# --------------------------------------------------------------------------- learning


def demo_samples(per_activity: int, *, width: int, height: int) -> list[Sample]:
    samples = []
    for activity in synth.ACTIVITIES:
        for f in synth.render_activity(activity, per_activity, seed=0, width=width, height=height):
            dhg = encode_dhg(f.depth_m, f.height_m, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY))
            samples.append(Sample(rgb=f.rgb, dhg=dhg, mask=f.mask, group=activity, key=(activity, f.index)))
    return samples


@pytest.mark.slow
def test_egonet_lite_learns_the_demo_better_than_the_action_object_prior(tmp_path):
    """~40 s on one core: 105 demo frames at 64x48, 8 epochs from a random initialisation.

    Small frames and few epochs favour quick fitting over regularisation
    (dropout 0.1, no augmentation, a larger step); the default settings need
    more data and epochs (see docs/training.md).
    """
    samples = demo_samples(15, width=64, height=48)
    config = TrainConfig(
        model="egonet-lite", model_options={"dropout": 0.1}, augment=None, lr=0.05, folds="single",
        epochs=8, batch_size=4, height=48, width=64, device="cpu", eval_every=0,
    )
    (result,) = cross_validate(samples, config, out_dir=tmp_path)
    losses = [h["train_loss"] for h in result.history]
    assert losses[-1] < 0.5 * losses[0]
    assert all(b < a for a, b in itertools.pairwise(losses[1:]))  # falling after the first step away from init
    metrics = result.metrics
    assert metrics["test_frames"] == 21 and metrics["train_frames"] == 84
    assert metrics["max_f"] > metrics["aop_max_f"] + 0.02, metrics
    assert metrics["ap"] > metrics["aop_ap"], metrics


@pytest.mark.slow
def test_torchrun_trains_on_two_processes_and_only_rank_zero_writes(tmp_path):
    script = tmp_path / "ddp.py"
    script.write_text(textwrap.dedent(f"""
        import json, os, sys
        sys.path.insert(0, {str(ROOT)!r})
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_train import TINY, tiny_samples
        from egonet.checkpoint import TrainConfig
        from egonet.train import Fold, cross_validate
        rank = int(os.environ["RANK"])
        out = {str(tmp_path / "out")!r}
        results = cross_validate(tiny_samples(6), TrainConfig(**(TINY | {{"batch_size": 4}}), epochs=2), out_dir=out,
                                 folds=[Fold("x", [0, 1, 2, 3], [4, 5])])
        # A file per rank: the two processes' stdout can interleave.
        with open(os.path.join({str(tmp_path)!r}, f"rank{{rank}}.json"), "w") as f:
            json.dump({{"rank": rank, "world": int(os.environ["WORLD_SIZE"]), "max_f": results[0].metrics.get("max_f")}}, f)
    """))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    run = subprocess.run(
        [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-port", "29533", str(script)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300, check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    lines = [json.loads(path.read_text()) for path in sorted(tmp_path.glob("rank*.json"))]
    assert sorted((line["rank"], line["world"]) for line in lines) == [(0, 2), (1, 2)]
    assert [line["max_f"] is not None for line in sorted(lines, key=lambda x: x["rank"])] == [True, False]
    state = load_checkpoint(tmp_path / "out" / "x.pt")
    assert state["epoch"] == 2 and state["iteration"] == 2  # 4 frames, 2 per process and step
    assert json.loads((tmp_path / "out" / "config.json").read_text())["environment"]["world_size"] == 2


# --------------------------------------------------------------------------- object classes (DeepLab-Obj)


def test_deeplab_obj_learns_the_classes_of_each_folds_training_frames_only(tmp_path):
    samples = []
    for s in tiny_samples(6, groups=("a", "b", "c")):
        mask = s.mask
        other = np.zeros_like(mask)
        other[0:4, 0:6] = True
        instances = {"a": (("cup", mask),), "b": (("cup", mask), ("pan", other)), "c": (("knife", mask),)}[s.group]
        samples.append(Sample(rgb=s.rgb, dhg=None, mask=mask, group=s.group, key=s.key, instances=instances))
    config = TrainConfig(**(TINY | {"model": "deeplab-obj"}), epochs=1, model_options={"width_divisor": 16})
    maps = []
    results = cross_validate(samples, config, out_dir=tmp_path, on_map=lambda fold, sample, p: maps.append(p))
    seen = {r.name: load_checkpoint(r.checkpoint)["model"]["options"]["classes"] for r in results}
    assert seen == {"a": ["cup", "knife", "pan"], "b": ["cup", "knife"], "c": ["cup", "pan"]}
    assert [r.metrics["classes"] for r in results] == [3, 2, 2]
    model = model_from_checkpoint(load_checkpoint(results[1].checkpoint))
    assert model.head.fc10.out_channels == 3  # background, cup, knife
    assert len(maps) == 6 and all(p.dtype == np.float32 and 0 <= p.min() and p.max() <= 1 for p in maps)
