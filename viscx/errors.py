"""The one exception type for problems with the user's input.

A :class:`ViscxError` carries a one-line message meant for a person; the CLI prints
it as ``viscx: error: <message>`` and exits with status 2. Anything else that
escapes is a bug in viscx.
"""


class ViscxError(Exception):
    """Bad input: a file that is missing, unreadable, of the wrong kind, or a
    scene or option that cannot be used. The message is one line."""

    exit_code = 2
