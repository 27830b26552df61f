"""EgoNet science: first-person action-object detection.

Arrays in, arrays out. This package never imports Flask or a database layer;
import the submodules you need (``egonet.synth``, ``egonet.dhg``,
``egonet.metrics``, ...). Importing ``egonet`` itself loads nothing heavy.
"""

__version__ = "0.1.0"
