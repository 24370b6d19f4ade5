"""What every run folder records: resolved config, command, package versions, seed."""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import shlex
import sys
import tempfile
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml

PACKAGES = ("zodrive", "highway-env", "gymnasium", "stable-baselines3", "torch", "numpy")


def versions() -> dict[str, str]:
    """Installed versions of the packages that decide zodrive's numbers."""
    found = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


_COMMAND: list[str] | None = None


def set_command(argv: list[str]) -> None:
    """Remember the CLI arguments of this process (the CLI calls this once)."""
    global _COMMAND
    _COMMAND = ["zodrive", *argv]


def command_line() -> str:
    """The command as the user typed it (`zodrive ...`), or the Python command line."""
    return shlex.join(_COMMAND if _COMMAND is not None else sys.argv)


def write_atomic(path: Path, text: str) -> None:
    """Write a file so that a reader never sees it half-written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "w") as handle:
        handle.write(text)
    os.chmod(tmp, 0o644)  # mkstemp makes files private; results are meant to be shared
    os.replace(tmp, path)


def to_json(data: Any, indent: int | None = None) -> str:
    """Strict JSON: numpy values as plain numbers, NaN and infinities as null (not the
    non-standard NaN token other JSON readers reject)."""
    return json.dumps(_finite(data), indent=indent, sort_keys=False, default=_jsonable, allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return _finite(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, data: Any) -> None:
    write_atomic(path, to_json(data, indent=2) + "\n")


def _jsonable(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def write_run_info(folder: Path, config: dict[str, Any], seed: int | None) -> None:
    """Record config, command, versions and seed in `folder` (created if needed)."""
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(folder / "config.yaml", yaml.safe_dump(config, sort_keys=False))
    write_json(
        folder / "run.json",
        {"command": command_line(), "seed": seed, "versions": versions()},
    )


def sha256(path: Path) -> str:
    """The file's SHA-256 (hex): what results and trained folders are keyed on."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
