"""Exchanging action-object masks with other tools: PNG masks, COCO JSON, the frames' images.

An export is a folder (or a zip holding the same files)::

    masks/<activity>/<sequence>/<frame>.png               the frame's mask: binary 0/255, the union of the
                                                          instances of its best exported annotation (reviewed,
                                                          then done, ...; the latest first): its ground truth
    annotators/<user>/<activity>/<sequence>/<frame>.png   every exported annotation's union, one per frame and annotator
    annotations.json                                      COCO: one image per frame, one annotation per instance of
                                                          every exported annotation (RLE by pycocotools), with
                                                          ``attributes`` annotator, status, kind, label
    images/<activity>/<sequence>/<frame>.<ext>            the frame's RGB file as stored (only when asked for)

``masks/`` and ``annotators/`` come with ``--format png`` or ``both``,
``annotations.json`` with ``coco`` or ``both``. ``<frame>`` is the frame's
source name (its file stem when imported from a folder); a name used twice
in a sequence gets ``~`` and the start of the frame's content hash. COCO
images carry the frame's identity (activity, sequence, name, content hash)
and, under ``egonet.annotations``, each exported annotation's annotator,
status, "no action-object" flag, time spent, review and mask file, and
whether it is the one in ``masks/`` (``frame_mask``).

``import_annotations`` reads any of these back onto frames already in the
database (matched by content hash, else by name): ``annotations.json``
when present (everything), else ``annotators/`` (one author per folder,
no statuses), else ``masks/``. An export imported into a database with the
same frames and exported again gives the same files, byte for byte.
"""

from app.services.exchange.jobs import (
    build_export,
    export_file,
    fits_a_request,
    get_export,
    queue_export,
    recent_exports,
)
from app.services.exchange.reading import ImportReport, import_annotations
from app.services.exchange.selection import (
    ANNOTATORS_DIR,
    COCO_FILE,
    DEFAULT_STATUSES,
    EXPORTABLE_STATUSES,
    FORMATS,
    IMAGES_DIR,
    MASKS_DIR,
    ExchangeProblem,
    ExportOptions,
    FrameExport,
    NothingToExport,
    Plan,
    activity_names,
    annotator_names,
    frame_names,
    plan_export,
    safe,
    select_export,
)
from app.services.exchange.writing import ExportReport, export_folder, export_zip, write_export, write_zip

__all__ = [
    "ANNOTATORS_DIR",
    "COCO_FILE",
    "DEFAULT_STATUSES",
    "EXPORTABLE_STATUSES",
    "FORMATS",
    "IMAGES_DIR",
    "MASKS_DIR",
    "ExchangeProblem",
    "ExportOptions",
    "ExportReport",
    "FrameExport",
    "ImportReport",
    "NothingToExport",
    "Plan",
    "activity_names",
    "annotator_names",
    "build_export",
    "export_file",
    "export_folder",
    "export_zip",
    "fits_a_request",
    "frame_names",
    "get_export",
    "import_annotations",
    "plan_export",
    "queue_export",
    "recent_exports",
    "safe",
    "select_export",
    "write_export",
    "write_zip",
]
