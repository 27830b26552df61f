"""Access rules of the scores area (see __init__)."""

RULES: dict = {}


def url_values(app, tmp_path) -> dict:
    return {}
