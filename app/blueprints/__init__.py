"""Blueprints, one per area, and the navigation bar that links them."""

from flask import current_app, request, url_for

from app.models import Role
from app.queue import WORKER_GONE_S, worker_last_seen
from app.security import access_of, current_role

# (label, endpoint): shown when the endpoint exists and the user's role may use it.
NAVIGATION = [
    ("Activities", "frames.index"),
    ("Label", "label.index"),
    ("Studies", "studies.index"),
    ("Training", "training.index"),
    ("Scores", "scores.index"),
    ("Users", "users.index"),
]
# Blueprints whose pages belong under another area's tab (an export is made from the Label page).
TAB_OF = {"exports": "label"}
# The signed-in user's own page (their password), linked from their name in the top bar.
ACCOUNT = "users.account"


def _may_use(endpoint: str, role: Role | None) -> bool:
    view = current_app.view_functions.get(endpoint)
    if view is None or role is None:
        return False
    allowed = access_of(view)
    return allowed is None or role in allowed


def navigation() -> dict:
    role = current_role()
    items = []
    for label, endpoint in NAVIGATION:
        if _may_use(endpoint, role):
            area = TAB_OF.get(request.blueprint, request.blueprint)
            active = area == endpoint.split(".")[0] and request.endpoint != ACCOUNT
            items.append({"label": label, "url": url_for(endpoint), "active": active})
    return {"navigation": items, "account_url": url_for(ACCOUNT) if _may_use(ACCOUNT, role) else None,
            # for pages with queued work (templates/_worker.html); asked only where such a page calls it
            "worker_last_seen": worker_last_seen, "worker_gone_s": WORKER_GONE_S}
