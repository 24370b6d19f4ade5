"""Where an evaluation's records live: its folder while it runs, or a pack once it is finished.

An evaluation folder (`evaluate`'s `out`) holds `eval_key.json`, `episodes.jsonl` and `summary.json` (and
`steps.jsonl`, which git ignores). It is the live form: it resumes, and a run writes nothing else. A folder of
finished evaluation folders P (a grid's `cells/`, a study's folder of runs) packs into one file beside it,
`P.jsonl.gz` (`zodrive pack`): gzip-compressed JSON lines, one per evaluation, sorted by name,

    {"cell": NAME, "eval_key": {...}, "summary": {...}, "episodes": [{...}, ...]}

(a file the folder did not hold is left out of its line). `P/NAME` stays the evaluation's address in either
form: every reader here reads the folder where it exists and otherwise line NAME of P's pack, so a command, a
card or a test names a cell the same way whichever form it is in (`read`, `names`), and a grid resumes over
packed cells (`experiments.cells.run_cells`: the same key and episodes run nothing).

Packing keeps every byte: each packed folder's files are what `to_json` writes of its line (checked before the
folder is removed; a folder in another layout is left as it is), and `unpack` gives them back. steps.jsonl is
not kept: it is git-ignored, and a finished summary holds what it gave. Only finished evaluations are packed
(a summary over every episode recorded), so a packed cell is resumed only to add episodes, as a committed
folder without its steps is. A bench grid's `table.json` (a row's, its `clean/`'s, a brake's: one row per cell,
its grid entry and its summary's figures) goes too once every cell is packed: `zodrive pack` removes it where the
rows its cells give are the file's to the bit, and its readers then make it from them
(`zodrive.bench.bench.pack_table`, `read_table`); a grid that is not finished keeps its file.

A study's printed outputs (`P/NAME.txt`: what a command printed, often beside the evaluation `P/NAME` it
ran) fold the same way into one text file beside their folder, `P.txt` (`zodrive pack --logs`): each log under
a header line, as `tail -n +1 *.txt` run in P prints them, so the file reads as the logs did,

    ==> NAME.txt <==
    ...what NAME.txt held...

and `unpack_logs` gives every file back, byte for byte (a log that would not come back so is left as it is)."""

from __future__ import annotations

import contextlib
import fnmatch
import gzip
import json
import os
import re
import shutil
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from zodrive.errors import ZodriveError
from zodrive.runinfo import LOCK_FILE, read_json, read_jsonl, run_lock, to_json, write_atomic, write_json

PACKED = ".jsonl.gz"
KEY, EPISODES, SUMMARY, STEPS = "eval_key.json", "episodes.jsonl", "summary.json", "steps.jsonl"
PARTS = {KEY: "eval_key", SUMMARY: "summary", EPISODES: "episodes"}
"""An evaluation folder's files a pack keeps, and their fields in its line."""
RUN_FILES = (KEY, EPISODES, STEPS, SUMMARY)
"""What an evaluation writes into its folder (`evaluate.RUN_FILES`)."""
LOGS = ".txt"
"""The suffix of a folder's printed outputs folded into one file beside it (`logs_path`)."""
MAX_PACK_BYTES = 1 << 30
"""A pack's most bytes once decompressed (the largest committed one holds a few MB): a larger one is refused."""


@dataclass(frozen=True)
class Evaluation:
    """One evaluation's records, read from its folder or from its line in a pack."""

    folder: Path
    """Its address, `P/NAME`, in either form."""
    key: dict[str, Any] | None
    summary: dict[str, Any] | None
    episodes: list[dict[str, Any]]
    packed: bool


def pack_path(parent: Path) -> Path:
    """The pack of the evaluation folders in `parent`: `parent.jsonl.gz`, beside it."""
    parent = Path(parent)
    return parent.with_name(parent.name + PACKED)


