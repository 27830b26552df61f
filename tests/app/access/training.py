"""Access rules of the training area (see __init__)."""

RULES: dict = {}


def url_values(app, tmp_path) -> dict:
    return {}
