"""Human studies: building a study, running timed sessions, soft masks and exports.

One module per concern; callers use the names re-exported here
(``from app.services import studies; studies.create_study(...)``):

* ``building``: settings, the frames a study draws, participants, codes, links.
* ``session``: the participant's side: entering, consent, timing, trials, answers.
* ``overview``: the admin's progress tables and summaries.
* ``masks``: the superpixel cache, soft masks (and their means), overlays.
* ``exports``: CSV, JSON and mask PNGs.
* ``common``: ``StudyProblem``, the server clock ``now()`` and ``LATE_GRACE_S``.
"""

from app.services.studies.building import (
    CODE_ALPHABET,
    DEFAULT_CONSENT,
    DEFAULT_INSTRUCTIONS,
    DEFAULT_SUPERPIXELS,
    SUPERPIXEL_OPTIONS,
    add_participants,
    check_superpixels,
    create_study,
    eligible_counts,
    format_code,
    new_seed,
    order_seed,
)
from app.services.studies.common import LATE_GRACE_S, StudyProblem, now
from app.services.studies.exports import EXPORTS, TRIAL_COLUMNS, export_csv, export_json, export_to_folder, mask_files, masks_zip
from app.services.studies.masks import (
    answered_trials,
    cached_superpixels,
    mask_png,
    mean_soft_mask,
    overlay_png,
    participant_soft_masks,
    precompute_superpixels,
    settings_key,
    study_participants,
    superpixel_labels,
    trial_soft_mask,
)
from app.services.studies.overview import Progress, StudySummary, activity_table, answered_counts, progress, study_summaries
from app.services.studies.session import (
    MAX_CLICKS,
    MAX_EVENTS,
    Answer,
    ClientEvent,
    SessionState,
    answer_consent,
    link_participant,
    participant_by_code,
    participant_of,
    refresh,
    session_state,
    start_session,
    step,
    submit,
    trial_frame,
    use_link,
)
