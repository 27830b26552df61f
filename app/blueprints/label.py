"""Labelling pages and API: GrabCut-assisted action-object outlines."""

from flask import Blueprint

bp = Blueprint("label", __name__)