def is_live(folder: Path) -> bool:
    """Whether `folder` is an evaluation folder on disk (the live form, read before any pack): a folder that holds
    an evaluation's key, summary or episodes. A folder left with only its git-ignored steps.jsonl (a checkout that
    moved to the packed cell) is not one: the pack is read."""
    folder = Path(folder)
    return folder.is_dir() and any((folder / name).is_file() for name in PARTS)


def is_evaluation(folder: Path) -> bool:
    """Whether `folder` is a live evaluation folder that `pack` would pack (an evaluation's files, nothing else)."""
    return _kind(Path(folder)) == "evaluation"


def exists(folder: Path) -> bool:
    """Whether an evaluation is at `folder`, in either form."""
    folder = Path(folder)
    return is_live(folder) or folder.name in _lines(pack_path(folder.parent))


def read(folder: Path) -> Evaluation:
    """The evaluation at `folder`: its folder where it exists, else its line in its parent's pack. A damaged
    record is one line naming it; an address with neither form says so."""
    folder = Path(folder)
    if is_live(folder):
        key = read_json(folder / KEY, "evaluation key", needs=("model",)) if (folder / KEY).is_file() else None
        summary = read_json(folder / SUMMARY, "summary", needs=("episodes",)) if (folder / SUMMARY).is_file() else None
        return Evaluation(folder, key, summary, read_jsonl(folder / EPISODES, "run record", needs=("episode",)), False)
    pack = pack_path(folder.parent)
    line = _lines(pack).get(folder.name)
    if line is None:
        raise ZodriveError(f"{folder} holds no evaluation: no such folder, and no cell {folder.name!r} in "
                           f"{pack if pack.is_file() else 'a pack ' + str(pack)}")
    record = _parse(line, pack, folder.name)
    return Evaluation(folder, record.get("eval_key"), record.get("summary"), record.get("episodes", []), True)


def summary(folder: Path, needs: tuple[str, ...] = ()) -> dict[str, Any]:
    """The summary of the evaluation at `folder`, with the keys `needs` (one line naming it otherwise)."""
    folder = Path(folder)
    if is_live(folder) and (folder / SUMMARY).is_file():
        return read_json(folder / SUMMARY, "summary", needs=needs)  # the file alone, as its readers read it
    found = read(folder).summary
    if found is None:
        raise ZodriveError(f"{folder} holds no summary: the evaluation is not finished; run it again to resume it")
    missing = [k for k in needs if k not in found]
    if missing:
        raise ZodriveError(f"summary of {folder} has no {missing[0]!r} (damaged, or not a record zodrive wrote)")
    return found


def episodes(folder: Path, needs: tuple[str, ...] = (), missing_ok: bool = False) -> list[dict[str, Any]]:
    """The episode records of the evaluation at `folder` (as `episodes.jsonl` holds them), each with `needs`;
    `missing_ok`: none where there is no evaluation at `folder` (as `read_jsonl` reads a missing file)."""
    if missing_ok and not exists(folder):
        return []
    if is_live(folder):  # the file alone, as its readers read it (a missing file has no rows)
        return read_jsonl(Path(folder) / EPISODES, "run record", needs=needs)
    rows = read(folder).episodes
    for number, row in enumerate(rows, start=1):
        missing = [k for k in needs if k not in row]
        if missing:
            raise ZodriveError(f"episode records of {folder} are damaged: record {number} has no {missing[0]!r}")
    return rows


def names(parent: Path, pattern: str = "*") -> list[Path]:
    """The evaluations in `parent` whose names match `pattern` (a glob), in either form, sorted by name."""
    parent = Path(parent)
    live = {p.name for p in parent.glob(pattern) if is_live(p)} if parent.is_dir() else set()
    packed = {name for name in _lines(pack_path(parent)) if fnmatch.fnmatchcase(name, pattern)}
    return [parent / name for name in sorted(live | packed)]


def walk(root: Path) -> Iterator[Path]:
    """Every evaluation under `root` (a folder of folders), in either form: each live evaluation folder and
    each line of each pack."""
    root = Path(root)
    for path in sorted(root.rglob("*")):
        if path.is_dir() and _kind(path) == "evaluation":
            yield path
        elif path.is_file() and path.name.endswith(PACKED):
            parent = path.with_name(path.name[: -len(PACKED)])
            yield from (parent / name for name in _lines(path) if not is_live(parent / name))


