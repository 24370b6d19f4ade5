"""What every run folder records: resolved config, command, package versions, seed; and the
readers that turn a damaged record into one line naming the file and what is wrong."""

from __future__ import annotations

import contextlib
import functools
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
from typing import Any, Iterator

import yaml

from zodrive.config import read_text
from zodrive.errors import ZodriveError

PACKAGES = ("zodrive", "highway-env", "gymnasium", "stable-baselines3", "torch", "numpy")


def versions() -> dict[str, str]:
    """Installed versions of the packages that decide zodrive's numbers, and the CPU's float32 rounding."""
    found = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    found["float32"] = float_fingerprint()
    return found


@functools.cache
def float_fingerprint() -> str:
    """12 hex digits that differ where torch's float32 kernels round differently. The same package versions
    give other last bits on another instruction set (AVX2, AVX-512: randn, tanh, matrix products), which
    a network's outputs carry and an attack amplifies. Two runs with different fingerprints may differ
    in attacked episodes and continuous returns. Two with the same one match bit for bit."""
    import torch

    with torch.no_grad():
        gen = torch.Generator().manual_seed(0)
        a = torch.randn(64, 64, generator=gen)
        values = torch.tanh(a @ a.T / 8).flatten()
    return hashlib.sha256(values.numpy().tobytes()).hexdigest()[:12]


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
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.chmod(tmp, 0o644)  # mkstemp makes files private; results are meant to be shared
        os.replace(tmp, path)
    except BaseException:  # a full disk, an interrupt: no half-written stray file is left to confuse the next run
        Path(tmp).unlink(missing_ok=True)
        raise


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


def read_json(path: Path, what: str = "run record", needs: tuple[str, ...] = ()) -> Any:
    """A JSON record zodrive wrote (`summary.json`, `eval_key.json`, `run.json`, ...). A missing,
    undecodable or cut file, or one without a key of `needs`, is one line naming it."""
    text = read_text(path, what, max_bytes=None)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ZodriveError(f"{what} {path} is damaged, not JSON ({exc}); remove it, or the folder, "
                           "and run again") from None
    if needs and not isinstance(data, dict):
        raise ZodriveError(f"{what} {path} is damaged: it holds {type(data).__name__}, not a JSON object")
    missing = [key for key in needs if key not in data]
    if missing:
        raise ZodriveError(f"{what} {path} has no {missing[0]!r} (damaged, or not a record zodrive wrote)")
    return data


def read_jsonl(path: Path, what: str = "run record", needs: tuple[str, ...] = (), cut_ok: bool = False
               ) -> list[dict[str, Any]]:
    """The rows of a JSON-lines record (`episodes.jsonl`, `steps.jsonl`), each a JSON object
    with the keys `needs`. `cut_ok`: a line that is not JSON ends the rows (a run interrupted
    mid-write; what follows is redone), otherwise it is an error. A missing file has no rows."""
    if not Path(path).exists():
        return []
    rows = []
    for number, line in enumerate(read_text(path, what, max_bytes=None).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            if cut_ok:
                break
            raise ZodriveError(f"{what} {path} is damaged: line {number} is not JSON") from None
        if not isinstance(row, dict):
            raise ZodriveError(f"{what} {path} is damaged: line {number} holds {type(row).__name__}, not a JSON object")
        missing = [key for key in needs if key not in row]
        if missing:
            raise ZodriveError(f"{what} {path} is damaged: line {number} has no {missing[0]!r}")
        rows.append(row)
    return rows


LOCK_FILE = ".lock"
"""In a run folder while a run writes into it (`run_lock`); never counted as the folder's content."""


@contextlib.contextmanager
def run_lock(folder: Path, what: str = "a run") -> Iterator[None]:
    """Hold `folder`'s lock while the block runs: a second run into the same folder (another
    process, here or on a shared POSIX file system) is refused at once, in one line, instead of
    interleaving its records with this one's. The lock dies with the process (an interrupted
    run leaves nothing to clean up); the lock file is removed when the block ends."""
    import fcntl

    path = Path(folder) / LOCK_FILE
    for _ in range(10):
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ZodriveError(f"{folder} is in use by another zodrive run (it holds {LOCK_FILE}, locked); "
                               f"wait for it to end, or choose another folder for {what}") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a lock file that the previous holder removed as we opened it
            break
        os.close(fd)
    else:
        raise ZodriveError(f"{folder}: could not take the lock {path}")
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        os.close(fd)

