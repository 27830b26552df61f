"""`flask egonet ablations` and `train --init`: runs recorded like any other, the table, the init file's record.

VGG variants train at 16x12 (a one-cell fc grid: a second or two per step)
on two demo activities of two frames each; enough to pass through every
step, not to learn. The init file is torchvision VGG16's shapes made of
stride-0 views (a few hundred kilobytes on disk).
"""

import csv
import hashlib
import json
import re

import pytest
import torch

from app.extensions import db
from app.models import Activity
from app.models.training import RunStatus, TrainingRun
from app.services import ground_truth, training
from app.services.demo import create_demo
from app.services.training import ablations
from egonet.metrics import score_maps
from tests.unit.test_init import full_vgg16, tiny_vgg16

BUDGET = ["--folds", "single", "--epochs", "1", "--size", "16x12", "--batch-size", "2", "--device", "cpu",
          "--activities", "cooking", "--activities", "dining"]


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def demo(app):
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=32, height=24)
        return dict(db.session.execute(db.select(Activity.name, Activity.id)).all())


def held_out(run: TrainingRun, activity: str) -> list:
    """The run's held-out (map, truth mask) pairs of one activity."""
    pairs = [(f, p) for f, p in training.held_out_predictions(run) if f.sequence.activity.name == activity]
    truths = ground_truth.ground_truths([f.id for f, _ in pairs])
    return [(p, ground_truth.mask_of(truths[f.id])) for f, p in pairs]


def all_runs() -> list[TrainingRun]:
    return list(db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id)).scalars())


# --------------------------------------------------------------------------- planning (fast)


def test_plan_is_every_model_times_every_seed_with_one_budget():
    base = training.RunRequest(folds="single", epochs=2, width=16, height=12)
    requests = ablations.plan_ablations(ablations.AblationPlan("set A", models=("egonet", "no-coords"), seeds=(0, 5), base=base))
    assert [(r.model, r.seed) for r in requests] == [("egonet", 0), ("egonet", 5), ("no-coords", 0), ("no-coords", 5)]
    assert {(r.epochs, r.width, r.height, r.folds, r.ablation) for r in requests} == {(2, 16, 12, "single", "set A")}
    assert requests[1].name == "set A · egonet · seed 5"
    assert ablations.DEFAULT_MODELS == ("egonet", "single-stream", "egonet-rgb", "egonet-dhg", "no-coords", "no-embedding")


@pytest.mark.parametrize(
    ("models", "seeds", "message"),
    [((), (0,), "at least one of --models"), (("egonet", "egonet"), (0,), "--models repeats"),
     (("egonet",), (1, 1), "--seeds repeats"), (("egonet",), tuple(range(101)), "at most 100 runs")],
)
def test_bad_plans_name_the_option(models, seeds, message):
    with pytest.raises(training.TrainingProblem, match=message):
        ablations.plan_ablations(ablations.AblationPlan("x", models=models, seeds=seeds))


def test_a_bad_model_records_no_run_of_the_set(app, demo, runner):
    result = runner.invoke(args=["egonet", "ablations", "--models", "egonet-rgb,resnet", "--seeds", "0", *BUDGET])
    assert result.exit_code != 0 and "resnet: model: unknown name 'resnet'" in result.output
    assert "Traceback" not in result.output
    with app.app_context():
        assert all_runs() == []


def test_train_init_with_a_wrong_file_is_one_line_naming_layer_and_shapes(app, demo, runner, tmp_path):
    path = tmp_path / "vgg16-tiny.pth"
    torch.save(tiny_vgg16(), path)
    result = runner.invoke(args=["egonet", "train", "--model", "egonet", "--init", str(path), *BUDGET])
    assert result.exit_code != 0
    assert re.search(r"Error: vgg16-tiny.pth: layer conv1_1 has weight \(2, 3, 3, 3\).*needs \(64, 3, 3, 3\)", result.output)
    assert result.output.strip().count("\n") == 0, result.output
    sd = full_vgg16()
    del sd["classifier.3.weight"]
    torch.save(sd, path)
    result = runner.invoke(args=["egonet", "train", "--model", "egonet", "--init", str(path), *BUDGET])
    assert "no 'classifier.3.weight'" in result.output and result.exit_code != 0
    result = runner.invoke(args=["egonet", "train", "--model", "egonet-lite", "--init", str(path), *BUDGET])
    assert "no 'classifier.3.weight'" in result.output or "has no VGG stream" in result.output
    with app.app_context():
        assert all_runs() == []


# --------------------------------------------------------------------------- real runs (slow)


