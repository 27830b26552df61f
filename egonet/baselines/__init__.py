"""The baselines of the paper's Table 2 (and two references), behind one protocol.

Every baseline answers ``predict(rgb, dhg) -> float32 (H, W)`` in [0, 1]
(:class:`Predictor`); the learned ones are :class:`TrainedBaseline`
subclasses, fitted on the training activities' :class:`TrainingFrame`
objects and saved as plain data (``egonet.baselines.protocol`` says how).
One module per method:

* ``aop``: :class:`ActionObjectPrior`, the paper's AOP (learned: the mean mask);
* ``egonet.saliency``: :class:`GraphSaliency`, the paper's GBVS (learns nothing,
  as in the paper);
* ``handled``: :class:`HandledViewedObj`, the paper's Handled+Viewed-Obj (learned: a hand detector,
  ``egonet.hands``), and :class:`HandledViewedObject`, its regions scored by their distance to given hands;
* ``simple``: :class:`CenterPrior` and :class:`SpectralResidualSaliency`,
  references that are not rows of the paper.

:data:`BASELINES` maps each row's key (stable: it names the row in URLs and
exports, ``baseline:<key>``) to its class; the class's ``name`` is the
paper's name of the row, its ``version`` part of every cache key. A new
method is one module and one line here.

Example:
    >>> import numpy as np
    >>> rgb = np.zeros((48, 64, 3), dtype=np.uint8)
    >>> build_baseline("center").predict(rgb, None).shape
    (48, 64)
"""

from __future__ import annotations

from typing import Any

from egonet.baselines.aop import ActionObjectPrior
from egonet.baselines.fpmcg import FirstPersonMCG
from egonet.baselines.handled import HandledViewedObj, HandledViewedObject
from egonet.baselines.judd import Judd
from egonet.baselines.protocol import (
    Predictor,
    Summary,
    TrainedBaseline,
    TrainingFrame,
    fit_folds,
    load_baseline,
    params,
    save_baseline,
)
from egonet.baselines.salobj import SalientObjectDepth
from egonet.baselines.simple import CenterPrior, SpectralResidualSaliency
from egonet.errors import EgonetError
from egonet.saliency import GraphSaliency

__all__ = [
    "BASELINES",
    "ActionObjectPrior",
    "CenterPrior",
    "FirstPersonMCG",
    "GraphSaliency",
    "HandledViewedObj",
    "HandledViewedObject",
    "Judd",
    "Predictor",
    "SalientObjectDepth",
    "SpectralResidualSaliency",
    "Summary",
    "TrainedBaseline",
    "TrainingFrame",
    "build_baseline",
    "fit_folds",
    "is_trained",
    "load_baseline",
    "params",
    "save_baseline",
]

BASELINES: dict[str, type] = {
    "judd": Judd,
    "gbvs": GraphSaliency,
    "handled": HandledViewedObj,
    "aop": ActionObjectPrior,
    "fpmcg": FirstPersonMCG,
    "salobj": SalientObjectDepth,
    "center": CenterPrior,
    "saliency": SpectralResidualSaliency,
}
"""Row key -> class, in the order of the paper's Table 2 (then the references)."""


def is_trained(key: str) -> bool:
    """Whether the baseline ``key`` learns from labelled frames (a :class:`TrainedBaseline`)."""
    return issubclass(_class(key), TrainedBaseline)


def _class(key: str) -> type:
    if key not in BASELINES:
        valid = ", ".join(f"{k} ({c.name})" for k, c in BASELINES.items())
        raise EgonetError(f"unknown baseline {key!r}; valid names: {valid}", field="name")
    return BASELINES[key]


def build_baseline(key: str, **settings: Any) -> Any:
    """A baseline by its key with these settings (a learned one unfitted: call ``fit``).

    Raises:
        EgonetError: An unknown key (the message lists the valid ones), or a bad setting.

    Example:
        >>> type(build_baseline("saliency")).__name__
        'SpectralResidualSaliency'
    """
    cls = _class(key)
    try:
        return cls(**settings)
    except TypeError as exc:
        raise EgonetError(f"{key}: {exc}", field="settings") from None
