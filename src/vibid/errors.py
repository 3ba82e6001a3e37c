"""The one exception type the command line turns into a one-line message (exit code 1)."""


class VibidError(Exception):
    """Bad input or a failed job, described in one line for the person at the stand."""
