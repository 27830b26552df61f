"""The methods paragraph against the tables it describes: every frame count in it is counted again here, in each frame mode."""

import json
import re

from app.extensions import db
from app.models.studies import FrameKind, StudyFrame, Trial
from app.models.training import Prediction
from app.services import scoring, studies
from app.services.scoring.cells import BASELINE, count, frames_text
from egonet.metrics import MIN_FRAMES
from tests.app.test_scoring import frames_by_activity, make_run
from tests.app.test_studies_checks import quality_study, run_through, run_through_passing


def activity_of() -> dict[int, str]:
    return {f.id: a for a, fs in frames_by_activity().items() for f in fs}


def by_activity(frame_ids) -> dict[str, set[int]]:
    """Frame ids grouped by their activity."""
    names = activity_of()
    out: dict[str, set[int]] = {}
    for fid in frame_ids:
        out.setdefault(names[fid], set()).add(fid)
    return out


def breakdown(sets: dict[str, set[int]]) -> str:
    return ", ".join(f"{a} {len(ids)}" for a, ids in sorted(sets.items()) if ids)


def the_study(tmp_path):
    """Cooking and hotel, 2 frames each, 1 practice and 2 catch trials; P01 and P02 fail a catch trial, P03 passes; a pilot."""
    study = quality_study(tmp_path)
    good, careless = study.participants
    run_through(good, catch_click=(5.0, 5.0))
    run_through(careless, catch_click=(60.0, 40.0))
    run_through_passing(studies.add_participants(study, count=1)[0])
    studies.add_participants(study, count=1, pilot=True)
    return study


def main_frames(participant_id: int) -> set[int]:
    return set(db.session.execute(
        db.select(StudyFrame.frame_id).join(Trial, Trial.study_frame_id == StudyFrame.id)
        .where(Trial.participant_id == participant_id, StudyFrame.kind == FrameKind.MAIN)
    ).scalars())  # fmt: skip


def held_out(run_id: int) -> set[int]:
    return set(db.session.execute(db.select(Prediction.frame_id).where(Prediction.run_id == run_id, Prediction.held_out.is_(True))).scalars())


def frame_counts(paragraph: str) -> set[int]:
    """Every "N frame(s)" and "activity N" number of the paragraph (but the rule "below MIN_FRAMES frames")."""
    paragraph = paragraph.replace(f"below {MIN_FRAMES} frames in an activity", "")
    said = {int(n) for n in re.findall(r"(\d+) frames?\b", paragraph)}
    return said | {int(n) for n in re.findall(r"(?:cooking|hotel|dining) (\d+)", paragraph)}


def table_counts(report: scoring.Report) -> set[int]:
    """Every frame count the table shows or implies: each cell's n, each row's total and what it had before the cut."""
    out = set()
    for row in report.rows:
        cells = [c for c in row.cells.values() if c.n_frames]
        out |= {c.n_frames for c in cells} | {sum(c.n_frames for c in cells), sum(c.frames_available for c in row.cells.values())}
    return out | {sum(report.frames_per_activity().values())}


