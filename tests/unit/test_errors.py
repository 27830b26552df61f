"""egonet's public checks raise EgonetError naming the argument (or file) at fault.

The app turns ``.field`` into the JSON's ``fields`` and the CLI's one line,
so each module's checks must name the right one. One check per module.
"""

import numpy as np
import pytest

from egonet import baselines, clicks, dhg, io, metrics, synth
from egonet.errors import EgonetError

@pytest.mark.parametrize(
    "call, field",
    [
        (lambda: io.check_rgb(np.zeros((4, 4), np.uint8), "image"), "image"),
        (lambda: dhg.decode_dhg(np.zeros((4, 4), np.uint8)), "dhg"),
        (lambda: dhg.encode_dhg(np.ones((4, 4)), np.zeros((4, 4)), np.zeros((4, 4), np.float32)), "gray"),
        (lambda: clicks.click_gaussian((4, 4), [(1, 1)], sigma=0), "sigma"),
        (lambda: clicks.click_gaussian((4, 4), [(9, 1)]), "clicks"),
        (lambda: metrics.score_maps([], []), "probs"),
        (lambda: metrics.count_stats(np.zeros((2, 2)), np.zeros((2, 2), bool), thresholds=0), "thresholds"),
        (lambda: baselines.build_baseline("nope"), "name"),
        (lambda: baselines.build_baseline("aop", size=(0, 1)), "size"),
        (lambda: synth.render_frame("juggling", 0), "activity"),
        (lambda: synth.render_frame("cooking", 0, width=0), "width"),
    ],
    ids=["io", "dhg", "dhg-gray", "clicks-sigma", "clicks", "metrics", "metrics-thresholds", "baselines", "baselines-size",
         "synth", "synth-width"],
)
def test_public_checks_name_their_field(call, field):
    with pytest.raises(EgonetError) as info:
        call()
    assert info.value.field == field
    assert isinstance(info.value, ValueError)  # callers that catch ValueError keep working


def test_media_errors_name_the_file(tmp_path):
    path = tmp_path / "frame.png"
    path.write_bytes(b"not a png")
    with pytest.raises(io.MediaError) as info:
        io.read_image(path)
    assert info.value.field == str(path)
    assert info.value.reason == "not a readable image (corrupt or unknown format)"


def test_reason_drops_the_field_prefix_only_when_the_message_has_it():
    assert EgonetError("radius: must be positive", field="radius").reason == "must be positive"
    assert EgonetError("sigma must be positive", field="sigma").reason == "sigma must be positive"
