"""The score table written out (text, CSV, LaTeX, JSON, figures), the `flask egonet score` command and the Scores pages."""

import csv
import io
import json
import re
import xml.etree.ElementTree as ET

import pytest

from app.extensions import db
from app.models.studies import Participant
from app.services import scoring, studies
from egonet.baselines import BASELINES
from egonet.metrics import MIN_FRAMES
from tests.app.access.studies import build_study
from tests.app.test_scoring import BASELINE_ROWS, add_activity, answer, frames_by_activity, make_run

# --------------------------------------------------------------------------
# Renderers, on a report made by hand


def cell(mf, ap, n=10, *, key="k", ci=True, sd=None, available=None, activities=1):
    """A cell as ``rows`` makes it: an interval from MIN_FRAMES frames, "n too small" below (none without frames)."""
    values = {"max_f": mf, "ap": ap}
    few = 0 < n < MIN_FRAMES
    intervals = {s: ((v - 0.05, v + 0.05) if ci and v is not None and not few else None) for s, v in values.items()}
    return scoring.Cell(n, values, intervals, sd, available if available is not None else n, key, activities, too_few=few)


def curve():
    return scoring.Curve((1.0, 0.5), (0.2, 0.1), 0)


def hand_report() -> scoring.Report:
    """A model and AOP on the same frames; a person on other frames (cooking only); the model's seeds as a group."""

    def make(key, name, kind, cells, mean, **extra):
        return scoring.Row(key, name, kind, "", cells, mean, cell(0.5, None if kind == "human" else 0.4, 20, key="all"),
                           {**{a: curve() for a in cells}, scoring.ALL: curve()}, **extra)  # fmt: skip

    model = make("run:1", "lite_v2 (run 1)", "model", {"cooking": cell(0.40, 0.30, key="c"), "hotel": cell(0.20, 0.10, key="h")},
                 cell(0.30, 0.20, 20, key="m", activities=2), seed=0)  # fmt: skip
    aop = make("baseline:aop", "AOP", "baseline", {"cooking": cell(0.30, 0.35, key="c"), "hotel": cell(0.20, 0.05, key="h")},
               cell(0.25, 0.20, 20, key="m", activities=2))  # fmt: skip
    person = make("participant:1", "P01", "human", {"cooking": cell(0.90, None, 2, key="p"), "hotel": cell(None, None, 0, available=3, key="x")},
                  cell(0.90, None, 2, key="pm"), unanswered=4)  # fmt: skip
    return scoring.Report(activities=["cooking", "hotel"], rows=[model, aop, person], notes=["a note"])


def test_best_is_marked_only_among_rows_on_the_same_frames():
    report = hand_report()
    best = report.best()
    assert best["cooking", "max_f"] == {"run:1": 2}  # P01's 0.90 is on 2 other frames: not compared
    assert best["cooking", "ap"] == {"baseline:aop": 2}
    assert best["hotel", "max_f"] == {"run:1": 2, "baseline:aop": 2}  # a tie: both
    assert set(best["mean", "max_f"]) == {"run:1"} and set(best["mean", "ap"]) == {"run:1", "baseline:aop"}
    assert not any("participant:1" in keys for keys in best.values())
    assert not report.complete(report.rows[2]) and report.complete(report.rows[0]) and report.partial_means()


def test_text_table_puts_n_intervals_and_the_partial_star_on_the_right_cell():
    table = hand_report().to_table()
    lines = table.splitlines()
    assert lines[0].startswith("Metric: pooled") and lines[1].startswith("Frames: shared") and lines[2].startswith("95% CI: ")
    mean_block = lines[lines.index("mean (unweighted over activities)") :]
    p01 = next(line for line in mean_block if line.strip().startswith("P01"))
    # The star marks P01's mean MF (it covers one of two activities), not its AP and not another row.
    assert p01.split() == ["P01", "2", "0.900*", "n", "too", "small", "-"]  # 2 frames: no interval
    assert sum("*" in line for line in mean_block if not line.startswith("*")) == 1
    model = next(line for line in lines[lines.index("cooking") :] if line.strip().startswith("lite_v2"))
    assert model.split() == ["lite_v2", "(run", "1)", "10", "0.400", "[0.350,", "0.450]", "0.300", "[0.250,", "0.350]", "<-", "best", "MF"]
    hotel = lines[lines.index("hotel") :]
    assert any(line.split()[:2] == ["P01", "0"] and "no shared frames (this row has 3 here)" in line for line in hotel)
    assert "* mean over the activities that row has frames in." in table
    assert "Unanswered trials (scored as empty maps): P01 4." in table and "a note" in table


