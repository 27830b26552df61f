"""Blueprints, one per area, and the navigation bar that links them."""

from flask import current_app, request, url_for

from app.security import access_of, current_role

# (label, endpoint): shown when the endpoint exists and the user's role may use it.
NAVIGATION = [
    ("Activities", "frames.index"),
    ("Label", "label.index"),
    ("Studies", "studies.index"),
    ("Training", "training.index"),
    ("Scores", "scores.index"),
]


def navigation() -> dict:
    role = current_role()
    items = []
    for label, endpoint in NAVIGATION:
        view = current_app.view_functions.get(endpoint)
        if view is None or role is None:
            continue
        allowed = access_of(view)
        if allowed is None or role in allowed:
            active = (request.endpoint or "").split(".")[0] == endpoint.split(".")[0]
            items.append({"label": label, "url": url_for(endpoint), "active": active})
    return {"navigation": items}
