"""Training runs: start through the queue, watch progress, list checkpoints."""

from flask import Blueprint

bp = Blueprint("training", __name__, url_prefix="/training")