def test_the_methods_paragraph_says_what_each_kind_of_row_was_scored_on_in_each_mode(ctx, tmp_path):
    study = the_study(tmp_path)
    single = make_run("single", held_out=["hotel"], folds="single", seed=1)
    loao = make_run("loao", held_out=["cooking", "hotel", "dining"], seed=2)
    people = [p.id for p in study.participants if not p.pilot]
    labelled = by_activity(f.id for fs in frames_by_activity().values() for f in fs)
    seen = {pid: by_activity(main_frames(pid)) for pid in people}
    assert {len(ids) for s in seen.values() for ids in s.values()} == {2}  # 2 frames of each study activity, the same for everyone

    # --frames each: every kind on its own frames, counted here.
    each = scoring.build_report(frames="each").to_methods()
    assert "(the each frame mode)" in each and "shared frame mode" not in each
    names = [r.name for r in scoring.build_report(frames="each").rows if r.kind == BASELINE]
    assert names[:2] == ["Judd", "GBVS"] and "centre prior" in names  # the paper's names, in Table 2's order
    listed = ", ".join(names[:-1]) + " and " + names[-1]
    assert f"Baselines: {listed}, scored on every labelled frame: {frames_text(sum(map(len, labelled.values())))} each ({breakdown(labelled)})" in each
    learned = [n for n in names if n not in ("GBVS", "centre prior", "saliency")]
    assert f"; {', '.join(learned[:-1])} and {learned[-1]} were fitted per fold under leave-one-activity-out" in each
    for run, split in ((loao, "trained with leave-one-activity-out cross-validation"), (single, "trained on a single split")):
        mine = by_activity(held_out(run.id))
        assert re.search(rf"one training run, {split}[^;]*, scored on its held-out frames: {frames_text(sum(map(len, mine.values())))} \({breakdown(mine)}\)[;.]", each)
    per_person = {sum(map(len, s.values())) for s in seen.values()}
    assert f"People are scored with MF only (AP says little about near-binary maps) on the frames of their own trials: {frames_text(per_person.pop())} each ({breakdown(next(iter(seen.values())))})" in each
    assert 'Human study "checks": three participants scored (one pilot participant left out; two participants who failed a check kept).' in each
    assert "Each was shown 4 frames (2 from each of two activities, drawn at random with seed 3, in shuffled order), with one practice trial and two attention-check (catch) trials that are not scored." in each
    assert "counts as an empty map (none here)" in each and "in place of the paper's MCG regions" in each
    assert "hierarchical superpixel regions (about 1000 watershed regions merged along colour boundaries weaker than 0.35)" in each
    report = scoring.build_report(frames="each")
    assert frame_counts(each) <= table_counts(report), frame_counts(each) - table_counts(report)
    data = json.loads(report.to_json())  # the same facts, for a program
    assert data["model_splits"] == {f"run:{single.id}": "single", f"run:{loao.id}": "loao"}
    (facts,) = data["human_maps"]
    assert {k: facts[k] for k in ("frames", "per_activity", "activities", "seed", "practice", "catch", "pilots", "failed_checks", "excluded")} == {
        "frames": 4, "per_activity": 2, "activities": 2, "seed": 3, "practice": 1, "catch": 2, "pilots": 1, "failed_checks": 2, "excluded": False}  # fmt: skip
    assert sorted(facts["rows"]) == sorted(f"participant:{pid}" for pid in people)

    # Shared (the default): every row of an activity on the frames all its rows have, counted here as intersections.
    shared_report = scoring.build_report()
    shared = shared_report.to_methods()
    rows_frames_of = [labelled, by_activity(held_out(single.id)), by_activity(held_out(loao.id)), *seen.values()]
    common = {a: set.intersection(*(f[a] for f in rows_frames_of if a in f)) for a in labelled}
    assert f"(the shared frame mode): {frames_text(sum(map(len, common.values())))} in all ({breakdown(common)})" in shared
    assert "before that cut the models had 3 to 9 frames each, the baselines had 9 frames each and the participants had 4 frames each." in shared
    assert "every labelled frame" not in shared and "scored on the shared frames among the labelled frames" in shared
    assert "the unweighted mean over the three activities with shared frames" in shared
    assert frame_counts(shared) <= table_counts(shared_report)

    # An activity whose rows share no frame drops out of every mean, and the paragraph says so.
    hotel = sorted(labelled["hotel"])
    db.session.execute(db.update(Prediction).where(Prediction.run_id == single.id, Prediction.frame_id == hotel[0]).values(held_out=False))
    db.session.execute(db.update(Prediction).where(Prediction.run_id == loao.id, Prediction.frame_id.in_(hotel[1:])).values(held_out=False))
    db.session.commit()
    apart = scoring.build_report(study_ids=[])
    assert all(c.no_shared_frames for r in apart.rows for a, c in r.cells.items() if a == "hotel")
    text = apart.to_methods()
    assert "Hotel has no frame shared by all rows and is left out of every row's mean." in text
    assert "the unweighted mean over the two activities with shared frames" in text

    # Leaving out who failed a check: how many, in the study's sentence.
    kept = scoring.build_report(frames="each", exclude_failed_checks=True).to_methods()
    assert 'Human study "checks": one participant scored (one pilot participant left out; two participants left out for failing a comprehension or attention check).' in kept


def test_counts_and_frames_read_as_english():
    assert [count(n, "trained model") for n in (0, 1, 2, 9, 10, 56)] == [
        "no trained models", "one trained model", "two trained models", "nine trained models", "10 trained models", "56 trained models"]  # fmt: skip
    assert count(1, "activity", "activities") == "one activity" and count(3, "activity", "activities") == "three activities"
    assert [frames_text(n) for n in (0, 1, 2)] == ["0 frames", "1 frame", "2 frames"]


def test_no_identifier_or_nested_parentheses_in_the_paragraph(ctx, tmp_path):
    the_study(tmp_path)
    make_run("single", held_out=["hotel"], folds="single", seed=1)
    for mode in ("shared", "each"):
        text = scoring.build_report(frames=mode).to_methods().split("\n@inproceedings")[0]
        assert not re.search(r"\b\w+_\w+\b", re.sub(r"\b(t_k|sum_k|R_k|P_k|R_\{k\+1\})", "", text)), mode
        depth = 0
        for ch in text:
            depth += {"(": 1, ")": -1}.get(ch, 0)
            assert depth <= 1, f"nested parentheses in the {mode} paragraph"
        assert depth == 0 and "1 frames" not in text and "1 trained model" not in text


def test_the_human_study_table_mode_is_easy_to_find(app, admin_client, runner):
    html = admin_client.get("/scores/").get_data(as_text=True)
    link = re.search(r'<a href="([^"]+)" id="human-study-table">Human-study table \(people on their own frames\)</a>', html)
    assert link and "frames=each" in link.group(1) and "a human-study table: each person on their own frames" in html
    assert 'id="human-study-table"' not in admin_client.get("/scores/?chosen=1&baselines=1&frames=each").get_data(as_text=True)
    for command in ("score", "report"):
        help_text = " ".join(runner.invoke(args=["egonet", command, "--help"]).output.split())
        assert "the mode a human-study table needs: each person on the frames they saw" in help_text, command
    assert "For a human study, give --frames each" in " ".join(runner.invoke(args=["egonet", "report", "--help"]).output.split())