def copy_for_resume(source: Path, target: Path) -> None:
    """Start the evaluation folder `target` from the evaluation at `source` (either form): every file but the
    summary, which the run makes again from the episodes. A live source's files are copied as they are."""
    source, target = Path(source), Path(target)
    target.mkdir(parents=True)
    if is_live(source):
        for name in RUN_FILES:
            if name != SUMMARY and (source / name).is_file():
                shutil.copyfile(source / name, target / name)
        return
    found = read(source)
    _write_files(target, {"eval_key": found.key, "episodes": found.episodes})


def unpack(folder: Path) -> None:
    """Give the packed evaluation at `folder` back its folder (the files it was packed from, byte for byte)
    and take its line out of the pack (a pack left empty is removed). A live folder is left as it is."""
    folder = Path(folder)
    if is_live(folder):
        return
    pack = pack_path(folder.parent)
    lines = dict(_lines(pack))
    if folder.name not in lines:
        raise ZodriveError(f"{folder} holds no evaluation: no such folder, and no cell {folder.name!r} in {pack}")
    _write_files(folder, _parse(lines.pop(folder.name), pack, folder.name))
    _write_pack(pack, lines)


def remove(folder: Path) -> None:
    """Remove the evaluation at `folder`, in whichever form it is (git's history keeps what was committed)."""
    folder = Path(folder)
    if is_live(folder):
        shutil.rmtree(folder)
        return
    pack = pack_path(folder.parent)
    lines = dict(_lines(pack))
    if lines.pop(folder.name, None) is not None:
        _write_pack(pack, lines)
        if folder.is_dir():  # its git-ignored steps.jsonl, left beside the pack
            shutil.rmtree(folder)


@dataclass
class Packed:
    """What `pack` did in one folder of evaluation folders."""

    pack: Path
    packed: list[str]
    left: dict[str, str]
    """Evaluation folders left as they are, and why."""


def pack(parent: Path) -> Packed:
    """Pack the finished evaluation folders in `parent` into `pack_path(parent)` (added to the lines it holds;
    a folder replaces a line of its name), and remove them once the pack reads back as their files, byte for
    byte. Each folder is locked while it is read and removed, so a run writing into it is not cut. Left as
    they are, and said: a folder with files an evaluation does not write, an unfinished one, one whose files
    are not in zodrive's own layout (`to_json`), one in use."""
    parent = Path(parent)
    target = pack_path(parent)
    lines = dict(_lines(target))
    left: dict[str, str] = {}
    taken: list[Path] = []
    with contextlib.ExitStack() as stack:
        for folder in sorted(p for p in parent.iterdir() if _kind(p) == "evaluation"):
            try:
                stack.enter_context(run_lock(folder, "packing"))
            except ZodriveError:
                left[folder.name] = "in use by a run"
                continue
            record, why = _record(folder)
            if record is None:
                left[folder.name] = why
                continue
            lines[folder.name] = to_json(record)
            taken.append(folder)
        for folder in sorted(p for p in parent.iterdir() if p.is_dir() and _kind(p) == "other" and p.name not in left):
            left[folder.name] = _other_files(folder)
        if taken:
            _write_pack(target, lines)
            _lines.cache_clear()
            for folder in taken:  # the pack reads back as the folder's files before the folder goes
                if _files_of(_parse(_lines(target)[folder.name], target, folder.name)) != _kept_bytes(folder):
                    raise ZodriveError(f"{target}: cell {folder.name} does not read back as {folder}'s files; "
                                       "the folder is kept")
            for folder in taken:
                for name in RUN_FILES:
                    (folder / name).unlink(missing_ok=True)
    for folder in taken:  # the lock file went with the lock
        with contextlib.suppress(OSError):
            folder.rmdir()
    if taken and not any(parent.iterdir()):  # a grid's cells/ goes with its last folder
        parent.rmdir()
    return Packed(target, [f.name for f in taken], left)


