"""The Scores page: Table 2 for this project, with PR curves and downloads."""

from flask import Blueprint

bp = Blueprint("scores", __name__, url_prefix="/scores")
