"""One exception type for every user-facing failure; the CLI prints it as one line."""

CAUSE_CHARS = 240


class ZodriveError(Exception):
    """A problem with the user's input or files, reported without a traceback."""


def cause(exc: BaseException, limit: int = CAUSE_CHARS) -> str:
    """A foreign exception as one line for a ZodriveError ("TypeName: message"): torch's state-dict
    errors, for one, run to a dozen lines; the first `limit` characters say what went wrong."""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return text if len(text) <= limit else text[: limit - 1] + "…"
