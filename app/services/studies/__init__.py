"""Human studies: building a study, recruiting, running timed sessions, checks, soft masks and exports.

One module per concern; callers use the names re-exported here
(``from app.services import studies; studies.create_study(...)``):

* ``building``: settings, the frames a study draws, editing, copying, deleting, status.
* ``protocol``: display, completion, open link, comprehension and condition settings.
* ``definition``: the study as a JSON file (``flask egonet study-create``, the builder's download).
* ``recruiting``: the open link, platforms' ids, places (cap, quotas), conditions, codes, trial orders.
* ``session``: the participant's steps: entering, consent, questions, practice, start, end.
* ``trials``: serving trials on time, answers, refusing late ones.
* ``checks``: answer regions, who passed the checks, completion codes.
* ``overview``: the admin's progress tables and summaries.
* ``masks``: the superpixel cache, soft masks (and their means), overlays.
* ``exports``: CSV, JSON and mask PNGs.
* ``withdrawal``: deleting one participant's data on request.
* ``common``: ``StudyProblem``, the server clock ``now()``, ``LATE_GRACE_S`` and value checks.
"""

from app.services.studies.building import (
    DEFAULT_CONSENT,
    DEFAULT_INSTRUCTIONS,
    DEFAULT_SUPERPIXELS,
    REFERENCE_WIDTH,
    SUPERPIXEL_OPTIONS,
    check_superpixels,
    create_study,
    delete_study,
    duplicate_study,
    eligible_counts,
    entered,
    format_code,
    new_seed,
    scaled_sigma,
    set_status,
    sigma_for,
)
from app.services.studies.checks import Checks, checks_of
from app.services.studies.common import LATE_GRACE_S, StudyProblem, now
from app.services.studies.definition import definition_of, study_from_definition, update_from_definition
from app.services.studies.exports import EXPORTS, TRIAL_COLUMNS, export_csv, export_json, export_to_folder, mask_files, masks_zip
from app.services.studies.masks import (
    CapSummary,
    answered_trials,
    cached_superpixels,
    cap_summary,
    condition_name,
    frame_regions,
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
from app.services.studies.overview import Progress, StudySummary, activity_table, answered_counts, condition_table, progress, study_summaries
from app.services.studies.protocol import settings_of
from app.services.studies.recruiting import (
    CODE_ALPHABET,
    PLATFORMS,
    Arrival,
    add_participants,
    admit,
    availability,
    by_external_id,
    example_frame,
    may_resume,
    mturk_submit_hosts,
    mturk_submit_url,
    open_link_study,
    order_seed,
    parse_arrival,
    places_taken,
    platform_urls,
    refusal,
    release,
    returning,
    set_active,
)
from app.services.studies.session import (
    answer_comprehension,
    answer_consent,
    check_may_enter,
    close_overdue,
    completion,
    link_participant,
    participant_by_code,
    participant_of,
    record_environment,
    refresh,
    start_session,
    step,
    use_link,
)
from app.services.studies.trials import MAX_CLICKS, MAX_EVENTS, Answer, ClientEvent, SessionState, session_state, submit, trial_frame
from app.services.studies.withdrawal import withdraw