def test_markdown_puts_the_papers_numbers_beside_and_the_seed_spread():
    row = ablations.ModelRow(
        model="egonet-dhg", description="DHG stream only", paper=(0.369, 0.208), runs=[4, 5],
        per_activity={"cooking": (0.5, 0.25)}, mean=(0.45, 0.3), spread=(0.0212, 0.01), aop=(0.4, None),
        n={"cooking": 7}, ci=((0.41, 0.49), None),
    )
    table = ablations.AblationTable(
        name="t", budget={"folds": "single", "epochs": 1, "width": 16, "height": 12, "batch_size": 2, "lr": 0.000192,
                          "device": "cpu", "seeds": [0, 1], "init": None, "frames": 4},
        activities=["cooking", "dining"], rows=[row], notes=["run 6 (egonet, seed 0) is failed: left out"],
        resamples=500, seed=2, code_version="egonet-studio 0.1.0 (git abc1234)",
    )
    text = ablations.table_markdown(table)
    assert "single folds, 1 epochs at 16x12, batch 2, lr 0.000192, seeds 0, 1, 4 labelled frames, random initialisation" in text
    assert "| model | paper MF / AP | cooking MF / AP (n 7) | dining MF / AP (n 0) | mean MF | mean AP |" in text
    assert "| egonet-dhg | 0.369 / 0.208 | 0.500 / 0.250 | – | 0.450 ± 0.021 [0.410, 0.490] | 0.300 ± 0.010 | 0.400 / – | 4, 5 |" in text
    assert "MF and AP pooled over each activity's n held-out frames." in text and "95% BCa bootstrap over held-out frames" in text
    assert "(500 resamples, seed 2). Code: egonet-studio 0.1.0 (git abc1234)." in text
    assert "- run 6 (egonet, seed 0) is failed: left out" in text
    record = ablations.table_rows(table)[0]
    assert record["cooking max_f"] == 0.5 and record["dining ap"] is None and record["sd_max_f"] == 0.0212
    assert (record["cooking n"], record["mean_max_f_lo"], record["mean_max_f_hi"], record["mean_ap_lo"]) == (7, 0.41, 0.49, None)
    assert (record["resamples"], record["bootstrap_seed"], record["code_version"]) == (500, 2, "egonet-studio 0.1.0 (git abc1234)")


def test_ablations_help_states_n_and_intervals(runner):
    text = " ".join(runner.invoke(args=["egonet", "ablations", "--help"]).output.split())
    assert "pooled over its n held-out frames" in text and "95% BCa bootstrap interval over frames" in text
    assert "n per activity, 95% intervals" in text


@pytest.mark.slow
@pytest.mark.one_database
def test_ablations_train_recorded_runs_and_write_the_table(app, demo, runner, tmp_path):
    out = tmp_path / "table"
    args = ["egonet", "ablations", "--models", "egonet-lite", "--seeds", "0,1", "--name", "tiny", "--out", str(out), *BUDGET]
    result = runner.invoke(args=args)
    assert result.exit_code == 0, result.output
    assert "ablation set 'tiny': 2 runs" in result.output

    with app.app_context():
        runs = all_runs()
        assert [(r.model_name, r.seed) for r in runs] == [("egonet-lite", 0), ("egonet-lite", 1)]
        assert all(r.status is RunStatus.DONE and r.config["ablation"] == "tiny" for r in runs)
        assert len({tuple(c.test_frame_ids) for r in runs for c in r.checkpoints}) == 1  # one split for all
        per_run = [{a: score_maps(*zip(*held_out(r, a))) for a in ("cooking", "dining")} for r in runs]

    markdown = (out / "ablations.md").read_text()
    assert "single folds, 1 epochs at 16x12, batch 2" in markdown and "random initialisation" in markdown
    mean_mf = [(s["cooking"].max_f + s["dining"].max_f) / 2 for s in per_run]
    rows = list(csv.DictReader((out / "ablations.csv").read_text().splitlines()))
    assert [r["model"] for r in rows] == ["egonet-lite"] and rows[0]["seeds"] == "2"
    assert float(rows[0]["mean_max_f"]) == pytest.approx(sum(mean_mf) / 2)
    assert float(rows[0]["sd_max_f"]) == pytest.approx(abs(mean_mf[0] - mean_mf[1]) / 2 ** 0.5)
    assert int(rows[0]["cooking n"]) == per_run[0]["cooking"].n_maps and rows[0]["resamples"] == "1000"
    assert float(rows[0]["mean_max_f_lo"]) <= float(rows[0]["mean_max_f"]) <= float(rows[0]["mean_max_f_hi"])
    document = json.loads((out / "ablations.json").read_text())
    assert document["budget"]["seeds"] == [0, 1] and document["activities"] == ["cooking", "dining"]

    # The table again from the recorded runs alone; a taken name is refused.
    again = runner.invoke(args=["egonet", "ablations", "--table", "tiny", "--out", str(tmp_path / "again")])
    assert again.exit_code == 0
    assert (tmp_path / "again" / "ablations.csv").read_text().splitlines()[1:] == (out / "ablations.csv").read_text().splitlines()[1:]
    taken = runner.invoke(args=args)
    assert taken.exit_code != 0 and "exists already" in taken.output


@pytest.mark.slow
@pytest.mark.one_database
def test_train_init_records_the_file_and_the_training_page_shows_it(app, demo, runner, tmp_path, admin_client):
    init = tmp_path / "vgg16-synthetic.pth"
    torch.save(full_vgg16(), init)
    result = runner.invoke(args=["egonet", "train", "--model", "deeplab-rgb", "--init", str(init), *BUDGET])
    assert result.exit_code == 0, result.output
    digest = hashlib.sha256(init.read_bytes()).hexdigest()
    with app.app_context():
        (run,) = all_runs()
        assert run.status is RunStatus.DONE
        assert run.config["init"] == {"name": init.name, "sha256": digest, "kind": "torchvision-vgg16", "path": str(init)}
        assert run.config["train"]["init_sha256"] == digest
        assert run.config["train"]["lr"] == pytest.approx(1e-6 * 16 * 12)  # the paper's lr, converted
        state = training.files.load(run.checkpoints[0].path)
    # One step at the paper's tiny lr keeps fc7 near the file's 7.0 (a random start is ~N(0, 0.02)).
    assert float(state["state_dict"]["rgb_stream.layers.fc7.weight"][:8, :8].mean()) == pytest.approx(7.0, abs=1e-2)
    page = admin_client.get(f"/training/runs/{run.id}").get_data(as_text=True)
    assert "vgg16-synthetic.pth (torchvision-vgg16, SHA-256" in page and digest[:16] in page
