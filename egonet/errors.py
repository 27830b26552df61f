"""The one error egonet raises for input it cannot use, and the base of its others.

``EgonetError`` is a ``ValueError`` whose ``field`` names the argument or
file at fault and whose message says what to do instead. The app maps it
onto its own error (a 400 naming the field, a one-line CLI failure), so a
check written once in egonet reaches the user in words.

Example::

    >>> raise EgonetError("radius: must be a positive number of pixels", field="radius")
    Traceback (most recent call last):
    ...
    egonet.errors.EgonetError: radius: must be a positive number of pixels
"""


class EgonetError(ValueError):
    """Input egonet cannot use.

    Args:
        message: The whole sentence for the user (it names the field itself).
        field: The argument, request field or file the message is about.
        reason: The message without the field's name, for forms and JSON's
            ``fields``; defaults to what follows ``"<field>: "`` in the
            message, else the whole message.
    """

    def __init__(self, message: str, *, field: str | None = None, reason: str | None = None):
        super().__init__(message)
        self.message = message
        self.field = field
        if reason is None:
            prefix = f"{field}: "
            reason = message[len(prefix):] if field and message.startswith(prefix) else message
        self.reason = reason


class Cancelled(EgonetError):
    """Raised by a progress callback to stop long work (training, converting weights); what was saved stays."""

    def __init__(self, message: str = "cancelled"):
        super().__init__(message)