def test_latex_is_table_2_shaped_with_intervals_and_the_best_in_bold():
    tex = hand_report().to_latex()
    assert tex.startswith("% Metric: pooled") and "\\begin{tabular}{lcccccc}" in tex and "\\bottomrule" in tex
    assert "\\multicolumn{2}{c}{cooking} & \\multicolumn{2}{c}{hotel} & \\multicolumn{2}{c}{mean}" in tex
    lines = {line.split(" & ")[0]: line for line in tex.splitlines() if " & " in line and not line.startswith(" ")}
    assert lines["lite\\_v2 (run 1)"].split(" & ")[1] == "\\textbf{0.400} {\\scriptsize[0.350, 0.450]} {\\scriptsize $n$=10}"
    assert lines["AOP"].split(" & ")[2] == "\\textbf{0.350} {\\scriptsize[0.300, 0.400]}"
    p01 = lines["P01"].split(" & ")
    assert p01[1] == "0.900 {\\scriptsize ($n$ too small)} {\\scriptsize $n$=2}" and p01[2] == "--"  # not bold: other frames
    assert p01[3] == "{\\scriptsize no shared frames}" and p01[5].startswith("0.900$^*$")
    assert tex.count("\\midrule") == 3  # one per group


def test_csv_and_json_carry_n_and_intervals():
    report = hand_report()
    rows = list(csv.reader(io.StringIO(report.to_csv())))
    assert rows[0][:9] == ["key", "method", "kind", "group", "metric", "frames", "unanswered", "cooking frames", "cooking n too small"]
    assert rows[0][9:15] == ["cooking MF", "cooking MF lo", "cooking MF hi", "cooking AP", "cooking AP lo", "cooking AP hi"]
    line = dict(zip(rows[0], rows[1]))
    assert (line["key"], line["metric"], line["frames"], line["cooking frames"], line["cooking MF"]) == ("run:1", "pooled", "shared", "10", "0.4000")
    assert (line["cooking MF lo"], line["cooking MF hi"], line["mean MF"], line["mean over activities"]) == ("0.3500", "0.4500", "0.3000", "2")
    person = dict(zip(rows[0], rows[3]))
    assert (person["unanswered"], person["hotel frames"], person["hotel MF"], person["cooking AP"]) == ("4", "0", "", "")
    assert (person["cooking MF"], person["cooking MF lo"], person["cooking n too small"], line["cooking n too small"]) == ("0.9000", "", "1", "0")

    data = json.loads(report.to_json())
    assert (data["frames"], data["metric"], data["answered_only"]) == ("shared", "pooled", False)
    assert data["statistics"] == {"max_f": "MF", "ap": "AP"} and data["ci"]["resamples"] == 1000
    assert list(data)[:2] == ["frames", "metric"]  # what the numbers are, first
    first = data["rows"][0]
    assert first["cells"]["cooking"] == {
        "max_f": 0.4, "max_f_ci": [0.35000000000000003, 0.45], "ap": 0.3, "ap_ci": [0.25, 0.35],
        "n_frames": 10, "frames_available": 10, "no_shared_frames": False, "too_few_frames": False,
    }  # fmt: skip
    assert first["mean"]["activities"] == 2 and first["curves"]["all"]["precision"] == [1.0, 0.5] and first["seed"] == 0
    person = data["rows"][2]
    assert person["unanswered"] == 4 and person["cells"]["cooking"]["ap"] is None and person["cells"]["cooking"]["ap_ci"] is None
    assert person["cells"]["cooking"]["max_f"] == 0.9 and person["cells"]["cooking"]["max_f_ci"] is None and person["cells"]["cooking"]["too_few_frames"]
    assert person["cells"]["hotel"] == {"max_f": None, "max_f_ci": None, "ap": None, "ap_ci": None, "n_frames": 0,
                                         "frames_available": 3, "no_shared_frames": True, "too_few_frames": False}  # fmt: skip
    assert "unweighted mean" in data["definition"] and "bootstrap" in data["definition"]


PROVENANCE = scoring.Provenance(
    metric="ois-mean", empty_frames={"cooking": 2, "hotel": 0}, resamples=1000, seed=7,
    human_maps=(scoring.HumanMaps('study 1 "pilot"', "hierarchical superpixel regions", "a standard deviation of 60 px"),),
    code_version="egonet-studio 0.1.0 (git abc1234)",
)  # fmt: skip


