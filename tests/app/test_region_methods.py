"""Studies keep the region method they were made with when the default changes (issue 17).

The default became the boundary-based hierarchy (``bench/bench_regions.py``);
a study made before records SLIC in ``Study.superpixels`` and must go on
projecting its clicks onto SLIC regions, or its participants' masks, scores
and exports would change under it.
"""

import numpy as np

from app.extensions import db
from app.models import Activity, Frame
from app.models.studies import Study
from app.services import media, studies
from app.services.demo import create_demo
from egonet import clicks as egonet_clicks
from egonet import io

# What every study made before issue 17 recorded (the old defaults).
OLD_SLIC = {"method": "slic", "n_segments": 400, "compactness": 10.0, "max_side": 640}


def test_an_old_study_keeps_slic_and_a_new_one_records_the_new_default(ctx):
    create_demo(frames_per_activity=2, unlabelled_fraction=0, width=96, height=72)
    activity_ids = list(db.session.execute(db.select(Activity.id)).scalars())[:2]
    old = studies.create_study(name="before", activity_ids=activity_ids, frames_per_activity=1, seed=1, superpixels=OLD_SLIC)
    new = studies.create_study(name="after", activity_ids=activity_ids, frames_per_activity=1, seed=1)
    db.session.expire_all()
    old, new = db.session.get(Study, old.id), db.session.get(Study, new.id)
    assert old.superpixels == OLD_SLIC
    assert new.superpixels == {"method": "hierarchical", "fine_regions": egonet_clicks.SUPERPIXEL_DEFAULTS.fine_regions,
                               "level": egonet_clicks.SUPERPIXEL_DEFAULTS.level,
                               "max_region_share": egonet_clicks.SUPERPIXEL_DEFAULTS.max_region_share, "max_side": 640}

    frame = db.session.get(Frame, old.frames[0].frame_id)
    rgb = io.read_image(media.local_path(frame.rgb_path))
    slic = egonet_clicks.superpixels(rgb, method="slic", n_segments=400, compactness=10.0, max_side=640)
    hierarchy = egonet_clicks.superpixels(rgb)
    assert not np.array_equal(slic, hierarchy)  # the two methods differ on this frame
    np.testing.assert_array_equal(studies.superpixel_labels(frame, old.superpixels), slic)
    np.testing.assert_array_equal(studies.superpixel_labels(frame, new.superpixels), hierarchy)
    # Each study's labels are cached under its own settings; neither reads the other's.
    assert studies.cached_superpixels(frame, old.superpixels) and studies.cached_superpixels(frame, new.superpixels)
    np.testing.assert_array_equal(studies.superpixel_labels(frame, old.superpixels), slic)
