"""Access rules of the scores area (see __init__): staff see the table, its figures and per-frame scores, and download them.

The pages and the downloads need nothing in the database (an empty table
renders), so ``url_values`` only names the download formats.
"""

from tests.app.access import STAFF

RULES = {
    "scores.index": (STAFF, 200),
    "scores.download": (STAFF, 200),
    "scores.comparison": (STAFF, 400),  # without two rows to compare
    "scores.figure": (STAFF, 200),
    "scores.frames": (STAFF, 200),
    "scores.frames_csv": (STAFF, 200),
}


def url_values(app, tmp_path) -> dict:
    return {"table_format": "csv", "figure_format": "svg"}