def unpack_all(parent: Path) -> list[str]:
    """Unpack every line of `parent`'s pack into its folder (a live folder of the same name is kept, and its
    line dropped); the pack is removed. Returns the names given back."""
    parent = Path(parent)
    pack = pack_path(parent)
    given = []
    for name, line in sorted(_lines(pack).items()):
        if not is_live(parent / name):
            _write_files(parent / name, _parse(line, pack, name))
            given.append(name)
    if pack.is_file():
        pack.unlink()
    _lines.cache_clear()
    return given


def pack_tree(root: Path) -> list[Packed]:
    """`pack` every folder of evaluation folders under `root` (`root` itself included)."""
    root = Path(root)
    if not root.is_dir():
        raise ZodriveError(f"{root}: not a folder")
    parents = sorted({p.parent for p in root.rglob("*") if p.is_dir() and _kind(p) == "evaluation"}
                     | ({root} if any(_kind(p) == "evaluation" for p in root.iterdir()) else set()))
    return [pack(parent) for parent in parents]


def unpack_tree(root: Path) -> dict[Path, list[str]]:
    """`unpack_all` every pack under `root`, and `root`'s own (`root.jsonl.gz`, beside it)."""
    root = Path(root)
    packs = sorted({*root.rglob("*" + PACKED), *([pack_path(root)] if pack_path(root).is_file() else [])})
    return {p: unpack_all(p.with_name(p.name[: -len(PACKED)])) for p in packs}


# ---------------------------------------------------------------- printed outputs


_LOG_HEADER = re.compile(r"^==> (.*) <==$", re.MULTILINE)


def logs_path(parent: Path) -> Path:
    """The file that holds the printed outputs of `parent` (its `*.txt`): `parent.txt`, beside it."""
    parent = Path(parent)
    return parent.with_name(parent.name + LOGS)


def read_logs(path: Path) -> dict[str, str]:
    """Name -> text of each log folded into `path` (`pack_logs`), in its order; anything else is one line."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as err:
        raise ZodriveError(f"{path}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise ZodriveError(f"folded logs {path} are damaged (not UTF-8 text)") from None
    parts = _LOG_HEADER.split(text)  # ["", name, "\n" + text (+ "\n" between two logs), name, ...]
    if parts[0] or len(parts) < 3:
        raise ZodriveError(f"{path} holds no folded logs: it does not start with a '==> NAME.txt <==' line")
    logs: dict[str, str] = {}
    for i, (name, body) in enumerate(zip(parts[1::2], parts[2::2])):
        last = i == len(parts) // 2 - 1
        log = body[1:] if last else body[1:-1]
        if not _log_name(name) or name in logs or not body.startswith("\n") or not log.endswith("\n") or (
                not last and not body.endswith("\n\n")):
            raise ZodriveError(f"folded logs {path} are damaged at the log {name!r}")
        logs[name] = log
    return logs


def logs_text(logs: dict[str, str]) -> str:
    """The folded file of `logs` (name -> text, each ending in a newline), sorted by name: what
    `tail -n +1 *.txt` prints in their folder."""
    return "\n".join(f"==> {name} <==\n{logs[name]}" for name in sorted(logs))


def pack_logs(parent: Path, patterns: tuple[str, ...] = ("*" + LOGS,)) -> Packed:
    """Fold the printed outputs in `parent` (its `*.txt` files; those whose names match one of `patterns`, globs)
    into `logs_path(parent)` (added to the logs it holds; a file replaces a log of its name), and remove them once
    the folded file reads back as their bytes. `parent` goes with its last file. Left as they are, and said: a
    file that is not UTF-8 text, that does not end in a newline, or that holds a line like a header (unpacking
    would not give it back)."""
    parent = Path(parent)
    target = logs_path(parent)
    if not parent.is_dir():
        raise ZodriveError(f"{parent}: not a folder")
    logs = read_logs(target) if target.is_file() else {}
    left: dict[str, str] = {}
    taken: list[Path] = []
    for path in sorted(parent.glob("*" + LOGS)):
        if not path.is_file() or path.is_symlink() or not _log_name(path.name) or not any(
                fnmatch.fnmatchcase(path.name, pattern) for pattern in patterns):
            continue
        try:
            text = path.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            left[path.name] = "not UTF-8 text"
            continue
        if not text.endswith("\n"):
            left[path.name] = "does not end in a newline (unpacking would not give it back)"
        elif _LOG_HEADER.search(text):
            left[path.name] = "holds a line like a header of folded logs (==> NAME <==)"
        else:
            logs[path.name] = text
            taken.append(path)
    if taken:
        _write_bytes(target, logs_text(logs).encode("utf-8"))
        back = read_logs(target)
        for path in taken:  # the folded file reads back as each file before the file goes
            if back.get(path.name, "").encode("utf-8") != path.read_bytes():
                raise ZodriveError(f"{target}: the log {path.name} does not read back as {path}; the file is kept")
        for path in taken:
            path.unlink()
        if not any(parent.iterdir()):
            parent.rmdir()
    return Packed(target, [p.name for p in taken], left)


def unpack_logs(parent: Path) -> list[str]:
    """Give every log folded into `logs_path(parent)` its file in `parent` back, byte for byte (a file of the
    same name is kept, and the folded log dropped); the folded file is removed. Returns the names given back."""
    parent = Path(parent)
    target = logs_path(parent)
    logs = read_logs(target)
    parent.mkdir(parents=True, exist_ok=True)
    given = []
    for name, text in sorted(logs.items()):
        if not (parent / name).exists():
            _write_bytes(parent / name, text.encode("utf-8"))
            given.append(name)
    target.unlink()
    return given


def _log_name(name: str) -> bool:
    """A name a folded log may have: a file's, ending in .txt, with no folder in it."""
    return name.endswith(LOGS) and len(name) > len(LOGS) and "/" not in name and "\\" not in name and \
        name not in (".", "..") and not name.startswith(".")


