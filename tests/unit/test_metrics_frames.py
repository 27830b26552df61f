"""egonet.metrics per frame: the four conventions, frames without positives, the bootstrap, the paired test.

Hand-computed small cases, a direct (slow, loop-per-threshold) computation
from tests/unit/test_metrics.py, and a coverage study of the intervals.
"""

import numpy as np
import pytest

from egonet.errors import EgonetError
from statistics import NormalDist

from egonet.metrics.bootstrap import MAX_WEIGHTS

from egonet.metrics import (
    METRICS,
    Counts,
    Estimate,
    FrameCounts,
    Resampler,
    count_stats,
    frame_scores,
    jackknife_weights,
    resample_weights,
    p_floor,
    resolve_metric,
    score_frames,
    score_maps,
)
from tests.unit.test_metrics import direct_counts, direct_curve, direct_frame_curve, direct_score, random_maps

# Two frames, T = 3 thresholds (0.25, 0.5, 0.75):
#   A: prob 0.9 0.6 0.4 0.3, mask T F T F (2 positives)
#      t=.25: TP 2 FP 2 -> P 1/2 R 1   F 2/3
#      t=.50: TP 1 FP 1 -> P 1/2 R 1/2 F 1/2
#      t=.75: TP 1 FP 0 -> P 1   R 1/2 F 2/3   best F 2/3 (t=.25 and .75: OIS takes .75)
#      AP = (1 - 1/2) 1/2 + 0 + (1/2) 1 = 3/4
#   B: prob 0.3 0.3, mask T T
#      t=.25: TP 2 FP 0 -> P 1 R 1 F 1; t=.5, .75: nothing predicted -> P 1 R 0 F 0
#      best F 1 at .25; AP = 1
# pooled: t=.25 TP 4 FP 2 (4 positives): P 2/3 R 1 F 4/5; t=.5 TP 1 FP 1: P 1/2 R 1/4 F 1/3;
#         t=.75 TP 1 FP 0: P 1 R 1/4 F 2/5 -> MF 4/5; AP = (3/4)(2/3) + 0 + (1/4) 1 = 3/4
# ois-mean: mean F (2/3 + 1) / 2 = 5/6, mean AP (3/4 + 1) / 2 = 7/8
# mean-curve: P (3/4, 3/4, 1), R (1, 1/4, 1/4): F (6/7, 3/8, 2/5) -> MF 6/7; AP = (3/4)(3/4) + 0 + (1/4) 1 = 13/16
# OIS: A at .75 (TP 1, FP 0) + B at .25 (TP 2, FP 0) = TP 3 FP 0 of 4: P 1 R 3/4 F 6/7
A = (np.array([[0.9, 0.6, 0.4, 0.3]]), np.array([[True, False, True, False]]))
B = (np.array([[0.3, 0.3]]), np.array([[True, True]]))


def two_frames() -> FrameCounts:
    return FrameCounts.stack([count_stats(*A, thresholds=3), count_stats(*B, thresholds=3)])


def scalar(scores: dict) -> dict:
    return {k: float(v[0]) for k, v in scores.items()}


