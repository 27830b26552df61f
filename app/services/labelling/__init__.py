"""Labelling: a person's annotation of a frame, its review, the queues, and
the server-side GrabCut sessions that help draw it; import it from here.

    * ``annotations``: loading and saving an annotation (version checks,
      statuses) and its instances;
    * ``grabcut``: the GrabCut sessions (their saved state, this worker's
      caches, locks, box / stroke / undo and what each may cost);
    * ``review``: accept / reject, a reviewer's fix, the annotators' and reviewers' queues;
    * ``history``: the labelling page's undo / redo history, kept on the server;
    * ``presence``: who else has a frame open or an annotation of it;
    * ``masks``: masks as COCO RLE and PNG, checked before they are decoded;
    * ``propagation``: carrying an annotation to the next / from the previous
      frame of its sequence, and the sequence's filmstrip;
    * ``suggest``: proposals ("Suggest"), accepting them, batches;
    * ``proposers``: who proposes: a trained run, or depth, handled, saliency (no run needed);
    * ``regions``: the regions of a probability map that Suggest proposes.
"""

from app.services.labelling.annotations import (
    AUTHOR_STATUSES,
    MAX_INSTANCES,
    MAX_TIME_DELTA_S,
    add_time,
    check_key,
    check_open,
    check_open_frame,
    empty_mask,
    get_annotation,
    get_frame,
    instance_of,
    reopen_annotation,
    save_annotation,
    upload_instance_mask,
    user_annotation,
)
from app.services.labelling.grabcut import (
    check_box,
    check_stroke,
    grabcut_box,
    grabcut_keys,
    grabcut_mask,
    grabcut_stroke,
    grabcut_undo,
    stroke_pixels,
)
from app.services.labelling.history import MAX_HISTORY_BYTES, get_history, put_history
from app.services.labelling.masks import Rle, decode_rle
from app.services.labelling.propagation import (
    FILMSTRIP_MAX,
    Filmstrip,
    adjacent_frame,
    copy_from_previous,
    filmstrip,
    RANGE_MAX,
    RANGE_OBJECT_FRAMES,
    propagate,
)
from app.services.labelling.proposers import SOURCES as SUGGEST_SOURCES
from app.services.labelling.proposers import SuggestProblem, resolve_run, source_choices, suggestion_runs
from app.services.labelling.suggest import (
    BatchReport,
    Queued,
    Suggestion,
    accept_proposal,
    queue_suggestions,
    suggest_frame,
    suggest_frames,
    suggest_from_page,
)
from app.services.labelling.regions import proposal_regions
from app.services.labelling.presence import HEARTBEAT_S, PRESENCE_TTL_S, leave, mark_present, others_on
from app.services.labelling.review import (
    INSTANCE_COLOURS,
    annotator_queue,
    fix_annotation,
    instance_colour,
    mask_thumbnail,
    next_to_review,
    next_unlabelled,
    review_annotation,
    review_queue,
)
from egonet.rle import max_chars as max_rle_chars

__all__ = [
    "AUTHOR_STATUSES",
    "INSTANCE_COLOURS",
    "FILMSTRIP_MAX",
    "HEARTBEAT_S",
    "MAX_HISTORY_BYTES",
    "MAX_INSTANCES",
    "PRESENCE_TTL_S",
    "MAX_TIME_DELTA_S",
    "BatchReport",
    "Filmstrip",
    "Queued",
    "Rle",
    "SUGGEST_SOURCES",
    "SuggestProblem",
    "Suggestion",
    "accept_proposal",
    "add_time",
    "adjacent_frame",
    "annotator_queue",
    "check_box",
    "check_key",
    "check_open",
    "check_open_frame",
    "check_stroke",
    "copy_from_previous",
    "decode_rle",
    "empty_mask",
    "filmstrip",
    "fix_annotation",
    "get_annotation",
    "get_frame",
    "get_history",
    "grabcut_box",
    "grabcut_keys",
    "grabcut_mask",
    "grabcut_stroke",
    "grabcut_undo",
    "instance_colour",
    "instance_of",
    "leave",
    "mark_present",
    "mask_thumbnail",
    "max_rle_chars",
    "next_to_review",
    "next_unlabelled",
    "others_on",
    "propagate",
    "RANGE_MAX",
    "RANGE_OBJECT_FRAMES",
    "proposal_regions",
    "put_history",
    "queue_suggestions",
    "reopen_annotation",
    "resolve_run",
    "review_annotation",
    "review_queue",
    "save_annotation",
    "source_choices",
    "stroke_pixels",
    "suggest_frame",
    "suggest_frames",
    "suggest_from_page",
    "suggestion_runs",
    "upload_instance_mask",
    "user_annotation",
]
