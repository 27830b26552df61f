"""Access rules of the label area (see __init__)."""

RULES: dict = {}


def url_values(app, tmp_path) -> dict:
    return {}