# ---------------------------------------------------------------- the pack file


def _kind(path: Path) -> str:
    """'evaluation': a folder that holds an evaluation's files and nothing else (its lock aside); 'other': a
    folder that holds them and more; '' otherwise."""
    if not path.is_dir():
        return ""
    entries = list(path.iterdir())
    if not any(e.name in PARTS for e in entries):
        return ""
    return "evaluation" if all(e.name in RUN_FILES or e.name == LOCK_FILE for e in entries) else "other"


def _other_files(folder: Path) -> str:
    others = sorted(e.name for e in folder.iterdir() if e.name not in RUN_FILES and e.name != LOCK_FILE)
    return f"holds {', '.join(others[:3])}{' and more' if len(others) > 3 else ''}, which a pack does not keep"


def _record(folder: Path) -> tuple[dict[str, Any] | None, str]:
    """The pack line of a finished evaluation folder, or None and why it is left as it is."""
    kept = _kept_bytes(folder)
    try:
        record = {"cell": folder.name, **{PARTS[name]: _decode(name, text) for name, text in kept.items()}}
    except (ValueError, UnicodeDecodeError):
        return None, "a file is not JSON"
    summary, rows = record.get("summary"), record.get("episodes", [])
    if not isinstance(summary, dict) or not isinstance(summary.get("episodes"), int):
        return None, "unfinished: no summary"
    if any(not isinstance(r, dict) for r in rows):
        return None, "an episode record is not a JSON object"
    if EPISODES in kept and sorted(r.get("episode") for r in rows) != list(range(summary["episodes"])):
        return None, f"unfinished: {len(rows)} episode records for a summary of {summary['episodes']}"
    if _files_of(record) != kept:
        return None, "its files are not in zodrive's own JSON layout (unpacking would not give them back)"
    return record, ""


def _decode(name: str, data: bytes) -> Any:
    text = data.decode("utf-8")
    if name == EPISODES:
        return [json.loads(line) for line in text.splitlines()]
    return json.loads(text)


