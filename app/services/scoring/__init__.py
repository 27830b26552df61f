"""The score table (the paper's Table 2 for this project's data): MF and AP per activity.

Rows, in this order:

* **models**: each completed training run (``app.services.training``),
  scored on its held-out predictions only (the activity left out in each
  leave-one-activity-out fold, or the test split of a single split);
* **baselines** (``egonet.baselines``), scored on every labelled frame:
  the Action-Object Prior "AOP", fitted inside each leave-one-activity-out
  fold (the frames of activity A are scored with the mean ground-truth mask
  of the labelled frames of every *other* activity), the "centre prior" and
  bottom-up "saliency" (spectral residual);
* **people**: each participant of the chosen studies, scored on exactly the
  frames they saw and answered, their click soft masks against the same
  ground truth; MF only, as in the paper (AP says little about near-binary
  maps).

Columns are the activities and their mean. Every cell holds MF, AP and the
number of frames scored. The metric is ``egonet.metrics`` (see
:data:`DEFINITION`): by default pixel counts are pooled over all the frames
of the activity at 99 thresholds ``k / 100``. The **mean** column is the
unweighted mean of a row's per-activity values, over the activities the row
has frames in (marked with ``*`` when that is not every column). Each row
also keeps the curve pooled over all its frames, for the overall
precision-recall plot.

Ground truth is each frame's finished annotation
(``app.services.ground_truth``). Computing a row streams its maps through
one ``ScoreAccumulator`` per activity and stores the accumulators' sufficient
statistics (per-threshold TP/FP/FN and per-map curve sums) as JSON under
``CACHE_ROOT/scores/``, named by a hash of everything the row depends on
(the ground-truth annotations' ids, versions and update times, the run or the
participant's answers, the number of thresholds, the scorer's version). A
later report with the same inputs reads the statistics back instead of
scoring again, in pooled or per-image mode alike.

The package, one module per concern:

* ``report``: :func:`build_report`, what to score and the jobs that fill the rows;
* ``sources``: ground truth and each source's statistics per activity;
* ``cache``: the statistics on disk;
* ``table``: :class:`Report` and its rows, as text, CSV, LaTeX or JSON;
* ``plots``: :func:`pr_plot`, the precision-recall plots of the Scores page.
"""

from app.services.scoring.plots import PLOT_MARGIN, Plot, PlotLine, pr_plot
from app.services.scoring.report import ScoringProblem, available_runs, available_studies, build_report
from app.services.scoring.table import ALL, DEFINITION, Cell, Curve, Report, Row

__all__ = [
    "ALL",
    "DEFINITION",
    "PLOT_MARGIN",
    "Cell",
    "Curve",
    "Plot",
    "PlotLine",
    "Report",
    "Row",
    "ScoringProblem",
    "available_runs",
    "available_studies",
    "build_report",
    "pr_plot",
]
