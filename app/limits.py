"""Constants the app's modules share; a leaf that imports nothing of the app."""

# Ids are at most this (SQL INTEGER, the id columns' type; PostgreSQL refuses
# to compare them with anything larger): larger path ids match no route (404),
# larger ids in bodies and queries are a 400 (app.validation).
MAX_ID = 2**31 - 1
# What a token may hold: a link's (``/s/l/<token>``, ``/s/o/<token>``), a completion code, a condition
# name or a platform's id. In a URL another shape matches no route (404) before any query.
TOKEN_REGEX = r"[A-Za-z0-9_.\-]{1,64}"
# The key that signs cookies when none is configured lives in this file of the
# instance folder; a shorter key is refused.
SECRET_KEY_FILE = "secret_key"
MIN_SECRET_KEY_LENGTH = 32