def test_every_format_says_how_the_table_was_made():
    report = hand_report()
    report.provenance = PROVENANCE
    facts = dict(PROVENANCE.facts())
    assert list(facts) == ["Metric", "Frames", "95% CI", "Frames without action-object pixels", "Training set", "Columns",
                           "People's maps", "Code"]
    assert facts["Training set"].startswith("per row: each model on its own held-out frames") and facts["Columns"].startswith("activities")
    assert facts["Metric"].startswith("ois-mean - OIS-mean: the mean over frames") and "99 thresholds t_k = k/100" in facts["Metric"]
    assert facts["95% CI"].startswith("BCa (bias-corrected and accelerated) bootstrap over frames") and "1000 resamples, seed 7; none (n too small) where an activity has fewer than 10 frames; not paired" in facts["95% CI"]
    assert facts["Frames without action-object pixels"] == "2 (cooking 2); policy leave-out: left out of the per-frame means (our choice: the paper does not say)"
    assert facts["People's maps"] == 'study 1 "pilot": hierarchical superpixel regions; click Gaussians of a standard deviation of 60 px'

    text = report.to_table()
    assert all(f"{label}: {fact}." in text for label, fact in facts.items())
    tex = report.to_latex()
    assert "% Code: egonet-studio 0.1.0 (git abc1234)." in tex and "% Frames without action-object pixels: 2 (cooking 2); policy leave-out" in tex
    rows = list(csv.DictReader(io.StringIO(report.to_csv())))
    assert {(r["metric"], r["thresholds"], r["empty frames policy"], r["empty frames"], r["resamples"], r["bootstrap seed"], r["ci"],
             r["paired"], r["code version"]) for r in rows} == {("ois-mean", "99", "leave-out", "2", "1000", "7", "BCa 95%", "0",
                                                                "egonet-studio 0.1.0 (git abc1234)")}  # fmt: skip
    assert rows[0]["people's maps"].startswith('study 1 "pilot": hierarchical superpixel regions')
    data = json.loads(report.to_json())
    assert list(data)[:2] == ["frames", "metric"] and data["code_version"] == "egonet-studio 0.1.0 (git abc1234)"
    assert data["empty_frames"] == {"policy": "leave-out", "count": 2, "by_activity": {"cooking": 2, "hotel": 0}, "applies": True,
                                    "means": scoring.EMPTY_TITLES["leave-out"]}  # fmt: skip
    assert data["ci"] == {"level": 0.95, "method": scoring.provenance.CI_METHOD, "resamples": 1000, "seed": 7, "paired": False, "p_floor": 1 / 1001,
                          "min_frames": MIN_FRAMES}
    assert data["human_maps"][0]["sigma"] == "a standard deviation of 60 px" and len(data["threshold_values"]) == 99


def hand_comparison(p_values: tuple[float, float], resamples: int) -> scoring.Comparison:
    """Run 1 minus AOP: cooking's difference at the floor of ``resamples``, the mean's not."""
    cooking = {"max_f": scoring.Difference(0.1, (0.05, 0.15), p_values[0], 10), "ap": scoring.Difference(-0.05, (-0.1, 0.0), 0.05, 10)}
    mean = {"max_f": scoring.Difference(0.05, (0.0, 0.1), p_values[1], 20), "ap": scoring.Difference(0.0, (-0.05, 0.05), 1.0, 20)}
    provenance = scoring.Provenance(resamples=resamples, paired=True, code_version="v")
    return scoring.Comparison(("run:1", "lite"), ("baseline:aop", "AOP"), ("max_f", "ap"), {"cooking": cooking}, mean, provenance)


def test_p_values_at_the_floor_say_so_in_every_format():
    assert [scoring.p_text(p, b) for p, b in ((1 / 1001, 1000), (1 / 101, 100), (1 / 5001, 5000), (0.0005, 100_000), (0.0234, 1000), (None, 0))] == [
        "< 0.001", "< 0.01", "< 0.0002", "0.0005", "0.023", "-"]  # fmt: skip
    comparison = hand_comparison((1 / 1001, 0.0234), 1000)
    text = comparison.to_text()
    assert "MF difference (mean over activities) +0.050 [+0.000, +0.100] p = 0.023 (20 frames)." in text
    assert re.search(r"^cooking\s+10\s+\+0\.100\s+\[\+0\.050, \+0\.150\]\s+< 0\.001", text, re.M) and "0.001 " not in text.replace("< 0.001", "")
    assert "paired: both rows on the same resamples of the frames they share; p two-sided, written < 0.001 at its floor 1/(B+1)" in text
    rows = list(csv.DictReader(io.StringIO(comparison.to_csv())))
    assert [(r["activity"], r["statistic"], r["p"]) for r in rows] == [("cooking", "MF", "< 0.001"), ("cooking", "AP", "0.050"),
                                                                      ("mean", "MF", "0.023"), ("mean", "AP", "1.000")]  # fmt: skip
    assert rows[0]["paired"] == "1" and rows[0]["code version"] == "v"
    assert "cooking & 10 & +0.100 & [+0.050, +0.150] & $< 0.001$" in comparison.to_latex()
    data = json.loads(comparison.to_json())
    assert data["activities"]["cooking"]["max_f"]["p_text"] == "< 0.001" and data["activities"]["cooking"]["max_f"]["p_value"] == 1 / 1001
    assert data["p_text"] == "0.023" and data["ci"] == [0.0, 0.1] and data["bootstrap"]["paired"] is True and data["bootstrap"]["p_floor"] == 1 / 1001
    # With more resamples the floor moves down, and so does what is printed.
    assert "< 0.0002" in hand_comparison((1 / 5001, 0.5), 5000).to_text()


