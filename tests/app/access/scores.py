"""Access rules of the scores area (see __init__): staff see the table and download it.

The page and the downloads need nothing in the database (an empty table
renders), so ``url_values`` only names the download format.
"""

from tests.app.access import STAFF

RULES = {
    "scores.index": (STAFF, 200),
    "scores.download": (STAFF, 200),
}


def url_values(app, tmp_path) -> dict:
    return {"table_format": "csv"}
