"""One exception type for every user-facing failure; the CLI prints it as one line."""


class ZodriveError(Exception):
    """A problem with the user's input or files, reported without a traceback."""