def test_empty_report_renders():
    empty = scoring.Report(activities=[], rows=[])
    assert "nothing to score" in empty.to_table()
    header = list(csv.reader(io.StringIO(empty.to_csv())))[0]
    assert header[header.index("mean over activities") - 2 :][:3] == ["mean AP lo", "mean AP hi", "mean over activities"]
    assert "\\begin{tabular}{lcc}" in empty.to_latex()
    assert json.loads(empty.to_json())["rows"] == []


def test_pr_plot_maps_curves_to_svg_coordinates_and_draws_the_chosen_rows():
    report = hand_report()
    plot = scoring.pr_plot(report, "cooking", width=300, height=270)
    left, top, right, bottom = scoring.PLOT_MARGIN
    assert [line.name for line in plot.lines] == ["lite_v2 (run 1)", "AOP", "P01"]
    first = plot.lines[0]
    # (recall 0.2, precision 1.0) then (0.1, 0.5)
    sx, sy = 300 - left - right, 270 - top - bottom
    assert first.points == f"{round(left + 0.2 * sx, 1)},{float(top)} {round(left + 0.1 * sx, 1)},{round(top + 0.5 * sy, 1)}"
    assert (first.best_x, first.best_y) == (round(left + 0.2 * sx, 1), float(top))
    assert plot.lines[2].dashed and not first.dashed and first.row == "run:1"
    assert "pooled F 0.333" in first.best_label and "(10 frames)" in first.best_label
    assert all(line.shown for line in plot.lines)  # a few people: all drawn by default
    chosen = scoring.pr_plot(report, "cooking", rows={"baseline:aop"})
    assert [line.shown for line in chosen.lines] == [False, True, False]
    assert len(plot.iso_f) == 4 and plot.title == "cooking"
    assert scoring.pr_plot(report, scoring.ALL).title == "All activities (pooled)"


def test_pr_figure_is_an_svg_or_pdf_of_the_chosen_rows():
    report = hand_report()
    svg = scoring.pr_figure(report, "cooking", rows={"run:1", "participant:1"}, file_format="svg")
    root = ET.fromstring(svg)
    text = " ".join(t.text or "" for t in root.iter("{http://www.w3.org/2000/svg}text"))
    assert "lite_v2 (run 1) (n=10)" in text and "P01 (n=2)" in text and "AOP" not in text
    assert "cooking (pooled curves)" in text and "Recall" in text
    pdf = scoring.pr_figure(report, scoring.ALL, file_format="pdf")
    assert pdf.startswith(b"%PDF") and b"/FontFile2" in pdf  # TrueType fonts embedded, not Type 3


# --------------------------------------------------------------------------
# CLI


def test_score_command_prints_each_format_and_view(ctx, runner, tmp_path):
    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1)
    answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))

    result = runner.invoke(args=["egonet", "score"])
    assert result.exit_code == 0, result.output
    table = result.stdout
    assert table.startswith("Metric: pooled") and "Frames: shared" in table
    assert "AOP" in table and "centre prior" in table and "saliency" in table and "P01" in table and "95% CI" in table

    result = runner.invoke(args=["egonet", "score", "--format", "csv", "--runs", "", "--studies", str(ids["study"])])
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(io.StringIO(result.stdout)))  # stdout holds the CSV only
    assert [r[1] for r in rows[1:]] == [*BASELINE_ROWS, "P01"]

    result = runner.invoke(args=["egonet", "score", "--format", "latex", "--no-baselines"])
    assert result.exit_code == 0 and "\\begin{tabular}" in result.stdout and "AOP" not in result.stdout

    args = ["egonet", "score", "--format", "json", "--studies", "", "--thresholds", "19", "--metric", "ods-ois", "--frames", "each", "--no-cache"]
    data = json.loads(runner.invoke(args=args).stdout)
    assert (data["frames"], data["metric"], data["thresholds"]) == ("each", "ods-ois", 19)
    assert [r["key"] for r in data["rows"]] == [f"baseline:{key}" for key in BASELINES]
    assert set(data["rows"][0]["cells"]["cooking"]) >= {"max_f", "max_f_ci", "ois", "ois_ci", "ap", "ap_ci", "n_frames"}

    data = json.loads(runner.invoke(args=["egonet", "score", "--format", "json", "--resamples", "0", "--answered-only"]).stdout)
    assert data["ci"]["resamples"] == 0 and data["answered_only"] is True
    assert data["rows"][0]["cells"]["cooking"]["max_f_ci"] is None

    report = scoring.build_report(run_ids=[], study_ids=[ids["study"]])
    assert runner.invoke(args=["egonet", "score", "--format", "csv"]).stdout == report.to_csv()


