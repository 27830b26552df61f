"""The score table (the paper's Table 2 for this project's data): MF and AP per activity.

Rows, in this order:

* **models**: each completed training run (``app.services.training``),
  scored on its held-out predictions only (the activity left out in each
  leave-one-activity-out fold, or the test split of a single split);
* **baselines** (``egonet.baselines``), scored on every labelled frame,
  with the paper's names (Judd, GBVS, Handled+Viewed-Obj, AOP, FP-MCG,
  salObj+depth; then the "centre prior" and "saliency" references); the
  learned ones are fitted per leave-one-activity-out fold (the frames of
  activity A are mapped by a model fitted on the labelled frames of every
  *other* activity; ``fitting``), in the worker when that takes long;
  in a table of models trained on some activities (``trained_on``: the
  runs trained on every frame of them, the paper's Tables 3 and 4) they are
  fitted once on those activities and the columns are the other activities;
* **people**: each participant of the chosen studies, scored on exactly the
  frames they saw and answered, their click soft masks against the same
  ground truth; MF only, as in the paper (AP says little about near-binary
  maps).

Columns are the activities (or, with ``columns="sequences"``, each
activity's recordings) and their mean. Every cell holds the chosen
convention's statistics (``egonet.metrics.frames``: ``pooled``, the
default, ``ois-mean``, ``mean-curve`` or ``ods-ois``), their 95 % bootstrap
intervals (none below ``egonet.metrics.MIN_FRAMES`` frames in an activity:
"n too small") and the number of frames scored. Frames without action-object
pixels are counted and, in the per-frame means, treated as the ``empty``
policy says (left out by default). Every report carries its
:class:`Provenance` (how its numbers were made, down to the code version). By default (``frames="shared"``) every row of
an activity is scored on the frames all those rows have; ``"each"`` scores
each row on all its frames and marks the best only among rows on the same
frames. Runs that differ only in their seed are grouped (mean and standard
deviation across the seeds, each seed below). The **mean** column is the
unweighted mean of a row's per-activity values, over the activities the row
has frames in (marked with ``*`` when that is not every column). Each row
also keeps the curve pooled over all its frames, for the overall
precision-recall plot. Participants' unanswered trials count as empty maps
unless ``answered_only``.

Ground truth is each frame's finished annotation
(``app.services.ground_truth``). Computing a row streams its maps one at a
time into per-frame counts at every threshold and stores them as ``.npz``
under ``CACHE_ROOT/scores/``, named by a hash of everything the row depends
on (the ground-truth annotations' ids, versions and update times, the run or
the participant's trials, the number of thresholds, the scorer's version).
A later report with the same inputs reads the counts back instead of
scoring again, under any convention, frames or resamples.

The package, one module per concern:

* ``report``: :func:`build_report`, what to score and the jobs that fill the rows;
* ``sources``: ground truth and each source's per-frame counts;
* ``fitting``: the learned baselines' folds, fitted and cached (or queued for the worker);
* ``cache``: the per-frame counts on disk;
* ``rows``: frames per row (shared or each), seed groups, intervals, paired comparisons;
* ``cells``: the table's labels, cells, curves, rows and paired differences;
* ``table``: :class:`Report` and a :class:`Comparison`;
* ``provenance``: :class:`Provenance`, the facts every format carries, and
  the seed paper's BibTeX; :func:`p_text`;
* ``methods``: the methods paragraph, from the provenance and the table's own frames per kind of row;
* ``formats``: their renderers (text, CSV, LaTeX, JSON, methods), mixins of the two;
* ``plots``: :func:`pr_plot` (the page's SVG) and :func:`pr_figure` (SVG/PDF files);
* ``perframe``: :func:`frame_table`, each frame's own scores in one activity.
"""

from app.services.scoring.perframe import FrameTable, frame_table
from app.services.scoring.plots import PLOT_MARGIN, Plot, PlotLine, default_plot_rows, pr_figure, pr_plot
from app.services.scoring.report import available_runs, available_studies, build_report, load_sources, table_runs, training_sets
from app.services.scoring.sources import baseline_rows
from app.services.scoring.rows import ScoringProblem
from app.services.scoring.cells import (
    ALL,
    FRAMES,
    MEAN,
    METRIC_SHORT,
    METRIC_TITLES,
    STATISTIC_LABELS,
    Cell,
    Curve,
    Difference,
    Row,
    definition,
)
from app.services.scoring.provenance import EMPTY_TITLES, HumanMaps, Provenance, p_text
from app.services.scoring.table import Comparison, Report

__all__ = [
    "ALL",
    "FRAMES",
    "MEAN",
    "METRIC_SHORT",
    "METRIC_TITLES",
    "PLOT_MARGIN",
    "STATISTIC_LABELS",
    "Cell",
    "Comparison",
    "Curve",
    "Difference",
    "EMPTY_TITLES",
    "FrameTable",
    "HumanMaps",
    "Plot",
    "PlotLine",
    "Provenance",
    "Report",
    "Row",
    "ScoringProblem",
    "available_runs",
    "available_studies",
    "baseline_rows",
    "build_report",
    "default_plot_rows",
    "definition",
    "frame_table",
    "load_sources",
    "p_text",
    "pr_figure",
    "pr_plot",
    "table_runs",
    "training_sets",
]
