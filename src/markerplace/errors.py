"""User-facing errors.

Anything the user can fix (bad path, bad option, bad mesh) raises :class:`UserError` with a
one-line message that says what is wrong and how to fix it. The CLI prints it on one line and
exits with code 2; it never shows a traceback for these.
"""


class UserError(Exception):
    """An error caused by input the user can fix. ``str(err)`` is a one-line message."""

    exit_code = 2

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))