@pytest.mark.one_database
def test_score_command_compares_two_rows(ctx, runner):
    add_activity("cooking", n=MIN_FRAMES, seed=1)
    add_activity("hotel", n=MIN_FRAMES, seed=2)
    result = runner.invoke(args=["egonet", "score", "--compare", "baseline:center", "baseline:saliency", "--format", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert (data["a"]["key"], data["b"]["key"], data["metric"], data["statistic"]) == ("baseline:center", "baseline:saliency", "pooled", "max_f")
    report = scoring.build_report(run_ids=[], study_ids=[])
    mean = {r.key: r.mean.max_f for r in report.rows}
    assert data["difference"] == pytest.approx(mean["baseline:center"] - mean["baseline:saliency"], abs=1e-12)
    assert 0 < data["p_value"] <= 1 and data["ci"][0] <= data["difference"] <= data["ci"][1] and data["n_frames"] == 2 * MIN_FRAMES
    assert set(data["activities"]) == {"cooking", "hotel"} and set(data["mean"]) == {"max_f", "ap"}
    same = json.loads(runner.invoke(args=["egonet", "score", "--compare", "baseline:aop", "baseline:aop", "--format", "json"]).stdout)
    assert same["difference"] == 0 and same["p_value"] == 1.0
    text = runner.invoke(args=["egonet", "score", "--compare", "baseline:center", "baseline:saliency", "--metric", "ois-mean"]).stdout
    assert text.startswith("centre prior [baseline:center] minus saliency [baseline:saliency]")
    assert re.search(r"difference \(mean over activities\) [+-]\d\.\d{3} \[.*\] p (= \d\.\d{3}|< 0\.001) \(20 frames\)", text)
    assert "mean F diff" in text and "ois-mean" in text


@pytest.mark.one_database
def test_p_values_at_the_floor_on_the_page_and_in_every_download_and_more_resamples_lower_it(ctx, runner, admin_client):
    add_activity("cooking", n=MIN_FRAMES, seed=1)
    add_activity("hotel", n=MIN_FRAMES, seed=2)
    compare = ["egonet", "score", "--compare", "baseline:gbvs", "baseline:handled"]  # a large difference: p at the floor
    floors = {"table": "p < 0.001 (20 frames)", "csv": ",< 0.001,", "latex": "$< 0.001$", "json": '"p_text": "< 0.001"'}
    for fmt, floor in floors.items():
        result = runner.invoke(args=[*compare, "--format", fmt])
        assert result.exit_code == 0 and floor in result.stdout, fmt
    query = "compare_a=baseline:gbvs&compare_b=baseline:handled"
    assert 'class="p-value">p &lt; 0.001<' in admin_client.get(f"/scores/?{query}").get_data(as_text=True)
    for fmt, floor in (("csv", ",< 0.001,"), ("tex", "$< 0.001$"), ("json", '"p_text": "< 0.001"')):
        with admin_client.get(f"/scores/comparison.{fmt}?{query}") as response:
            assert response.status_code == 200 and floor in response.get_data(as_text=True), fmt
            assert f'filename="comparison.{fmt}"' in response.headers["Content-Disposition"]
    data = json.loads(runner.invoke(args=[*compare, "--format", "json", "--resamples", "20000"]).stdout)
    assert data["p_text"] == "< 0.00005" and data["bootstrap"]["resamples"] == 20000 and data["p_value"] == pytest.approx(1 / 20001)


@pytest.mark.one_database
def test_below_min_frames_a_cell_or_difference_says_n_too_small_in_every_format(ctx, runner):
    """1 and MIN_FRAMES - 1 frames: the estimate, "n too small", no interval and no p-value; MIN_FRAMES frames: an interval."""
    add_activity("cooking", n=1, seed=1)
    add_activity("hotel", n=MIN_FRAMES - 1, seed=2)
    add_activity("desk work", n=MIN_FRAMES, seed=3)
    report = scoring.build_report(run_ids=[], study_ids=[])
    centre = report.row("baseline:center")
    counted = {a: len(fs) for a, fs in frames_by_activity().items()}  # counted here, not by the report
    assert {a: c.n_frames for a, c in centre.cells.items()} == counted == {"cooking": 1, "hotel": 9, "desk work": 10}
    for activity, few in (("cooking", True), ("hotel", True), ("desk work", False)):
        got = centre.cells[activity]
        assert got.max_f is not None and got.too_few is few and (got.ci["max_f"] is None) is few, activity
    assert centre.mean.too_few and centre.mean.ci["max_f"] is None and centre.mean.max_f is not None  # two activities below

    text = report.to_table().splitlines()
    line = next(x for x in text[text.index("cooking") :] if x.strip().startswith("centre prior"))
    assert line.split()[2:] == ["1", f"{centre.cells['cooking'].max_f:.3f}", "n", "too", "small", f"{centre.cells['cooking'].ap:.3f}", "n", "too", "small"]
    rows = {r["key"]: r for r in csv.DictReader(io.StringIO(report.to_csv()))}
    assert (rows["baseline:center"]["cooking n too small"], rows["baseline:center"]["cooking MF lo"]) == ("1", "")
    assert rows["baseline:center"]["desk work n too small"] == "0" and rows["baseline:center"]["desk work MF lo"] != ""
    assert rows["baseline:center"]["mean n too small"] == "1" and rows["baseline:center"]["min frames"] == str(MIN_FRAMES)
    assert "($n$ too small)" in report.to_latex()
    cells = next(r for r in json.loads(report.to_json())["rows"] if r["key"] == "baseline:center")["cells"]
    assert cells["cooking"]["too_few_frames"] and cells["cooking"]["max_f_ci"] is None and not cells["desk work"]["too_few_frames"]

    compare = ["egonet", "score", "--compare", "baseline:center", "baseline:saliency"]
    text = runner.invoke(args=compare).stdout
    assert "MF difference (mean over activities)" in text and "(20 frames): n too small for an interval or p-value (fewer than 10 frames in an activity)" in text
    cooking = next(x for x in text.splitlines() if x.startswith("cooking"))
    assert "n too small" in cooking and "[" not in cooking and "<" not in cooking  # was "[+x, +x] < 0.001" on one frame
    data = json.loads(runner.invoke(args=[*compare, "--format", "json"]).stdout)
    assert data["too_few_frames"] and data["p_value"] is None and data["ci"] is None and data["n_frames"] == 20
    assert data["activities"]["cooking"]["max_f"]["too_few_frames"] and not data["activities"]["desk work"]["max_f"]["too_few_frames"]
    assert data["activities"]["desk work"]["max_f"]["p_value"] is not None
    by_activity = {(r["activity"], r["statistic"]): r for r in csv.DictReader(io.StringIO(runner.invoke(args=[*compare, "--format", "csv"]).stdout))}
    assert (by_activity["cooking", "MF"]["n too small"], by_activity["cooking", "MF"]["lo"], by_activity["cooking", "MF"]["p"]) == ("1", "", "")
    assert by_activity["desk work", "MF"]["n too small"] == "0" and by_activity["desk work", "MF"]["lo"] != ""
    assert re.search(r"^cooking & 1 & [+-]\d\.\d{3} & n too small & -- ", runner.invoke(args=[*compare, "--format", "latex"]).stdout, re.M)


def test_report_command_writes_the_facts_or_a_methods_paragraph(ctx, runner, tmp_path):
    from app.version import code_version

    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1, sigma_px=6.0)
    answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
    result = runner.invoke(args=["egonet", "report", "--metric", "per-image"])
    assert result.exit_code == 0, result.output
    assert "--metric per-image is deprecated and goes in the next release: use --metric ois-mean" in result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("Metric: ois-mean - OIS-mean") and lines[3].startswith("Frames without action-object pixels: none; policy leave-out")
    assert f'People\'s maps: study {ids["study"]} "' in result.stdout and "click Gaussians of a standard deviation of 6 px" in result.stdout
    assert lines[-1] == f"Code: {code_version()}." and code_version().startswith("egonet-studio ")

    out = tmp_path / "methods.txt"
    result = runner.invoke(args=["egonet", "report", "--methods", "--resamples", "2000", "--seed", "4", "--out", str(out)])
    assert result.exit_code == 0 and result.stdout == "" and f"written: {out}" in result.stderr
    text = out.read_text()
    report = scoring.build_report(resamples=2000, seed=4)
    frames = report.frames_per_activity()
    assert f"(the shared frame mode): {sum(frames.values())} frames in all (cooking {frames['cooking']}, hotel {frames['hotel']})" in text
    assert "T = 99 thresholds t_k = k/100" in text and "The convention is pooled: max F and AP of the pixel counts" in text
    assert "bias-corrected and accelerated (BCa) bootstrap intervals over frames" in text and "B = 2000 resamples (seed 4)" in text
    assert "reported as p < 0.0005" in text and "scored on the shared frames among the labelled frames" in text
    assert "FP-MCG and salObj+depth were fitted per fold under leave-one-activity-out" in text
    assert 'Human study "test study": one participant scored.' in text
    assert "Each click becomes a Gaussian with a standard deviation of 6 px" in text and f"computed with {code_version()}." in text
    assert "@inproceedings{bertasius2017egonet," in text and "title     = {First-Person Action-Object Detection with {EgoNet}}," in text
    assert "author    = {Gedas Bertasius and Hyun Soo Park and Stella X. Yu and Jianbo Shi}" in text and "year      = {2017}" in text


def test_score_command_errors_are_one_line(ctx, runner):
    result = runner.invoke(args=["egonet", "score", "--studies", "12"])
    assert result.exit_code == 1
    assert [line for line in result.output.splitlines() if line.startswith("Error:")] == ["Error: study 12 does not exist"]
    add_activity("cooking")
    result = runner.invoke(args=["egonet", "score", "--compare", "baseline:center", "run:4"])
    assert result.exit_code == 1 and "Error: compare: there is no row 'run:4' in this table" in result.output
    for args, option in ((["--runs", "x"], "--runs"), (["--format", "xml"], "--format"), (["--thresholds", "0"], "--thresholds"),
                         (["--metric", "mean"], "--metric"), (["--frames", "all"], "--frames"), (["--resamples", "-1"], "--resamples"),
                         (["--compare", "a"], "--compare")):  # fmt: skip
        result = runner.invoke(args=["egonet", "score", *args])
        assert result.exit_code == 2 and option in result.output, args
    result = runner.invoke(args=["egonet", "score", "--empty-frames", "none"])
    assert result.exit_code == 2 and "--empty-frames" in result.output
    result = runner.invoke(args=["egonet", "score", "--resamples", "100000", "--format", "csv"])  # 6 frames x 100,000: fits
    assert result.exit_code == 0, result.output


# --------------------------------------------------------------------------
# The pages


def test_scores_page_shows_the_tables_switches_comparison_plots_and_downloads(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1)
        answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
        run_id = make_run("lite", held_out=["cooking"]).id
    html = admin_client.get("/scores/").get_data(as_text=True)
    assert 'id="score-table-max_f"' in html and 'id="score-table-ap"' in html and "<polyline" in html
    for name in (f"egonet-lite (run {run_id})", "AOP", "centre prior", "saliency", "P01"):
        assert name in html
    assert "Pooled: max F and AP of the pixel counts summed over all frames of an activity" in html  # the convention, up front
    assert 'name="metric" value="pooled" checked' in html and 'name="frames" value="shared" checked' in html
    assert 'name="empty" value="leave-out" checked' in html and 'value="mean-curve"' in html and 'value="per-image"' not in html
    assert '<details class="provenance" id="provenance">' in html and "<dt>Code</dt><dd>egonet-studio " in html
    assert "<dt>Frames without action-object pixels</dt><dd>none; pooled counts their false positives" in html
    assert html.count('class="pr-plot"') == 3  # all activities, cooking, hotel
    assert "0 unanswered" in html and 'class="ci too-few"' in html and "n 2" in html and 'class="ci"' not in html  # 2 frames: n too small
    assert f'name="studies" value="{ids["study"]}" checked' in html and f'name="runs" value="{run_id}" checked' in html
    assert f"/scores/table.csv?chosen=1&amp;runs={run_id}&amp;studies={ids['study']}&amp;metric=pooled&amp;frames=shared&amp;empty=leave-out&amp;baselines=1" in html

    html = admin_client.get(f"/scores/?chosen=1&baselines=1&metric=ods-ois&frames=each&studies={ids['study']}").get_data(as_text=True)
    assert 'id="score-table-ois"' in html and 'name="metric" value="ods-ois" checked' in html and 'name="frames" value="each" checked' in html
    assert "BSDS ODS / OIS" in html and "all frames each row has" in html

    page = admin_client.get("/scores/?compare_a=baseline:center&compare_b=baseline:saliency")
    html = page.get_data(as_text=True)
    assert 'id="comparison"' in html and "centre prior minus saliency" in html
    # 3 frames an activity: the difference without an interval or a p-value, and the page says why.
    assert '<strong class="too-few">n too small</strong> for an interval or p-value: 6 shared frames, fewer than 10 in an activity' in html
    assert 'class="p-value"' not in html and "Fewer than 10 shared frames in cooking, hotel" in html
    assert '<option value="baseline:center" selected>' in html

    page = admin_client.get("/scores/?chosen=1")  # nothing ticked: no rows
    assert page.status_code == 200 and "Nothing to score yet" in page.get_data(as_text=True)
    html = admin_client.get(f"/scores/?chosen=1&studies={ids['study']}").get_data(as_text=True)
    assert 'data-row="participant:' in html and 'data-row="baseline:aop"' not in html

    with admin_client.get(f"/scores/table.csv?chosen=1&baselines=1&studies={ids['study']}&metric=per-image") as response:
        assert response.status_code == 200 and response.mimetype == "text/csv"
        assert 'filename="scores.csv"' in response.headers["Content-Disposition"]
        rows = list(csv.reader(io.StringIO(response.get_data(as_text=True))))
        # The old name still works for a release: it is ois-mean, and the download says so.
        assert [r[1] for r in rows[1:]] == [*BASELINE_ROWS, "P01"] and rows[1][4] == "ois-mean"
    with admin_client.get("/scores/table.tex") as response:
        assert response.status_code == 200 and "\\begin{tabular}" in response.get_data(as_text=True)
    with admin_client.get("/scores/table.json?compare_a=baseline:aop&compare_b=baseline:center") as response:
        data = json.loads(response.get_data(as_text=True))
        assert data["rows"] and data["comparison"]["b"]["key"] == "baseline:center"


def test_figures_and_per_image_scores(app, admin_client):
    with app.app_context():
        add_activity("cooking", seed=1)
        add_activity("hotel", seed=2)
    with admin_client.get("/scores/figure.svg?plotted=1&plot=baseline:aop&activity=hotel") as response:
        assert response.status_code == 200 and response.mimetype == "image/svg+xml"
        assert 'filename="pr-hotel.svg"' in response.headers["Content-Disposition"]
        svg = response.get_data(as_text=True)
        assert "AOP (n=3)" in svg and "saliency" not in svg
    with admin_client.get("/scores/figure.pdf") as response:
        assert response.status_code == 200 and response.data.startswith(b"%PDF")

    html = admin_client.get("/scores/frames?activity=hotel&sort=baseline:saliency").get_data(as_text=True)
    assert 'id="frame-table"' in html and html.count('<tr data-frame="') == 3 and "take #0" in html
    with app.app_context():
        table = scoring.frame_table(activity="hotel", sort="baseline:saliency")
    saliency = [line.scores["baseline:saliency"][0] for line in table.lines]
    assert saliency == sorted(saliency)  # lowest F first
    order = [line.frame_id for line in table.lines]
    assert [int(m) for m in re.findall(r'<tr data-frame="(\d+)"', html)] == order
    with admin_client.get("/scores/frames.csv?activity=hotel") as response:
        rows = list(csv.reader(io.StringIO(response.get_data(as_text=True))))
        assert rows[0][:6] == ["frame_id", "frame", "activity", "action-object pixels", "empty frames policy", "baseline:judd best F"]
        assert len(rows) == 4 and int(rows[1][3]) > 1 and rows[1][4] == "leave-out"  # a count of pixels, not a flag
        assert 'filename="per-frame-hotel.csv"' in response.headers["Content-Disposition"]


def test_scores_pages_refuse_bad_choices(admin_client):
    page = admin_client.get("/scores/?chosen=1&studies=99")
    assert page.status_code == 400 and "study 99 does not exist" in page.get_data(as_text=True)
    with admin_client.get("/scores/table.csv?chosen=1&runs=abc", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and response.get_json()["fields"] == {"runs": "must be an integer"}
    with admin_client.get("/scores/table.json?chosen=1&runs=5", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and "runs" in response.get_json()["fields"]
    for query, field in (("metric=mean", "metric"), ("frames=most", "frames"), ("compare_a=run:1", "compare_b"),
                         ("compare_a=x&compare_b=y", "compare")):  # fmt: skip
        with admin_client.get(f"/scores/?{query}", headers={"Accept": "application/json"}) as response:
            assert response.status_code == 400 and field in response.get_json()["fields"], query
    with admin_client.get("/scores/figure.svg?activity=nowhere", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and "activity" in response.get_json()["fields"]
    with admin_client.get("/scores/frames?sort=run:7", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and "sort" in response.get_json()["fields"]
    for url in ("/scores/?empty=skip", "/scores/frames?empty=skip", "/scores/comparison.csv"):
        with admin_client.get(url, headers={"Accept": "application/json"}) as response:
            assert response.status_code == 400 and set(response.get_json()["fields"]) & {"empty", "compare_a"}, url
    assert admin_client.get("/scores/table.xml").status_code == 404
    assert admin_client.get("/scores/figure.png").status_code == 404


@pytest.mark.parametrize("role", ["annotator", "reviewer"])
def test_only_admins_see_participants_scores(app, admin_client, client, make_user, tmp_path, role):
    """Review: annotators and reviewers saw every participant's per-activity scores, while the README says they see no
    studies. A participant's scores are the study's research data: its team (admins) only, in the page and every download."""
    with app.app_context():
        ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1)
        answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
    assert "P01" in admin_client.get("/scores/").get_data(as_text=True)
    make_user(role, "staff")
    assert client.login("staff", "correct horse battery").status_code == 302
    page = client.get("/scores/").get_data(as_text=True)
    assert page.count('data-row="baseline:') >= 1 and 'data-row="participant:' not in page and "P01" not in page
    assert 'name="studies"' not in page and "scores are shown to admins only." in page
    for path in ("/scores/table.csv", "/scores/table.json", "/scores/frames?activity=cooking", "/scores/frames.csv?activity=cooking"):
        answer_ = client.get(path)
        assert answer_.status_code == 200 and b"participant" not in answer_.data.lower() and b"P01" not in answer_.data, path
    chosen = f"chosen=1&baselines=1&studies={ids['study']}"
    for path in ("/scores/", "/scores/table.csv", "/scores/figure.svg", "/scores/frames", "/scores/frames.csv"):
        assert client.get(f"{path}?{chosen}").status_code == 403, path
