"""Tests for egonet.metrics: hand-checked cases and a direct reference.

The per-frame conventions (pooled, ois-mean, mean-curve, ODS/OIS), the bootstrap and
the paired test are in tests/unit/test_metrics_frames.py.
"""

import dataclasses

import numpy as np
import pytest

from egonet.errors import EgonetError
from egonet.metrics import (
    Counts,
    Score,
    ScoreAccumulator,
    count_stats,
    curve_from_counts,
    iso_f_curve,
    score_maps,
    threshold_values,
)

# --------------------------------------------------------------------------
# An independent, slow implementation: one comparison per threshold.


def direct_counts(prob, mask, thresholds):
    t = np.arange(1, thresholds + 1, dtype=np.float64) / (thresholds + 1)
    p = np.asarray(prob).astype(np.float64)  # exact for float32 input
    tp, fp, fn = [], [], []
    for tk in t:
        pred = p >= tk
        tp.append(np.count_nonzero(pred & mask))
        fp.append(np.count_nonzero(pred & ~mask))
        fn.append(np.count_nonzero(~pred & mask))
    return np.array(tp), np.array(fp), np.array(fn)


def direct_curve(tp, fp, fn):
    p = np.array([a / (a + b) if a + b > 0 else 1.0 for a, b in zip(tp, fp)])
    r = np.array([a / (a + c) if a + c > 0 else 0.0 for a, c in zip(tp, fn)])
    return p, r


def direct_frame_curve(tp, fp, fn, empty):
    """A map's own curve; a map without positives as the policy says (None: left out)."""
    if tp[0] + fn[0] > 0:
        return direct_curve(tp, fp, fn)
    if empty == "leave-out":
        return None
    hit = np.array([1.0 if b == 0 and empty == "one-if-empty" else 0.0 for b in fp])
    return hit, hit


def direct_score(probs, masks, thresholds, beta2, metric, empty="leave-out"):
    per_map = [direct_counts(p, m, thresholds) for p, m in zip(probs, masks)]
    if metric == "mean-curve":
        curves = [c for c in (direct_frame_curve(*m, empty) for m in per_map) if c is not None]
        prec = np.mean([c[0] for c in curves], axis=0)
        rec = np.mean([c[1] for c in curves], axis=0)
    else:
        prec, rec = direct_curve(*(sum(c[i] for c in per_map) for i in range(3)))
    f = np.array([(1 + beta2) * p * r / (beta2 * p + r) if p + r > 0 else 0.0 for p, r in zip(prec, rec)])
    ap = 0.0
    for k in range(thresholds):
        r_next = rec[k + 1] if k + 1 < thresholds else 0.0
        ap += (rec[k] - r_next) * prec[k]
    return prec, rec, f, ap


# --------------------------------------------------------------------------
# Hand-checked cases.

# Eight pixels, T = 3 thresholds: 0.25, 0.5, 0.75.
#   prob   1.0  0.75  0.5  0.5  0.3  0.25  0.1  0.0
#   mask   T    T     F    T    F    T     F    F      (4 positives)
# t=0.25: predicted {1.0, .75, .5, .5, .3, .25} -> TP 4, FP 2, FN 0
# t=0.50: predicted {1.0, .75, .5, .5}          -> TP 3, FP 1, FN 1
# t=0.75: predicted {1.0, .75}                   -> TP 2, FP 0, FN 2
# P = [4/6, 3/4, 1], R = [1, 3/4, 1/2]
# F1 = [0.8, 0.75, 2/3] -> MF 0.8 at t = 0.25
# AP = (1 - 3/4) 2/3 + (3/4 - 1/2) 3/4 + (1/2 - 0) 1 = 1/6 + 3/16 + 1/2 = 41/48
EIGHT_PROB = np.array([[1.0, 0.75, 0.5, 0.5], [0.3, 0.25, 0.1, 0.0]])
EIGHT_MASK = np.array([[True, True, False, True], [False, True, False, False]])


def test_threshold_values():
    np.testing.assert_array_equal(threshold_values(3), [0.25, 0.5, 0.75])
    t = threshold_values()
    assert t.shape == (99,)
    assert t[0] == 0.01 and t[29] == 0.3 and t[-1] == 0.99


