"""Thin objects in GrabCut: a stroke's effect is local, a click follows a thin part, and NoC@90 on real frames.

The NoC@90 protocol and the frames are ``tests/thin_objects.py``'s (the
same as ``bench/bench_grabcut.py --noc``).
"""

import cv2
import numpy as np
import pytest

from egonet.grabcut import GrabCutSession, stroke_footprint
from egonet.grabcut.colour import _first_models
from egonet.grabcut.cut import _along, _crossing, _flooded, _restored, _sharpened, _straight, _Terms
from egonet.grabcut.fine import _fine_cut
from tests import thin_objects

NEAR = 16  # px: a stroke's neighbourhood (the engine's is two grid pixels: 3-10 px here)


def _far_changes(before: np.ndarray, after: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """Changed pixels more than ``NEAR`` px from the stroke and not joined to it through changed pixels."""
    changed = before != after
    near = cv2.dilate(footprint.view(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * NEAR + 1,) * 2))
    _, parts = cv2.connectedComponents(changed.view(np.uint8), connectivity=8)
    joined = np.unique(parts[(near > 0) & changed])
    return changed & ~np.isin(parts, joined)


def _fork_scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 480x360 grey fork (a head with tines, a 4 px handle) on a brownish table with a grey patch."""
    rng = np.random.default_rng(seed)
    h, w = 360, 480
    truth = np.zeros((h, w), np.uint8)
    cv2.line(truth, (60, 180), (330, 180), 1, 4)  # handle
    cv2.rectangle(truth, (330, 160), (360, 200), 1, -1)  # head
    for k in range(4):
        cv2.rectangle(truth, (360, 160 + 11 * k), (420, 164 + 11 * k), 1, -1)  # tines, 5 px wide
    truth = truth.astype(bool)
    image = np.empty((h, w, 3), np.float64)
    image[...] = (150, 110, 80)
    image[40:120, 300:440] = (175, 175, 180)  # a grey patch near the head, as the fork's colour
    image[truth] = (185, 185, 190)
    image += rng.normal(0, 8, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8), truth


def test_background_stroke_keeps_the_far_end_of_a_handle():
    image, truth = _fork_scene()
    session = GrabCutSession(image)
    mask = session.box(40, 30, 450, 215)  # takes the grey patch in with the fork
    handle_end = np.zeros_like(truth)
    handle_end[170:190, 60:120] = truth[170:190, 60:120]
    assert mask[handle_end].mean() > 0.9  # the thin handle survives the box's cut
    for points in ([(310, 60), (430, 60)], [(310, 100), (430, 100)], [(380, 215), (430, 210)]):
        before = session.mask
        after = session.stroke(points, "bg", 6)
        assert not _far_changes(before, after, stroke_footprint(truth.shape, points, 6)).any()
        np.testing.assert_array_equal(after[handle_end], before[handle_end])
        assert not (after & ~before).any()  # a background stroke only removes
    assert mask[40:120, 300:440].all() and session.mask[40:120, 300:440].mean() < 0.01  # the patch went
    iou = np.count_nonzero(session.mask & truth) / np.count_nonzero(session.mask | truth)
    assert iou > 0.99  # the fork, tines and the whole handle


def test_foreground_stroke_changes_only_what_joins_it():
    image, truth = _fork_scene(1)
    session = GrabCutSession(image)
    session.box(40, 150, 450, 215)
    for points in ([(200, 180), (260, 180)], [(390, 171), (410, 171)]):
        before = session.mask
        after = session.stroke(points, "fg", 2)
        assert not _far_changes(before, after, stroke_footprint(truth.shape, points, 2)).any()
        assert not (before & ~after).any()  # a foreground stroke only adds


def test_strokes_on_real_video_change_nothing_far():
    """The camel (DAVIS, a real frame): every click of the NoC@90 run, to IoU 0.9, is local.

    On main's engine before issue 36 every one of these strokes changed
    pixels far from itself (up to 9,023 px).
    """
    case = thin_objects.davis_case(thin_objects.REAL_VIDEO / "camel-00024")
    session = GrabCutSession(case.rgb)
    far = []

    def stroke(k):
        before = session.mask
        after = session.stroke(k.points, k.label, k.radius)
        far.append(int(_far_changes(before, after, stroke_footprint(after.shape, k.points, k.radius)).sum()))
        return after

    run = thin_objects.noc(lambda b: session.box(*b), stroke, case.truth)
    assert run.noc is not None and run.noc <= 12
    while len(far) < 5:  # the box alone now takes the camel near 0.9: a few more clicks past it, each local too
        stroke(thin_objects.click(session.mask, case.truth))
    assert far == [0] * len(far)


def test_an_object_click_does_not_carry_the_background_its_colour_model_holds():
    """The camel a few video frames on (camel-00028): the first click, on its missed head, takes the head
    and little of the fence behind it.

    The stroke's re-cut smooths the label over the fence beside the head,
    whose colours the background's model explains at least as well as the
    object's: before, 39,218 px of fence came with the head (IoU 0.792 ->
    0.788); a pixel carried against its colour now moves only if it is like
    the stroke's colours (``cut._recut``).
    """
    case = thin_objects.davis_case(thin_objects.REAL_VIDEO / "camel-00024", 4)
    session = GrabCutSession(case.rgb)
    before = session.box(*thin_objects.loose_box(case.truth))
    k = thin_objects.click(before, case.truth)
    assert k.label == "fg"
    after = session.stroke(k.points, k.label, k.radius)
    wrong = np.count_nonzero((before == case.truth) & (after != case.truth))
    assert wrong < 20_000, wrong  # 14,964 on 2026-12-05
    assert thin_objects.iou(after, case.truth) > thin_objects.iou(before, case.truth) + 0.02


def test_a_click_floods_the_coherent_region_it_lands_in():
    """``_flooded``: an object stroke in a bright square labelled background takes the square, up to its edges."""
    rng = np.random.default_rng(0)
    image = np.full((100, 120, 3), 60.0)
    image[30:60, 40:75] = (200, 190, 170)
    image[70:90, 10:30] = (200, 190, 170)  # the same colour, but not joined to the square
    image = np.clip(image + rng.normal(0, 6, image.shape), 0, 255).astype(np.uint8)
    square = np.zeros((100, 120), bool)
    square[30:60, 40:75] = True
    crop = np.zeros((5, 5), bool)
    crop[1:4, :] = True  # a short stroke at the square's centre
    against = np.ones((100, 120), bool)  # everything labelled background
    region = _flooded(image, against, [(crop, (43, 55), True)], 56, 0.7)
    assert np.count_nonzero(region & square) / np.count_nonzero(region | square) > 0.9
    near = cv2.dilate(square.view(np.uint8), np.ones((5, 5), np.uint8)).view(bool)
    assert not (region & ~near).any()  # stops at the square's edges: nothing of the other patch
    # What surely has the other label stops the flood: here the square's right part.
    sure = np.zeros_like(square)
    sure[30:60, 66:75] = True
    region = _flooded(image, against, [(crop, (43, 45), True)], 56, 0.7, sure)
    assert not (region & sure).any() and region[40:50, 40:48].all() and not (region & ~near).any()


def test_an_object_click_follows_a_thin_part_along_itself_and_not_a_wide_one():
    """``_along``: a stroke along a missed leg (a thin bar of its colour) takes the bar, not a patch of its colour.

    On a wide patch of the stroke's colour (the part is no thin part there),
    or where the part of its colour spreads beyond the strip along the stroke
    (a bar joined to a patch), nothing is taken.
    """
    rng = np.random.default_rng(0)
    image = np.full((120, 160, 3), (100, 100, 100), np.float64)
    skin = (200, 150, 120)
    bar = np.zeros((120, 160), bool)
    bar[10:110, 60:68] = True  # a leg, 8 grid pixels wide
    image[bar] = skin
    image = np.clip(image + rng.normal(0, 5, image.shape), 0, 255).astype(np.uint8)
    crop = np.ones((11, 3), bool)  # a short stroke along the bar
    against, nothing = np.ones((120, 160), bool), np.zeros((120, 160), bool)
    taken = _along(image, against, (crop, (50, 63)), 56, nothing)
    assert np.count_nonzero(taken & bar) > 0.9 * np.count_nonzero(bar)
    near = cv2.dilate(bar.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
    assert not (taken & ~near).any()
    # A wide patch of the same colour: no thin part.
    wide = image.copy()
    wide[30:90, 40:100] = skin
    assert not _along(wide, against, (crop, (50, 63)), 56, nothing).any()
    # The bar joined to a patch beside it: the part spreads beyond the strip along the stroke.
    joined = image.copy()
    joined[70:110, 68:130] = skin
    assert not _along(joined, against, (crop, (50, 63)), 56, nothing).any()


def test_a_background_stroke_gives_back_a_thin_part_it_cut_off_and_not_a_wide_one():
    """``_restored``: a knife's handle lying on a mug the stroke removed comes back; a patch of its colour does not."""
    rng = np.random.default_rng(0)
    h, w = 120, 300
    image = np.empty((h, w, 3), np.float64)
    image[...] = (90, 60, 40)  # a brown table
    mug = np.zeros((h, w), np.uint8)
    cv2.circle(mug, (60, 60), 40, 1, -1)
    image[mug.view(bool)] = (235, 235, 240)  # a white mug, in the box's label
    bar = np.zeros((h, w), np.uint8)
    cv2.line(bar, (25, 45), (280, 75), 1, 7)  # the knife, across the mug
    image[bar.view(bool)] = (160, 160, 150)
    patch = np.zeros((h, w), bool)
    patch[68:88, 185:205] = True  # a grey patch of the knife's colour under it, that the re-cut took too
    image[patch] = (160, 160, 150)
    image = np.clip(image + rng.normal(0, 4, image.shape), 0, 255).astype(np.uint8)
    mug, bar = mug.view(bool), bar.view(bool)
    prior = mug | bar | patch
    handle = bar & (np.arange(w) < 150)
    low = prior & ~mug & ~handle & ~patch  # the re-cut took the mug, the handle and the patch
    gc = np.where(low, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    gc[55:65, 40:80] = cv2.GC_BGD  # the stroke, on the mug
    terms = _Terms.of_image(image)
    models = _first_models(image, np.where(prior, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8),
                           np.random.default_rng(0))
    kept = _restored(terms, models, prior, low, gc)
    assert not (low & ~kept).any() and not (kept & ~prior).any()
    assert kept[handle].mean() > 0.85  # the handle, on the mug and beyond it
    assert not kept[patch].any() and kept[mug & ~bar].mean() < 0.01


def test_an_object_click_floods_a_part_whose_colour_the_background_holds_too():
    """An object click on a missed blue part floods it, though blue blobs all over the table make it "sure" background.

    The flood stops at pixels the other side's colour model clearly prefers,
    but not at pixels like the stroke's own colours (``cut._unlike``). On
    main's engine before (2026-12-04) the same click took 7 % of the part.
    """
    rng = np.random.default_rng(0)
    image = np.full((240, 320, 3), (95, 90, 85), np.float64)
    blue = (60, 80, 170)
    for _ in range(40):
        cv2.circle(image, (int(rng.integers(0, 320)), int(rng.integers(0, 240))), int(rng.integers(4, 9)), blue, -1)
    truth, part = np.zeros((240, 320), bool), np.zeros((240, 320), bool)
    image[70:130, 120:200] = (190, 60, 50)  # a red body
    image[130:180, 140:180] = blue  # and a blue part joined to it, missed by the mask
    truth[70:130, 120:200] = part[130:180, 140:180] = True
    truth |= part
    image = np.clip(image + rng.normal(0, 5, image.shape), 0, 255).astype(np.uint8)
    session = GrabCutSession(image)
    session.seed_mask(truth & ~part)
    mask = session.stroke([(160, 150), (160, 160)], "fg", 4)
    assert np.count_nonzero(mask & part) > 0.5 * np.count_nonzero(part)  # 69 %
    assert np.count_nonzero(mask & ~truth) <= 20  # nothing of the table (its blue blobs included)


def test_a_click_on_a_chopstick_follows_it_at_full_resolution():
    """A click on an 8-10 px chopstick (2 px on the cut's grid) takes the stick along its length, nothing beside it.

    On main's engine before (10b4b88) the same click took 110 px of the
    stick, about its own footprint (101 px); with the cut reaching 240 px
    about 2,200, with 360 px (2026-12-04) about 4,000.
    """
    cases = [c for c in thin_objects.utensil_cases() if c.name.startswith("chopsticks")]
    if not cases:
        pytest.skip("no first-person frames in ../shared")
    case = cases[0]
    session = GrabCutSession(case.rgb)
    # As the box's cut before its straight-line prior (``_straight``): none of the sticks, on the box's grid
    # (a seed in the two corners of the box the sticks leave free).
    x0, y0, x1, y1 = thin_objects.loose_box(case.truth)
    before = np.zeros(case.truth.shape, bool)
    before[y0 : y0 + 20, x0 : x0 + 20] = before[y1 - 20 : y1, x1 - 20 : x1] = True
    assert not (before & case.truth).any()
    before = session.seed_mask(before)
    k = thin_objects.click(before, case.truth)
    assert k.label == "fg" and k.radius < 6
    after = session.stroke(k.points, k.label, k.radius)
    footprint = stroke_footprint(after.shape, k.points, k.radius)
    added = after & ~before
    assert np.count_nonzero(added & case.truth) > 30 * np.count_nonzero(footprint)
    assert np.count_nonzero(added & ~case.truth) < 0.01 * np.count_nonzero(added)
    assert not _far_changes(before, after, footprint).any()


def test_a_thin_stroke_follows_a_thin_part_and_leaves_a_wide_one_to_the_grid():
    """``_fine_cut``: on a 7 px bar the stroke takes the bar along its length; inside a wide patch it declines."""
    rng = np.random.default_rng(0)
    image = np.full((300, 600, 3), (190.0, 188.0, 180.0))  # a pale table
    bar = np.zeros((300, 600), np.uint8)
    cv2.line(bar, (40, 150), (560, 150), 1, 7)
    bar = bar.astype(bool)
    image[bar] = (150, 170, 160)  # a pale green stick
    image[20:120, 40:200] = (150, 170, 160)  # a wide patch of the same colour, not joined to it
    image = np.clip(cv2.GaussianBlur(image, (0, 0), 0.7) + rng.normal(0, 4, image.shape), 0, 255).astype(np.uint8)
    mask = np.zeros((300, 600), bool)
    crop = np.ones((5, 31), bool)  # a short stroke along the bar's middle
    mask[148:153, 285:316] = True
    flip = _fine_cut(image, mask, crop, (148, 285), True, 2.5)
    assert flip is not None
    assert (flip | mask)[150, 60:540].all()  # the bar, its whole length (240 px each way of the stroke)
    assert np.count_nonzero(flip & ~bar) < 0.05 * np.count_nonzero(flip)
    assert not flip[20:120, 40:200].any()
    patch = np.zeros((300, 600), bool)
    patch[68:73, 100:131] = True
    assert _fine_cut(image, patch, crop, (68, 100), True, 2.5) is None  # the grid's cut resolves the patch


def test_the_box_prior_follows_a_thin_object_to_the_edge_its_cut_missed():
    """``_crossing``: from the label to the box's edge band it misses, along a thin bar; not through clutter."""
    rng = np.random.default_rng(0)
    h, w = 120, 300
    image = np.full((h, w, 3), (120.0, 110.0, 100.0))  # a table
    bar = np.zeros((h, w), np.uint8)
    cv2.line(bar, (10, 10), (290, 112), 1, 3)  # a knife across the box, corner to corner
    bar = bar.astype(bool)
    image[bar] = (200, 200, 205)
    image[5:115, 5:70] = (230, 225, 215)  # a tall cup at the knife's handle, what the cut kept
    image[70:115, 90:140] = (60, 90, 40)  # and things of other colours on the table
    image[10:50, 150:230] = (40, 40, 60)
    image = np.clip(cv2.GaussianBlur(image, (0, 0), 0.7) + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)
    low = np.zeros((h, w), bool)
    low[5:115, 5:70] = True  # on every band but the right one
    path = _crossing(image, low)
    assert path is not None and path[:, -30:].any()  # it reaches the right band
    near = cv2.dilate(bar.view(np.uint8), np.ones((5, 5), np.uint8)).view(bool)
    assert np.count_nonzero(path & ~near & ~low) < 0.1 * np.count_nonzero(path & ~low)
    assert _crossing(image, np.ones((h, w), bool)) is None  # a label on every band needs no path
    # Across clutter of many colours (food on a plate) no path is of one material.
    clutter = rng.integers(0, 256, (h // 6, w // 6, 3)).astype(np.uint8)
    clutter = cv2.resize(clutter, (w, h), interpolation=cv2.INTER_NEAREST)
    assert _crossing(clutter, low) is None


def test_the_straight_line_prior_finds_a_thin_straight_object_and_not_clutter():
    """``_straight``: the line edge to edge along a thin bar of the table's colours; none across clutter."""
    rng = np.random.default_rng(0)
    h, w = 130, 210
    image = np.full((h, w, 3), (205.0, 200.0, 190.0))  # a pale table
    bar = np.zeros((h, w), np.uint8)
    cv2.line(bar, (10, 118), (200, 12), 1, 2)  # a chopstick across the box, 2 grid px wide
    image[bar.astype(bool)] = (185, 195, 185)  # a little darker and greener than the table
    image[80:125, 120:200] = (60, 90, 40)  # food on a plate, of strong edges
    image[20:60, 20:90] = (150, 150, 155)  # a laptop
    image = np.clip(cv2.GaussianBlur(image, (0, 0), 0.7) + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)
    ends = _straight(image, np.zeros((h, w), bool))
    assert ends is not None
    assert np.abs(ends - [(0, 123), (209, 7)]).max() <= 6  # the bar's line, to the box's edges
    clutter = cv2.resize(rng.integers(0, 256, (h // 6, w // 6, 3)).astype(np.uint8), (w, h),
                         interpolation=cv2.INTER_NEAREST)
    assert _straight(clutter, np.zeros((h, w), bool)) is None
    kept = np.zeros((h, w), bool)
    kept[bar.astype(bool)] = True
    assert _straight(image, kept) is None  # a line the box's cut kept needs no prior


def test_the_box_takes_a_pair_of_chopsticks_its_grid_cannot_resolve():
    """A box about two 8-10 px chopsticks (2-3 px on its grid): the straight-line prior and the full-resolution cut.

    The box's cut keeps a piece of food (IoU 0.00 before the prior); the
    line from edge to edge along a stick, followed at full resolution from
    its middle half, takes both sticks (they meet at their tips).
    """
    cases = [c for c in thin_objects.utensil_cases() if c.name.startswith("chopsticks")]
    if not cases:
        pytest.skip("no first-person frames in ../shared")
    case = cases[0]
    mask = GrabCutSession(case.rgb).box(*thin_objects.loose_box(case.truth))
    assert thin_objects.iou(mask, case.truth) >= 0.85  # 0.876


def _noc_scores(cases: list[thin_objects.Case]) -> dict[str, int]:
    """NoC@90 of each case as the bench runs it (a miss counts 20), asserting that every stroke is local."""
    scores = {}
    for case in cases:
        session = GrabCutSession(case.rgb)
        far = []

        def stroke(k, session=session, far=far):
            before = session.mask
            after = session.stroke(k.points, k.label, k.radius)
            far.append(int(_far_changes(before, after, stroke_footprint(after.shape, k.points, k.radius)).sum()))
            return after

        run = thin_objects.noc(lambda b, session=session: session.box(*b), stroke, case.truth)
        scores[case.name] = thin_objects.noc_score(run)
        assert not any(far), (case.name, far)
    return scores


@pytest.mark.slow
def test_noc90_on_real_frames_with_thin_objects():
    """NoC@90 (the box first, then clicks at the largest error's interior-most point), as the bench runs it.

    Mean over the real frames (DAVIS windows; with ``../shared`` the first-person
    frames with a fork, knife, spoon and chopsticks), a miss counting 20, and
    every stroke local.
    """
    scores = _noc_scores(thin_objects.all_cases())
    davis = [v for k, v in scores.items() if k in ("camel", "cows", "dog", "goat", "soapbox")]
    assert len(davis) == 5
    # 2026-12-04: 9.2 on the DAVIS frames and 6.78 on all nine (main's engine before issue 36: 11.6
    # and 10.0; before the full-resolution cut of thin strokes 9.56, with it reaching 240 px and
    # without the box prior 8.22; before the flood went past colours like the stroke's 11.2 and
    # 7.89, with it 10.8 and 7.67; with the box's sharpened foreground model too, the camel 8 -> 4,
    # the cows 10 -> 8, the dog 3 -> 2, the soapbox 13 -> 12); the goat takes all 20, the chopsticks
    # 7 (they missed before: IoU 0.33 at 20), the knife 5 (7 without the box prior). With the
    # straight-line prior (``_straight``) the chopsticks take 2 (the box 0.00 -> 0.88): 6.22 on all nine.
    # With an object click following a thin part of its colour along itself (``cut._along``): 8.2 on
    # the DAVIS frames and 5.56 on all nine (knife 4, cows 6, goat 19 at IoU 0.900, soapbox 10). With a
    # background click giving back the thin part it cut off (``cut._restored``: the knife's handle on the
    # mug the first click removes): the knife 3, 5.44 on all nine. With a re-cut that carries a pixel
    # against its colour only when it is like the stroke's (2026-12-05): 8.0 on the DAVIS frames, 5.33
    # on all nine (soapbox 8), but the goat's first frame misses (IoU 0.89 at 20; 19 before, at 0.900),
    # while the 20 later frames nobody tuned on go from 11.80 to 10.40 (``test_noc90_on_later_frames``).
    # The goal of issue 36, 5, is not met (see docs/benchmarks.md).
    assert np.mean(davis) <= 8.2, scores
    assert sum(v < thin_objects.MAX_CLICKS for v in davis) >= 4, scores
    if len(scores) > 5:
        assert np.mean(list(scores.values())) <= 5.4, scores
        assert scores["fork-00_007850_1"] <= 2 and scores["spoon-02_024150_3"] <= 3, scores
        assert scores["knife-01_007750_6"] <= 3 and scores["chopsticks-02_024150_3"] <= 2, scores


@pytest.mark.slow
def test_noc90_on_later_frames():
    """NoC@90 on the 20 later frames of the video windows, which no parameter was tuned on, every stroke local.

    2026-12-05: 12.05 before that day's changes (12.15 before issue 36's
    NoC work, 12.45 after its third pass), 11.80 with ``cut._along``, 10.40
    with the re-cut carrying a pixel against its colour only when it is like
    the stroke's.
    """
    scores = _noc_scores(thin_objects.later_cases())
    assert len(scores) == 20
    assert np.mean(list(scores.values())) <= 10.7, scores


def test_the_box_leaves_out_the_background_it_holds():
    """The camel (DAVIS): the box's cut, sharpened (``_sharpened``), leaves out the sand between its legs.

    Before the box's foreground model was fitted again on what is clearly
    object, the box kept the sand and the fence of the camel's colours: IoU 0.63.
    """
    case = thin_objects.davis_case(thin_objects.REAL_VIDEO / "camel-00024")
    mask = GrabCutSession(case.rgb).box(*thin_objects.loose_box(case.truth))
    assert thin_objects.iou(mask, case.truth) > 0.8  # 0.826 on 2026-12-04


def test_sharpening_drops_the_margins_colour_from_the_object_unless_the_box_cuts_through_it():
    """``_sharpened``: a pocket of the margin's colour inside the label goes; a label along the box's outline stays."""
    rng = np.random.default_rng(0)
    image = np.clip(rng.normal(100, 6, (80, 100, 3)), 0, 255)  # the margin's grey, and the pocket's
    image[20:60, 20:80] = (200, 60, 50)  # the object: a red block with a grey pocket cut into it
    image[30:60, 35:65] = np.clip(rng.normal(100, 6, (30, 30, 3)), 0, 255)
    image = image.astype(np.uint8)
    terms = _Terms.of_image(image)
    box = np.zeros((80, 100), bool)
    box[10:70, 10:90] = True
    low = np.zeros_like(box)
    low[20:60, 20:80] = True  # the first cut kept the pocket too
    gc = np.where(box, np.where(low, cv2.GC_PR_FGD, cv2.GC_PR_BGD), cv2.GC_BGD).astype(np.uint8)
    models = _first_models(image, np.where(box, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8), rng)
    sharp, _ = _sharpened(terms, gc, low, models)
    assert not sharp[35:58, 38:62].any() and sharp[20:28, 20:80].all()  # the pocket went, the block stayed
    # The block running out to the box's left edge (as where a box cuts through an object): left as it is.
    along = low.copy()
    along[20:60, 10:20] = True
    gc = np.where(box, np.where(along, cv2.GC_PR_FGD, cv2.GC_PR_BGD), cv2.GC_BGD).astype(np.uint8)
    image[20:60, 10:20] = (200, 60, 50)
    assert _sharpened(_Terms.of_image(image), gc, along, models)[0] is along
