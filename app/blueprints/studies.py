"""Human-study builder and results (admin pages)."""

from flask import Blueprint

bp = Blueprint("studies", __name__, url_prefix="/studies")