def test_eight_pixels_counts():
    tp, fp, fn = count_stats(EIGHT_PROB, EIGHT_MASK, thresholds=3)
    np.testing.assert_array_equal(tp, [4, 3, 2])
    np.testing.assert_array_equal(fp, [2, 1, 0])
    np.testing.assert_array_equal(fn, [0, 1, 2])


def test_eight_pixels_score():
    s = score_maps([EIGHT_PROB], [EIGHT_MASK], thresholds=3)
    np.testing.assert_allclose(s.precision, [4 / 6, 3 / 4, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.recall, [1.0, 3 / 4, 1 / 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.f, [0.8, 0.75, 2 / 3], rtol=0, atol=1e-15)
    assert s.max_f == pytest.approx(0.8, abs=1e-15)
    assert s.best_threshold == 0.25
    assert s.ap == pytest.approx(41 / 48, abs=1e-15)
    assert s.n_maps == 1 and s.metric == "pooled" and s.empty_maps == 0


def test_eight_pixels_beta2():
    # beta2 = 0.25: F = 1.25 P R / (0.25 P + R)
    # k1: 1.25 (2/3) / (1/6 + 1) = 5/7; k2: (45/64) / (15/16) = 3/4; k3: 0.625 / 0.75 = 5/6
    s = score_maps([EIGHT_PROB], [EIGHT_MASK], thresholds=3, beta2=0.25)
    np.testing.assert_allclose(s.f, [5 / 7, 3 / 4, 5 / 6], rtol=0, atol=1e-15)
    assert s.max_f == pytest.approx(5 / 6, abs=1e-15)
    assert s.best_threshold == 0.75
    assert s.beta2 == 0.25
    assert s.ap == pytest.approx(41 / 48, abs=1e-15)  # AP does not depend on beta


def test_boundaries_float64_default_thresholds():
    # With every pixel positive, tp_k counts pixels with prob >= k/100.
    prob = np.array([[0.5, np.nextafter(0.5, 0.0), 0.3, 0.01], [np.nextafter(0.01, 0.0), 0.99, 1.0, 0.0]])
    # levels reached (number of thresholds <= prob): 50, 49, 30, 1, 0, 99, 99, 0
    mask = np.ones(prob.shape, dtype=bool)
    tp, fp, fn = count_stats(prob, mask)
    expected = np.zeros(99, dtype=np.int64)
    expected[0:1] = 6  # k = 1
    expected[1:30] = 5  # k = 2..30: 0.5, 0.5-, 0.3, 0.99, 1.0
    expected[30:49] = 4  # k = 31..49
    expected[49:50] = 3  # k = 50: 0.5, 0.99, 1.0
    expected[50:] = 2  # k = 51..99
    np.testing.assert_array_equal(tp, expected)
    np.testing.assert_array_equal(fp, 0)
    np.testing.assert_array_equal(fn, 8 - expected)


def test_boundaries_float32_compared_exactly():
    # float32(0.29) = 0.28999999165... < 0.29: it reaches t_28, not t_29.
    # float32(0.07) = 0.07000000029... > 0.07 and float32(0.3) = 0.3000000119... > 0.3.
    # float32(0.5) = 0.5 exactly. A float32 comparison (prob >= np.float32(t))
    # would wrongly count 0.29 at t_29.
    prob = np.array([[0.29, 0.07, 0.3, 0.5]], dtype=np.float32)
    mask = np.zeros(prob.shape, dtype=bool)
    _, fp, _ = count_stats(prob, mask)
    assert fp[28 - 1] == 3 and fp[29 - 1] == 2  # 0.29 drops out after t_28
    assert fp[7 - 1] == 4 and fp[8 - 1] == 3  # 0.07 drops out after t_7
    assert fp[30 - 1] == 2 and fp[31 - 1] == 1  # 0.3 reaches t_30
    assert fp[50 - 1] == 1 and fp[51 - 1] == 0  # 0.5 reaches t_50


def test_mean_curve_vs_pooled():
    # T = 1 (threshold 0.5).
    # map A: probs [0.9, 0.9], mask [T, F]            -> TP 1, FP 1, FN 0: P 1/2, R 1
    # map B: probs [0, 0, 0, 0.9], mask [T, T, T, F]  -> TP 0, FP 1, FN 3: P 0, R 0
    # pooled: TP 1, FP 2, FN 3 -> P 1/3, R 1/4, F 2 (1/12) / (7/12) = 2/7, AP = 1/12
    # per image: P 1/4, R 1/2 -> F 2 (1/8) / (3/4) = 1/3, AP = 1/8
    probs = [np.array([[0.9, 0.9]]), np.array([[0.0, 0.0], [0.0, 0.9]])]
    masks = [np.array([[True, False]]), np.array([[True, True], [True, False]])]
    pooled = score_maps(probs, masks, thresholds=1)
    assert pooled.max_f == pytest.approx(2 / 7, abs=1e-15)
    assert pooled.ap == pytest.approx(1 / 12, abs=1e-15)
    per = score_maps(probs, masks, thresholds=1, metric="mean-curve")
    assert per.metric == "mean-curve" and per.n_maps == 2 and per.empty == "leave-out" and per.empty_maps == 0
    assert per.max_f == pytest.approx(1 / 3, abs=1e-15)
    assert per.ap == pytest.approx(1 / 8, abs=1e-15)


def test_per_image_is_the_old_name_of_the_mean_curve(caplog):
    probs, masks = [np.array([[0.9, 0.1]]), np.array([[0.2, 0.7]])], [np.array([[True, False]]), np.array([[True, True]])]
    old = score_maps(probs, masks, per_image=True)
    assert "per_image= is deprecated" in caplog.text and "metric='mean-curve'" in caplog.text
    new = score_maps(probs, masks, metric="mean-curve")
    assert (old.max_f, old.ap, old.metric) == (new.max_f, new.ap, "mean-curve") and old.per_image
    assert not score_maps(probs, masks, per_image=False).per_image
    with pytest.raises(EgonetError, match="score_frames scores the other conventions") as info:
        score_maps(probs, masks, metric="ois-mean")
    assert info.value.field == "metric"


def test_maps_without_positives_in_the_mean_curve():
    # T = 1 (0.5). A: one positive found, P 1 R 1. B: no positive, nothing predicted. C: no positive, one false positive.
    probs = [np.array([[0.9]]), np.array([[0.1]]), np.array([[0.8]])]
    masks = [np.array([[True]]), np.array([[False]]), np.array([[False]])]
    by_policy = {empty: score_maps(probs, masks, thresholds=1, metric="mean-curve", empty=empty) for empty in ("leave-out", "zero", "one-if-empty")}
    assert by_policy["leave-out"].max_f == 1.0  # A alone
    assert by_policy["zero"].max_f == pytest.approx(1 / 3, abs=1e-15)  # P = R = 1/3
    assert by_policy["one-if-empty"].max_f == pytest.approx(2 / 3, abs=1e-15)  # B counts as 1: P = R = 2/3
    assert {s.empty_maps for s in by_policy.values()} == {2} and by_policy["zero"].empty == "zero"
    assert score_maps(probs, masks, thresholds=1).empty_maps == 2  # pooled: said, no policy
    with pytest.raises(EgonetError, match="nothing to average") as info:
        score_maps(probs[1:], masks[1:], metric="mean-curve")
    assert info.value.field == "empty"
    with pytest.raises(EgonetError, match="leave-out, zero, one-if-empty"):
        score_maps(probs, masks, metric="mean-curve", empty="skip")


def test_no_positives():
    s = score_maps([np.full((4, 5), 0.7)], [np.zeros((4, 5), dtype=bool)])
    np.testing.assert_array_equal(s.recall, 0.0)
    np.testing.assert_array_equal(s.f, 0.0)
    assert s.max_f == 0.0 and s.ap == 0.0
    assert s.best_threshold == 0.01  # the lowest threshold on ties
    np.testing.assert_array_equal(s.precision[:70], 0.0)  # everything wrongly predicted
    np.testing.assert_array_equal(s.precision[70:], 1.0)  # nothing predicted


def test_all_predicted_negative():
    mask = np.zeros((3, 3), dtype=bool)
    mask[1, 1] = True
    s = score_maps([np.zeros((3, 3), dtype=np.float32)], [mask])
    np.testing.assert_array_equal(s.precision, 1.0)  # nothing predicted -> P = 1
    np.testing.assert_array_equal(s.recall, 0.0)
    assert s.max_f == 0.0 and s.ap == 0.0


def test_perfect_prediction():
    rng = np.random.default_rng(1)
    masks = [rng.random((7, 9)) < 0.3 for _ in range(3)]
    probs = [m.astype(np.float32) for m in masks]
    for metric in ("pooled", "mean-curve"):
        s = score_maps(probs, masks, metric=metric)
        assert s.max_f == 1.0
        assert s.ap == 1.0


def test_no_normalisation():
    # A faint but perfectly ranked map is not rescaled: nothing reaches 0.01.
    mask = np.array([[True, False]])
    s = score_maps([np.array([[0.009, 0.001]])], [mask])
    assert s.max_f == 0.0
    assert score_maps([np.array([[0.9, 0.1]])], [mask]).max_f == 1.0


# --------------------------------------------------------------------------
# Agreement with the direct implementation.


def random_maps(rng, dtype, thresholds, n=4):
    t = np.arange(1, thresholds + 1, dtype=np.float64) / (thresholds + 1)
    on = t.astype(dtype)
    special = np.concatenate(
        [
            on,
            np.nextafter(on, dtype(0)),
            np.nextafter(on, dtype(1)),
            np.array([0.0, 1.0, np.nextafter(1.0, 0.0)], dtype=dtype),
        ]
    ).astype(dtype)
    if dtype == np.float64:
        special = np.concatenate([special, t])
    probs, masks = [], []
    for i in range(n):
        shape = (int(rng.integers(5, 40)), int(rng.integers(5, 40)))
        p = rng.random(shape).astype(dtype)
        pick = rng.random(shape) < 0.4
        p[pick] = rng.choice(special, size=int(pick.sum()))
        m = rng.random(shape) < (0.0 if i == 1 else 0.3)
        probs.append(p)
        masks.append(m)
    return probs, masks


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("thresholds", [1, 3, 7, 99, 255])
def test_counts_match_direct(dtype, thresholds):
    rng = np.random.default_rng(thresholds)
    probs, masks = random_maps(rng, dtype, thresholds)
    for p, m in zip(probs, masks):
        got = count_stats(p, m, thresholds=thresholds)
        for a, b in zip(got, direct_counts(p, m, thresholds)):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(("metric", "empty"), [("pooled", "leave-out"), ("mean-curve", "leave-out"), ("mean-curve", "zero"), ("mean-curve", "one-if-empty")])
@pytest.mark.parametrize("beta2", [1.0, 0.3, 2.0])
def test_score_matches_direct(metric, empty, beta2):
    rng = np.random.default_rng(7)
    probs, masks = random_maps(rng, np.float32, 99, n=5)  # one map without positives
    s = score_maps(iter(probs), iter(masks), beta2=beta2, metric=metric, empty=empty)
    prec, rec, f, ap = direct_score(probs, masks, 99, beta2, metric, empty)
    np.testing.assert_allclose(s.precision, prec, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.recall, rec, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.f, f, rtol=0, atol=1e-12)
    assert abs(s.ap - ap) < 1e-12
    assert abs(s.max_f - f.max()) < 1e-12
    assert s.best_threshold == threshold_values()[int(np.argmax(f))]


def test_every_float32_near_thresholds():
    # All float32 values within 3 ulps of every threshold, one map each dtype.
    for thresholds in (99, 100, 127, 1000):
        t = threshold_values(thresholds)
        base = t.astype(np.float32)
        values = [base]
        up, down = base, base
        for _ in range(3):
            up = np.nextafter(up, np.float32(2))
            down = np.nextafter(down, np.float32(-1))
            values += [up, down]
        p = np.clip(np.concatenate(values), 0, 1).astype(np.float32)[None, :]
        m = np.zeros(p.shape, dtype=bool)
        m[:, ::2] = True
        got = count_stats(p, m, thresholds=thresholds)
        for a, b in zip(got, direct_counts(p, m, thresholds)):
            np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------
# Accumulation, streaming, merging.


def test_accumulator_merge_equals_one_pass():
    rng = np.random.default_rng(3)
    probs, masks = random_maps(rng, np.float32, 99, n=6)
    a, b = ScoreAccumulator(), ScoreAccumulator()
    for p, m in zip(probs[:2], masks[:2]):
        a.add(p, m)
    for p, m in zip(probs[2:], masks[2:]):
        b.add(p, m)
    a.merge(b)
    for metric in ("pooled", "mean-curve"):
        merged = a.score(metric=metric)
        whole = score_maps(probs, masks, metric=metric)
        np.testing.assert_allclose(merged.f, whole.f, rtol=0, atol=1e-15)
        assert merged.ap == pytest.approx(whole.ap, abs=1e-15)
        assert merged.n_maps == 6


def test_accumulator_state_of_eight_pixels():
    # Two copies of the eight pixels: each map's counts, pooled they double.
    acc = ScoreAccumulator(thresholds=3)
    acc.add(EIGHT_PROB, EIGHT_MASK)
    acc.add(EIGHT_PROB, EIGHT_MASK)
    state = acc.state()
    np.testing.assert_array_equal(state["tp"], [[4, 3, 2], [4, 3, 2]])
    np.testing.assert_array_equal(state["fp"], [[2, 1, 0], [2, 1, 0]])
    np.testing.assert_array_equal(state["positives"], [4, 4])
    np.testing.assert_array_equal(acc.counts.tp, [8, 6, 4])
    np.testing.assert_array_equal(acc.counts.fn, [0, 2, 4])
    assert acc.n_maps == 2 and acc.frames().n == 2
    state["tp"][0, 0] = 0  # a copy: the accumulator keeps its counts
    assert acc.counts.tp[0] == 8


def test_accumulator_state_round_trip():
    rng = np.random.default_rng(4)
    probs, masks = random_maps(rng, np.float32, 9, n=3)
    acc = ScoreAccumulator(thresholds=9)
    for p, m in zip(probs, masks):
        acc.add(p, m)
    # As a JSON cache stores it: plain lists.
    stored = {k: v.tolist() for k, v in acc.state().items()}
    back = ScoreAccumulator.from_state(stored, thresholds=9)
    for key, value in acc.state().items():
        np.testing.assert_array_equal(back.state()[key], value)
    assert back.counts.tp.dtype == np.int64 and back.n_maps == 3
    for metric in ("pooled", "mean-curve"):
        assert back.score(metric=metric).ap == acc.score(metric=metric).ap
    assert ScoreAccumulator.from_state({"tp": [], "fp": [], "positives": []}).n_maps == 0
    with pytest.raises(EgonetError, match="do not have 99 thresholds") as info:
        ScoreAccumulator.from_state(stored)
    assert info.value.field == "state"
    with pytest.raises(EgonetError, match="has no 'positives'"):
        ScoreAccumulator.from_state({k: v for k, v in stored.items() if k != "positives"}, thresholds=9)


def test_iso_f_curve():
    # F = 0.5: P = 0.5 R / (2 R - 0.5), from R = 1/3 (P = 1) to R = 1 (P = 1/3).
    recall, precision = iso_f_curve(0.5, points=3)
    np.testing.assert_allclose(recall, [1 / 3, 2 / 3, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(precision, [1.0, 0.4, 1 / 3], rtol=0, atol=1e-15)
    for beta2 in (0.3, 1.0, 2.0):
        recall, precision = iso_f_curve(0.6, beta2=beta2)
        assert recall.shape == precision.shape == (40,)
        f = Score.from_curves(precision, recall, beta2=beta2).f
        np.testing.assert_allclose(f, 0.6, rtol=0, atol=1e-12)
    for bad in (0, 1, 1.5, True):
        with pytest.raises(EgonetError, match="f: must be an F-score") as info:
            iso_f_curve(bad)
        assert info.value.field == "f"
    with pytest.raises(EgonetError, match="points: must be an int of at least 2"):
        iso_f_curve(0.5, points=1)


def test_counts_pool_with_add():
    c1 = count_stats(EIGHT_PROB, EIGHT_MASK, thresholds=3)
    c2 = count_stats(EIGHT_PROB[::-1], EIGHT_MASK[::-1], thresholds=3)
    pooled = Counts(*(np.add(x, y) for x, y in zip(c1, c2)))
    s = Score.from_counts(pooled)
    assert s.max_f == pytest.approx(0.8, abs=1e-15)
    p, r = curve_from_counts(pooled)
    np.testing.assert_allclose(p, [4 / 6, 3 / 4, 1.0])
    np.testing.assert_allclose(r, [1.0, 3 / 4, 1 / 2])


def test_streams_generators_of_different_sizes():
    def gen_probs():
        for h in (3, 5, 8):
            yield np.full((h, h + 1), 0.6, dtype=np.float32)

    def gen_masks():
        for h in (3, 5, 8):
            yield np.ones((h, h + 1), dtype=bool)

    s = score_maps(gen_probs(), gen_masks())
    assert s.n_maps == 3 and s.max_f == 1.0


def test_score_is_frozen_and_read_only():
    s = score_maps([EIGHT_PROB], [EIGHT_MASK], thresholds=3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.max_f = 0.5
    with pytest.raises(ValueError):
        s.f[0] = 0.0


# --------------------------------------------------------------------------
# Validation.


@pytest.mark.parametrize(
    ("value", "match"),
    [(np.nan, "NaN"), (1.5, r"\[0, 1\]"), (-0.1, r"\[0, 1\]")],
)
def test_rejects_bad_probabilities(value, match):
    p = np.full((2, 2), 0.5)
    p[1, 1] = value
    with pytest.raises(ValueError, match=match):
        score_maps([np.full((2, 2), 0.5), p], [np.ones((2, 2), bool)] * 2)
    with pytest.raises(ValueError, match=r"probs\[1\]"):
        score_maps([np.full((2, 2), 0.5), p], [np.ones((2, 2), bool)] * 2)


def test_rejects_shape_mismatch_naming_index():
    probs = [np.zeros((2, 2)), np.zeros((2, 3))]
    masks = [np.zeros((2, 2), bool), np.zeros((3, 2), bool)]
    with pytest.raises(ValueError, match=r"masks\[1\].*\(3, 2\).*\(2, 3\)"):
        score_maps(probs, masks)


def test_rejects_bad_types_and_lengths():
    with pytest.raises(ValueError, match="empty"):
        score_maps([], [])
    with pytest.raises(ValueError, match="differ in length"):
        score_maps([np.zeros((2, 2))], [])
    with pytest.raises(ValueError, match="differ in length"):
        score_maps([], [np.zeros((2, 2), bool)])
    with pytest.raises(ValueError, match="bool"):
        score_maps([np.zeros((2, 2))], [np.zeros((2, 2), np.uint8)])
    with pytest.raises(ValueError, match="float32 or float64"):
        score_maps([np.zeros((2, 2), np.uint8)], [np.zeros((2, 2), bool)])
    with pytest.raises(ValueError, match=r"2-D"):
        score_maps(np.zeros((2, 2)), np.zeros((2, 2), bool))  # one map, not a list of maps
    with pytest.raises(ValueError, match="thresholds"):
        score_maps([np.zeros((2, 2))], [np.zeros((2, 2), bool)], thresholds=0)
    with pytest.raises(ValueError, match="thresholds"):
        count_stats(np.zeros((2, 2)), np.zeros((2, 2), bool), thresholds=2.5)
    for beta2 in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="beta2"):
            score_maps([np.zeros((2, 2))], [np.zeros((2, 2), bool)], beta2=beta2)
    with pytest.raises(ValueError, match="no maps"):
        ScoreAccumulator().score()
    with pytest.raises(ValueError, match="thresholds"):
        ScoreAccumulator(thresholds=3).merge(ScoreAccumulator(thresholds=4))


def test_float16_accepted():
    s = score_maps([EIGHT_PROB.astype(np.float16)], [EIGHT_MASK], thresholds=3)
    assert s.ap == pytest.approx(41 / 48, abs=1e-15)
