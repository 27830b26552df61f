"""egonet.hands: the pixel-level hand detector and its skin-colour fallback, on cases checked by hand."""

import numpy as np
import pytest

from egonet.hands import FEATURES, HandModel, hand_features, skin_probability

SKIN, SHIRT, WALL = (205, 145, 115), (40, 60, 150), (90, 130, 90)


def frame(seed: int, *, hand_at: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 48x64 frame: a grey wall with a blue sleeve and a skin-coloured hand at its end, and its hand mask."""
    rng = np.random.default_rng(seed)
    rgb = np.empty((48, 64, 3), np.uint8)
    rgb[:] = WALL
    rgb[30:, hand_at - 12 : hand_at] = SHIRT
    hands = np.zeros((48, 64), bool)
    hands[26:44, hand_at : hand_at + 14] = True
    rgb[hands] = SKIN
    rgb = np.clip(rgb + rng.integers(-6, 7, rgb.shape), 0, 255).astype(np.uint8)
    return rgb, None, hands


def test_the_detector_learns_the_labelled_hands_and_finds_them_elsewhere_in_a_new_frame():
    model = HandModel(width=64, min_frames=3).fit([frame(s, hand_at=20 + 4 * s) for s in range(4)])
    assert model.source == "learned" and model.frames == 4 and model.name == "learned, 4 frames"
    rgb, _, hands = frame(9, hand_at=40)  # the hand where no training frame had it
    p = model.predict(rgb)
    assert p.shape == (48, 64) and p.dtype == np.float32 and 0 <= p.min() and p.max() <= 1
    inner = np.zeros_like(hands)
    inner[28:42, 42:52] = True  # away from the hand's edge, where resizing blurs
    assert p[inner].min() > 0.9
    assert p[:20].max() < 0.1  # the wall
    assert p[34:, 30:38].max() < 0.1  # the sleeve


def test_frames_without_hand_labels_teach_nothing_and_too_few_fall_back_on_skin_colour():
    rgb, dhg, _ = frame(0)
    model = HandModel(width=64, min_frames=2).fit([frame(1), (rgb, dhg, None), (rgb, dhg, np.zeros((48, 64), bool))])
    assert model.source == "skin colour" and model.frames == 1 and model.name == "skin colour"
    np.testing.assert_array_equal(model.predict(rgb), skin_probability(rgb))


def test_skin_probability_is_the_ycrcb_box_of_chai_and_ngan():
    # Skin (205, 145, 115): Y = .299 R + .587 G + .114 B = 159.5, Cr = .713 (R - Y) + 128 = 160.4,
    # Cb = .564 (B - Y) + 128 = 102.9: inside [133, 173] x [77, 127], 27.4, 12.6, 25.9 and 24.1 levels from the bounds.
    step = lambda t: 1 / (1 + np.exp(-t / 4))  # noqa: E731
    expected = step(27.4) * step(12.6) * step(25.9) * step(24.1)
    # The green wall: Y = 113.5, Cr = 111.2, 21.8 below 133; the blue sleeve: Cb = 177, 50 above 127.
    p = skin_probability(np.array([[SKIN, WALL, SHIRT]], np.uint8))
    assert p[0, 0] == pytest.approx(expected, abs=0.01) and p[0, 1] == pytest.approx(step(-21.8), abs=0.002)
    assert p[0, 2] < 1e-5


def test_the_state_is_plain_arrays_and_gives_back_the_same_maps():
    model = HandModel(width=64, min_frames=3).fit([frame(s) for s in range(3)])
    state = model.state()
    assert all(isinstance(v, np.ndarray) for v in state.values())
    assert state["w0"].shape == (len(FEATURES), 24) and int(state["frames"]) == 3
    again = HandModel(width=64, min_frames=3).load_state(state)
    rgb = frame(7)[0]
    np.testing.assert_array_equal(again.predict(rgb), model.predict(rgb))
    with pytest.raises(ValueError, match="not a hand model state"):
        HandModel(width=64, hidden=8).load_state(state)


def test_features_use_depth_when_there_is_some():
    rgb = frame(0)[0]
    dhg = np.zeros_like(rgb)
    dhg[..., 2] = 80
    without, with_depth = hand_features(rgb), hand_features(rgb, dhg)
    assert without.shape == with_depth.shape == (48, 64, len(FEATURES))
    at = FEATURES.index("has depth")
    assert (without[..., at:] == 0).all() and (with_depth[..., at] == 1).all()
    assert np.allclose(with_depth[..., FEATURES.index("depth")], 80 / 255)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: HandModel(width=8), "width must be an int >= 16"),
        (lambda: HandModel().fit([(np.zeros((4, 4), np.uint8), None, None)]), "rgb must be a uint8"),
        (lambda: HandModel().fit([(np.zeros((4, 4, 3), np.uint8), None, np.ones((4, 5), bool))]), "hands must be None or a bool"),
        (lambda: HandModel().predict(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint8)), "dhg must be None or a uint8"),
    ],
)
def test_bad_input_is_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()
