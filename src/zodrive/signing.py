"""This machine's signature on the files zodrive writes and later unpickles (training
checkpoints and replay buffers): a run folder from someone else carries no valid signature, so
resuming it runs no code unless the user says --trust-model."""

from __future__ import annotations

import os
from pathlib import Path

from zodrive.runinfo import sha256


def machine_key() -> bytes:
    """This machine's zodrive key (made once, readable by its owner only): what `signature` signs with."""
    import secrets

    folder = Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state") / "zodrive"
    path = folder / "key"
    if not path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as handle:
            handle.write(secrets.token_bytes(32))
    return path.read_bytes()


def signature(path: Path) -> str:
    """The file's HMAC-SHA256 under this machine's key: proof that zodrive here wrote it."""
    import hmac

    return hmac.new(machine_key(), sha256(path).encode(), "sha256").hexdigest()