def _kept_bytes(folder: Path) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in PARTS if (folder / name).is_file()}


def _files_of(record: dict[str, Any]) -> dict[str, bytes]:
    """The files a pack line stands for, as zodrive writes them (`write_json`, one `to_json` line per episode)."""
    files = {}
    for name, part in PARTS.items():
        if part in record:
            value = record[part]
            text = "".join(to_json(r) + "\n" for r in value) if name == EPISODES else to_json(value, indent=2) + "\n"
            files[name] = text.encode("utf-8")
    return files


def _write_files(folder: Path, record: dict[str, Any]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, part in PARTS.items():
        if record.get(part) is None:
            continue
        if name == EPISODES:
            write_atomic(folder / name, "".join(to_json(r) + "\n" for r in record[part]))
        else:
            write_json(folder / name, record[part])
    _lines.cache_clear()


def _write_pack(path: Path, lines: dict[str, str]) -> None:
    """Write a pack of `lines` (name -> JSON line) atomically, sorted by name; none: remove it. The same lines
    give the same bytes (no time stamp in the gzip header)."""
    _lines.cache_clear()
    if not lines:
        path.unlink(missing_ok=True)
        return
    _write_bytes(path, gzip.compress("".join(lines[name] + "\n" for name in sorted(lines)).encode("utf-8"),
                                     compresslevel=9, mtime=0))
    _lines.cache_clear()


def _write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` atomically (a reader never sees half a file), readable by all, as results are."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _parse(line: str, pack: Path, name: str) -> dict[str, Any]:
    try:
        record = json.loads(line)
    except json.JSONDecodeError:
        raise ZodriveError(f"evaluation pack {pack} is damaged: cell {name!r} is not JSON") from None
    if not isinstance(record.get("episodes", []), list) or not all(
            isinstance(record.get(part), (dict, type(None))) for part in ("eval_key", "summary")):
        raise ZodriveError(f"evaluation pack {pack} is damaged: cell {name!r} is not a packed evaluation")
    return record


class _Cache:
    """The lines of the packs read lately, by path, as long as the file is unchanged (its size and time)."""

    def __init__(self, size: int = 16) -> None:
        self.size = size
        self.entries: dict[Path, tuple[tuple[int, int], dict[str, str]]] = {}

    def __call__(self, path: Path) -> dict[str, str]:
        try:
            stat = path.stat()
        except OSError:
            return {}
        stamp = (stat.st_mtime_ns, stat.st_size)
        hit = self.entries.get(path)
        if hit is not None and hit[0] == stamp:
            return hit[1]
        lines = _read_pack(path)
        self.entries[path] = (stamp, lines)
        while len(self.entries) > self.size:
            del self.entries[next(iter(self.entries))]
        return lines

    def cache_clear(self) -> None:
        self.entries.clear()


def _read_pack(path: Path) -> dict[str, str]:
    """Name -> JSON line of a pack; anything else (not gzip, too large, a line without a name) is one line."""
    try:
        with path.open("rb") as handle:
            inflate = zlib.decompressobj(wbits=31)  # gzip
            data = inflate.decompress(handle.read(), MAX_PACK_BYTES + 1)
    except zlib.error:
        raise ZodriveError(f"evaluation pack {path} is damaged (not gzip)") from None
    if len(data) > MAX_PACK_BYTES or inflate.unconsumed_tail:
        raise ZodriveError(f"evaluation pack {path} holds more than {MAX_PACK_BYTES >> 20} MiB: not a pack zodrive "
                           "wrote")
    lines: dict[str, str] = {}
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ZodriveError(f"evaluation pack {path} is damaged (not UTF-8 text)") from None
    for number, line in enumerate(text.splitlines(), start=1):
        try:
            name = json.loads(line).get("cell")
        except (json.JSONDecodeError, AttributeError):
            name = None
        if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
            raise ZodriveError(f"evaluation pack {path} is damaged: line {number} is not a packed evaluation")
        lines[name] = line
    return lines


_lines = _Cache()
