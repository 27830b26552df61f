"""The participant side of a human study: consent, instructions, timed trials."""

from flask import Blueprint

bp = Blueprint("study", __name__, url_prefix="/s")