def test_two_frames_by_hand():
    counts = two_frames()
    np.testing.assert_array_equal(counts.tp, [[2, 1, 1], [2, 0, 0]])
    np.testing.assert_array_equal(counts.fp, [[2, 1, 0], [0, 0, 0]])
    np.testing.assert_array_equal(counts.positives, [2, 2])
    assert scalar(score_frames(counts, metric="pooled")) == pytest.approx({"max_f": 4 / 5, "ap": 3 / 4}, abs=1e-15)
    assert scalar(score_frames(counts, metric="ois-mean")) == pytest.approx({"max_f": 5 / 6, "ap": 7 / 8}, abs=1e-15)
    assert scalar(score_frames(counts, metric="mean-curve")) == pytest.approx({"max_f": 6 / 7, "ap": 13 / 16}, abs=1e-15)
    assert scalar(score_frames(counts, metric="ods-ois")) == pytest.approx({"max_f": 4 / 5, "ap": 3 / 4, "ois": 6 / 7}, abs=1e-15)
    own = frame_scores(counts)
    np.testing.assert_allclose(own["max_f"], [2 / 3, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(own["ap"], [3 / 4, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(own["best"], [2, 0])  # A: the highest of its tied thresholds


def test_pooled_is_score_maps():
    rng = np.random.default_rng(11)
    probs, masks = random_maps(rng, np.float32, 99, n=6)
    counts = FrameCounts.stack([count_stats(p, m) for p, m in zip(probs, masks)])
    got = scalar(score_frames(counts))
    expected = score_maps(probs, masks)
    assert got == {"max_f": expected.max_f, "ap": expected.ap}  # exactly the same arithmetic


def direct_conventions(probs, masks, thresholds, beta2, empty):
    """Every convention computed frame by frame with one comparison per threshold (no histograms, no weights)."""
    per_frame = [direct_counts(p, m, thresholds) for p, m in zip(probs, masks)]

    def f_of(p, r):
        return np.array([(1 + beta2) * a * b / (beta2 * a + b) if a + b > 0 else 0.0 for a, b in zip(p, r)])

    def ap_of(p, r):
        return sum((r[k] - (r[k + 1] if k + 1 < len(r) else 0.0)) * p[k] for k in range(len(r)))

    best_f, aps, at_best = [], [], []
    for tp, fp, fn in per_frame:
        own = direct_frame_curve(tp, fp, fn, empty)
        if own is not None:
            best_f.append(f_of(*own).max())
            aps.append(ap_of(*own))
        f = f_of(*direct_curve(tp, fp, fn))
        k = max(i for i in range(thresholds) if f[i] == f.max())  # the highest threshold on ties
        at_best.append((tp[k], fp[k], fn[k]))
    p, r = direct_curve(*(sum(c[i] for c in per_frame) for i in range(3)))
    tp, fp, fn = (sum(c[i] for c in at_best) for i in range(3))
    p_ois = tp / (tp + fp) if tp + fp else 1.0
    r_ois = tp / (tp + fn) if tp + fn else 0.0
    return {
        "pooled": {"max_f": f_of(p, r).max(), "ap": ap_of(p, r)},
        "ois-mean": {"max_f": np.mean(best_f), "ap": np.mean(aps)},
        "mean-curve": dict(zip(("max_f", "ap"), direct_score(probs, masks, thresholds, beta2, "mean-curve", empty)[2:])),
        "ods-ois": {"max_f": f_of(p, r).max(), "ap": ap_of(p, r), "ois": f_of([p_ois], [r_ois])[0]},
    }


@pytest.mark.parametrize(("thresholds", "beta2", "empty"), [(99, 1.0, "leave-out"), (7, 0.3, "zero"), (255, 2.0, "one-if-empty")])
def test_conventions_match_a_direct_computation(thresholds, beta2, empty):
    rng = np.random.default_rng(thresholds)
    probs, masks = random_maps(rng, np.float32, thresholds, n=7)  # one map without positives
    counts = FrameCounts.stack([count_stats(p, m, thresholds=thresholds) for p, m in zip(probs, masks)])
    expected = direct_conventions(probs, masks, thresholds, beta2, empty)
    expected["mean-curve"]["max_f"] = expected["mean-curve"]["max_f"].max()
    for metric in METRICS:
        got = scalar(score_frames(counts, metric=metric, beta2=beta2, empty=empty))
        assert got == pytest.approx(expected[metric], abs=1e-12), metric


@pytest.mark.parametrize("metric", list(METRICS))
def test_weights_count_frames_as_repeats(metric):
    rng = np.random.default_rng(5)
    probs, masks = random_maps(rng, np.float64, 99, n=4)
    counts = FrameCounts.stack([count_stats(p, m) for p, m in zip(probs, masks)])
    weights = np.array([[1, 1, 1, 1], [2, 0, 1, 0], [0, 3, 0, 1]], dtype=float)
    got = score_frames(counts, metric=metric, weights=weights)
    for row, w in enumerate(weights):
        repeated = counts.take(np.repeat(np.arange(4), w.astype(int)))
        for key, value in score_frames(repeated, metric=metric).items():
            assert got[key][row] == pytest.approx(value[0], abs=1e-12)


def test_a_frame_without_positives():
    empty = count_stats(np.array([[0.95, 0.2, 0.0]]), np.zeros((1, 3), bool), thresholds=3)
    quiet = count_stats(np.array([[0.3, 0.1, 0.0]]), np.zeros((1, 3), bool), thresholds=3)  # empty from 0.5 up
    own = frame_scores(FrameCounts.stack([empty, quiet]), empty="zero")
    np.testing.assert_array_equal(own["max_f"], [0, 0])
    np.testing.assert_array_equal(own["ap"], [0, 0])
    np.testing.assert_array_equal(own["best"], [2, 2])  # every F is 0: the highest threshold, the fewest false positives
    one = frame_scores(FrameCounts.stack([empty, quiet]), empty="one-if-empty")
    np.testing.assert_array_equal(one["max_f"], [0, 1])  # the map predicts nothing at 0.5 and 0.75
    np.testing.assert_array_equal(one["ap"], [0, 1])
    left = frame_scores(FrameCounts.stack([empty, quiet]))
    assert np.isnan(left["max_f"]).all() and not left["counted"].any()
    counts = FrameCounts.stack([count_stats(*B, thresholds=3), empty, quiet])
    # OIS adds B's counts at 0.25 and the empty frames' at 0.75 (one false positive, 0.95): P 2/3, R 1.
    for policy in ("leave-out", "zero", "one-if-empty"):
        assert scalar(score_frames(counts, metric="ods-ois", empty=policy))["ois"] == pytest.approx(0.8, abs=1e-15)
    mean_f = {policy: scalar(score_frames(counts, metric="ois-mean", empty=policy))["max_f"] for policy in ("leave-out", "zero", "one-if-empty")}
    assert mean_f == pytest.approx({"leave-out": 1.0, "zero": 1 / 3, "one-if-empty": 2 / 3}, abs=1e-15)
    # Left out, a resample of empty frames alone has nothing to average: NaN, not a number made up.
    only_empty = score_frames(counts, metric="mean-curve", weights=np.array([[1.0, 1, 1], [0, 2, 1]]))
    assert only_empty["max_f"][0] == 1.0 and np.isnan(only_empty["max_f"][1])


def test_per_image_is_the_old_name_of_ois_mean(caplog):
    counts = two_frames()
    assert scalar(score_frames(counts, metric="per-image")) == scalar(score_frames(counts, metric="ois-mean"))
    assert "'per-image' is deprecated" in caplog.text and "now called 'ois-mean'" in caplog.text
    assert resolve_metric("per-image") == ("ois-mean", "metric 'per-image' is deprecated and goes in the next release: it is now called 'ois-mean'")
    assert resolve_metric("mean-curve") == ("mean-curve", None) and "per-image" not in METRICS


def test_the_two_per_frame_means_differ():
    # The case in small: the mean of each frame's best F is not the best F of the mean curve.
    rng = np.random.default_rng(27)
    probs, masks = random_maps(rng, np.float32, 99, n=8)
    counts = FrameCounts.stack([count_stats(p, m) for p, m in zip(probs, masks)])
    ois_mean = scalar(score_frames(counts, metric="ois-mean"))["max_f"]
    mean_curve = scalar(score_frames(counts, metric="mean-curve"))["max_f"]
    assert mean_curve == pytest.approx(score_maps(probs, masks, metric="mean-curve").max_f, abs=1e-12)
    assert abs(ois_mean - mean_curve) > 0.003  # 0.450 and 0.447 here; 5/6 and 6/7 in test_two_frames_by_hand


def test_frame_counts_take_pool_and_refuse_bad_counts():
    counts = two_frames()
    assert counts.n == 2 and counts.thresholds == 3
    swapped = counts.take(np.array([1, 0]))
    np.testing.assert_array_equal(swapped.tp, counts.tp[::-1])
    pooled = counts.pooled()
    assert isinstance(pooled, Counts)
    np.testing.assert_array_equal(pooled.tp, [4, 1, 1])
    np.testing.assert_array_equal(pooled.fn, [0, 3, 3])
    both = FrameCounts.concat([counts, swapped], thresholds=3)
    assert both.n == 4 and FrameCounts.concat([], thresholds=3).n == 0
    with pytest.raises(ValueError):
        counts.tp[0, 0] = 5  # read-only
    with pytest.raises(EgonetError, match=r"\(N, T\)") as info:
        FrameCounts(np.zeros((2, 3)), np.zeros((2, 4)), np.zeros(2))
    assert info.value.field == "counts"
    with pytest.raises(EgonetError, match="more true positives"):
        FrameCounts(np.full((1, 3), 5), np.zeros((1, 3)), np.array([4]))
    with pytest.raises(EgonetError, match="give thresholds"):
        FrameCounts.stack([])
    with pytest.raises(EgonetError, match="must have 4 thresholds"):
        FrameCounts.concat([counts], thresholds=4)


def test_score_frames_refuses_bad_input():
    counts = two_frames()
    with pytest.raises(EgonetError, match="pooled, ois-mean, mean-curve, ods-ois") as info:
        score_frames(counts, metric="mean")
    assert info.value.field == "metric"
    with pytest.raises(EgonetError, match="leave-out, zero, one-if-empty") as info:
        score_frames(counts, metric="ois-mean", empty="drop")
    assert info.value.field == "empty"
    with pytest.raises(EgonetError, match="no frames"):
        score_frames(FrameCounts.stack([], thresholds=3))
    with pytest.raises(EgonetError, match=r"\(B, 2\)") as info:
        score_frames(counts, weights=np.ones((4, 3)))
    assert info.value.field == "weights"
    with pytest.raises(EgonetError, match="positive sum"):
        score_frames(counts, weights=np.array([[1.0, 1.0], [0.0, 0.0]]))


# --------------------------------------------------------------------------
# Resampling


def test_resample_weights():
    w = resample_weights(5, resamples=4000, rng=np.random.default_rng(0))
    assert w.shape == (4001, 5) and w.dtype == np.float64
    np.testing.assert_array_equal(w[0], 1.0)
    np.testing.assert_array_equal(w.sum(axis=1), 5.0)
    assert (w >= 0).all() and (w == np.round(w)).all()
    # Each frame is drawn once on average, and left out of a resample with probability (4/5)^5 = 0.328.
    np.testing.assert_allclose(w[1:].mean(axis=0), 1.0, atol=0.05)
    np.testing.assert_allclose((w[1:] == 0).mean(axis=0), 0.8**5, atol=0.03)
    np.testing.assert_array_equal(w, resample_weights(5, resamples=4000, rng=np.random.default_rng(0)))
    assert resample_weights(3, resamples=0, rng=np.random.default_rng(0)).shape == (1, 3)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(EgonetError, match="n: must be a positive int"):
            resample_weights(bad, resamples=10, rng=np.random.default_rng(0))


def test_jackknife_weights():
    np.testing.assert_array_equal(jackknife_weights(3), [[0, 1, 1], [1, 0, 1], [1, 1, 0]])
    assert jackknife_weights(1).shape == (0, 1)
    big = jackknife_weights(250)
    assert big.shape == (100, 250)
    np.testing.assert_array_equal((big == 0).sum(axis=1), [3] * 50 + [2] * 50)  # frame i in group i mod 100
    np.testing.assert_array_equal((big == 0).sum(axis=0), 1)  # each frame left out once


def test_resampler_is_seeded_by_stratum_and_size():
    one, two = Resampler(resamples=50, seed=3), Resampler(resamples=50, seed=3)
    w = one.weights("cooking", 7)
    assert w.shape == (1 + 50 + 7, 7)
    np.testing.assert_array_equal(w[51:], jackknife_weights(7))
    np.testing.assert_array_equal(w, two.weights("cooking", 7))
    assert one.weights("cooking", 7) is w  # drawn once per stratum
    assert not np.array_equal(w, one.weights("hotel", 7))
    assert not np.array_equal(w, Resampler(resamples=50, seed=4).weights("cooking", 7))
    none = Resampler(resamples=0)
    assert none.weights("x", 4).shape == (1, 4)
    estimate = none.estimate(np.array([0.5]))
    assert estimate.value == 0.5 and estimate.interval() is None and estimate.p_value() is None
    for bad in (-1, 100_001, 1.5):
        with pytest.raises(EgonetError, match="resamples: must be an int from 0 to 100000"):
            Resampler(resamples=bad)
    with pytest.raises(EgonetError, match="seed"):
        Resampler(seed=-2)


def test_resamples_are_capped_by_their_memory_and_p_has_a_floor():
    many = Resampler(resamples=100_000)
    assert many.weights("hotel", 3).shape == (1 + 100_000 + 3, 3)
    with pytest.raises(EgonetError, match="at most 83261 resamples fit these frames") as info:
        many.weights("cooking", 400)  # 403 frames in all: 40 million weights, refused before any is drawn
    assert info.value.field == "resamples" and MAX_WEIGHTS == 2**25
    assert p_floor(1000) == 1 / 1001 and p_floor(0) == 1.0


NORMAL = NormalDist()


def test_bca_without_bias_or_skew_is_the_percentile_interval():
    # Half the resamples below the value (z0 = 0), a symmetric jackknife (a = 0).
    spread = np.random.default_rng(2).uniform(0.01, 0.2, size=500)
    resampled = 0.5 + np.concatenate([spread, -spread])
    estimate = Estimate(0.5, resampled, (np.array([0.49, 0.5, 0.51]),))
    assert estimate.interval() == pytest.approx(tuple(np.quantile(resampled, [0.025, 0.975])), abs=1e-15)
    assert estimate.interval(level=0.9) == pytest.approx(tuple(np.quantile(resampled, [0.05, 0.95])), abs=1e-15)


def test_bca_by_hand():
    # 200 resamples 0.01 .. 2.00 around a value of 0.5: 49 below and 1 tied -> z0 = Phi^-1(49.5 / 200).
    resampled = np.arange(1, 201) / 100.0
    # Jackknife 0, 0, 0, 1: mean 1/4, l = 3 (1/4 - jack) = 3/4, 3/4, 3/4, -9/4
    # a = (sum l^3 / 4^3) / (6 (sum l^2 / 4^2)^(3/2)) = sum l^3 / (6 (sum l^2)^(3/2))
    jack = np.array([0.0, 0.0, 0.0, 1.0])
    l = 3 * (jack.mean() - jack)
    a = np.sum(l**3) / (6 * np.sum(l**2) ** 1.5)
    z0 = NORMAL.inv_cdf(49.5 / 200)
    levels = [NORMAL.cdf(z0 + (z0 + z) / (1 - a * (z0 + z))) for z in (NORMAL.inv_cdf(0.025), NORMAL.inv_cdf(0.975))]
    estimate = Estimate(0.5, resampled, (jack,))
    assert estimate.interval() == pytest.approx(tuple(np.quantile(resampled, levels)), abs=1e-12)
    # Its p-value: q = (0 + 0.5) / 201 resamples below 0.
    w = NORMAL.inv_cdf(0.5 / 201) - z0
    tail = NORMAL.cdf(w / (1 + a * w) - z0)
    assert estimate.p_value() == pytest.approx(max(2 * min(tail, 1 - tail), 1 / 201), abs=1e-12)


def test_p_value_by_hand():
    zeros = Estimate(0.0, np.zeros(999), (np.zeros(5),))
    assert zeros.p_value() == 1.0  # identical rows
    # Without bias or skew it is 2 min(q, 1 - q), q = (#below 0 + ties / 2 + 1/2) / (B + 1).
    spread = np.linspace(0.1, 0.3, 500)
    above = Estimate(0.2, np.concatenate([spread, 0.4 - spread]), (np.array([0.19, 0.2, 0.21]),))
    assert above.p_value() == pytest.approx(1 / 1001, rel=1e-9)  # 2 (0.5 / 1001), which is also the floor 1 / (B + 1)
    below = Estimate(-0.2, -above.resampled, (-above.jackknife[0],))
    assert below.p_value() == pytest.approx(above.p_value(), rel=1e-12)
    mixed = Estimate(0.0, np.concatenate([spread, -spread]), (np.array([-0.01, 0.0, 0.01]),))
    assert mixed.p_value() == pytest.approx(1.0, abs=1e-12)


def test_estimates_subtract_and_average():
    one = Estimate(0.6, np.array([0.5, 0.7]), (np.array([0.55, 0.65]),))
    two = Estimate(0.4, np.array([0.3, 0.5]), (np.array([0.35, 0.45]),))
    d = one - two
    assert d.value == pytest.approx(0.2) and d.resampled == pytest.approx([0.2, 0.2]) and d.jackknife[0] == pytest.approx([0.2, 0.2])
    m = Estimate.mean([one, two])
    assert m.value == pytest.approx(0.5) and m.resampled == pytest.approx([0.4, 0.6])
    s = Estimate.stratified_mean([one, two])  # two strata: leaving a group out moves its half of the mean
    assert s.value == pytest.approx(0.5) and len(s.jackknife) == 2
    assert s.jackknife[0] == pytest.approx([0.475, 0.525]) and s.jackknife[1] == pytest.approx([0.475, 0.525])


# --------------------------------------------------------------------------
# Synthetic frames for the paired test and the coverage study


def synthetic_counts(rng, n: int, *, noise: float, shape=(12, 16), thresholds: int = 99) -> tuple[FrameCounts, FrameCounts]:
    """``n`` frames with a box as truth, and two maps of each: a blurred box plus noise of ``noise``, and a noisier one."""
    good, bad = [], []
    for _ in range(n):
        mask = np.zeros(shape, bool)
        r, c = rng.integers(0, shape[0] - 4), rng.integers(0, shape[1] - 5)
        mask[r : r + rng.integers(2, 5), c : c + rng.integers(3, 6)] = True
        base = 0.25 + 0.5 * mask
        good.append(count_stats(np.clip(base + noise * rng.normal(size=shape), 0, 1), mask, thresholds=thresholds))
        bad.append(count_stats(np.clip(base + 2.5 * noise * rng.normal(size=shape), 0, 1), mask, thresholds=thresholds))
    return FrameCounts.stack(good), FrameCounts.stack(bad)


def paired(a: FrameCounts, b: FrameCounts, resampler: Resampler, metric: str = "pooled") -> dict[str, float]:
    w = resampler.weights("synthetic", a.n)
    va, vb = score_frames(a, metric=metric, weights=w), score_frames(b, metric=metric, weights=w)
    return {key: (resampler.estimate(va[key]) - resampler.estimate(vb[key])).p_value() for key in va}


def test_the_paired_test_rejects_a_real_difference_and_not_identical_rows():
    good, bad = synthetic_counts(np.random.default_rng(0), 40, noise=0.15)
    resampler = Resampler(resamples=999, seed=1)
    for metric in METRICS:
        assert max(paired(good, bad, resampler, metric).values()) < 0.01, metric
        assert paired(good, good, resampler, metric) == {key: 1.0 for key in METRICS[metric].statistics}


@pytest.mark.slow
def test_intervals_cover_the_true_value_about_95_percent_and_the_test_keeps_its_level():
    """A population of 4,000 synthetic frames; 300 samples of 40 frames drawn from it.

    Each sample's 95 % BCa interval should hold the population's value
    (exact: the sample is drawn with replacement from that finite
    population) in about 95 % of the samples. Two rows whose population values are equal
    by construction (every pair of maps appears both ways round) should
    differ at p < 0.05 in about 5 % of the samples.
    """
    rng = np.random.default_rng(2026)
    good, bad = synthetic_counts(rng, 2000, noise=0.2, thresholds=19)
    population_a = FrameCounts.concat([good, bad], thresholds=19)
    population_b = FrameCounts.concat([bad, good], thresholds=19)  # the same frames, the maps swapped
    truth = {metric: scalar(score_frames(population_a, metric=metric)) for metric in METRICS}
    assert truth["pooled"] == scalar(score_frames(population_b))  # equal by construction
    resampler = Resampler(resamples=1000, seed=0)
    covered = {metric: {key: 0 for key in truth[metric]} for metric in METRICS}
    rejected, repeats = 0, 300
    for _ in range(repeats):
        index = rng.integers(0, population_a.n, size=40)
        sample_a, sample_b = population_a.take(index), population_b.take(index)
        w = resampler.weights("sample", 40)
        # ods-ois holds the pooled statistics too (its max_f and ap are pooled MF and AP).
        values = {metric: score_frames(sample_a, metric=metric, weights=w) for metric in ("ois-mean", "mean-curve", "ods-ois")}
        values["pooled"] = {key: values["ods-ois"][key] for key in ("max_f", "ap")}
        for metric, scores in values.items():
            for key, v in scores.items():
                lo, hi = resampler.estimate(v).interval()
                covered[metric][key] += lo <= truth[metric][key] <= hi
        other = score_frames(sample_b, metric="pooled", weights=w)["max_f"]
        rejected += (resampler.estimate(values["pooled"]["max_f"]) - resampler.estimate(other)).p_value() < 0.05
    rates = {f"{metric} {key}": n / repeats for metric, keys in covered.items() for key, n in keys.items()}
    # 1,000 samples gave 0.935 to 0.951 (plain percentile intervals: 0.931 to 0.945); 300 vary by about 0.013.
    assert all(0.90 <= r <= 0.98 for r in rates.values()), rates
    assert np.mean(list(rates.values())) == pytest.approx(0.95, abs=0.025), rates
    assert rejected / repeats <= 0.09, rejected
