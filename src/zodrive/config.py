"""Config files: locate, load (YAML), inherit (`base:`), deep-merge and override.

highway-env's own `configure` replaces nested dicts wholesale, so zodrive merges configs
itself before handing the result over.
"""

from __future__ import annotations

import copy
import os
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml

from zodrive.errors import ZodriveError

CONFIG_ROOT_ENV = "ZODRIVE_CONFIGS"
MODELS_ENV = "ZODRIVE_MODELS"


def config_root() -> Path:
    """The shipped `configs/` folder: package data (in a checkout, `src/zodrive/configs` links
    to the repository's `configs/`); `$ZODRIVE_CONFIGS` points elsewhere. No other folder is
    ever adopted."""
    override = os.environ.get(CONFIG_ROOT_ENV)
    if override and not Path(override).is_dir():
        raise ZodriveError(f"{CONFIG_ROOT_ENV}={override} is not a folder (it replaces the shipped configs/: "
                           f"point it at a folder holding presets/, attacks/ and recipes/, or unset it)")
    return Path(override) if override else Path(str(resources.files("zodrive"))) / "configs"


def models_dir() -> Path:
    """Where shipped models live: `--models DIR` / `$ZODRIVE_MODELS`, default `./models`
    (the repository's folder when run from a checkout)."""
    return Path(os.environ.get(MODELS_ENV, "models"))


def demo_model() -> Path:
    """The model `zodrive demo` attacks: shipped inside the package, so that a wheel has it."""
    return Path(str(resources.files("zodrive"))) / "data" / "demo-model.zip"


def deep_merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Return `base` with `override` merged in; nested dicts merge, other values replace."""
    merged = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def parse_override(text: str) -> dict[str, Any]:
    """Turn `a.b.c=value` (value in YAML syntax) into `{"a": {"b": {"c": value}}}`."""
    shown = repr(text if len(text) <= 80 else text[:77] + "...")
    if "=" not in text:
        raise ZodriveError(f"invalid override {shown}: expected KEY.PATH=VALUE")
    path, _, raw = text.partition("=")
    keys = [k for k in path.strip().split(".")]
    if not all(keys):
        raise ZodriveError(f"invalid override {shown}: empty key in {path!r}")
    value = load_yaml(raw, f"the value of override {shown}") if raw.strip() else None
    nested: dict[str, Any] = {keys[-1]: value}
    for key in reversed(keys[:-1]):
        nested = {key: nested}
    return nested


def check_keys(data: Mapping[str, Any], valid: set[str], context: str, prefix: str = "") -> None:
    """Raise on a key not in `valid`, naming the closest valid one (a typo is never a no-op)."""
    import difflib

    for key in data:
        if key not in valid:
            close = difflib.get_close_matches(str(key), sorted(valid), n=1)
            names = sorted(v for v in valid if not v.startswith("_"))
            listed = ", ".join(names[:12]) + (f", ... ({len(names) - 12} more)" if len(names) > 12 else "")
            hint = f"; did you mean '{prefix}{close[0]}'?" if close else f" (valid: {listed})"
            raise ZodriveError(f"unknown key '{prefix}{key}' in {context}{hint}")


MAX_CONFIG_BYTES = 1 << 20
"""A config file larger than this (1 MiB; the shipped ones are under 3 kB) is refused unread."""
MAX_YAML_NODES = 10_000
"""The most values a YAML document may hold once its aliases are expanded. Anchors and aliases
stay allowed (they are ordinary YAML for sharing settings); a document whose aliases expand
past this ("billion laughs") or refer to themselves is refused before anything is built."""


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a mapping with one key twice (YAML says keys are
    unique; PyYAML lets the last one win)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge" or not isinstance(key_node, yaml.ScalarNode):
                continue  # `<<:` merges (explicit keys override merged ones); a non-scalar key is refused below
            key = self.construct_object(key_node)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (also on line {seen[key] + 1})", key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def _expanded_size(root: yaml.Node) -> int:
    """How many values `root` holds with its aliases expanded; raise on a cycle or past the cap."""
    sizes: dict[int, int] = {}
    open_: set[int] = set()
    aliased = False

    def size(node: yaml.Node) -> int:
        nonlocal aliased
        if id(node) in sizes:
            aliased = True
            return sizes[id(node)]
        if id(node) in open_:
            raise ValueError("an alias refers to the value that holds it (a recursive alias)")
        open_.add(id(node))
        if isinstance(node, yaml.SequenceNode):
            total = 1 + sum(size(child) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            total = 1 + sum(size(k) + size(v) for k, v in node.value)
        else:
            total = 1
        open_.discard(id(node))
        if total > MAX_YAML_NODES:
            raise ValueError(f"its aliases expand to more than {MAX_YAML_NODES:,} values (a YAML bomb?)" if aliased
                             else f"it holds more than {MAX_YAML_NODES:,} values")
        sizes[id(node)] = total
        return total

    return size(root)


def load_yaml(text: str, what: str) -> Any:
    """Parse one YAML document safely: no Python objects, unique keys, alias expansion capped
    (`MAX_YAML_NODES`), no recursive aliases. Every failure is one line naming `what`."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node)
        return loader.construct_document(node)
    except ValueError as exc:
        raise ZodriveError(f"{what} is refused: {exc}") from None
    except RecursionError:
        raise ZodriveError(f"{what} is nested too deeply") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise ZodriveError(f"{what} is not valid YAML{where}: {exc.problem or exc.context}") from None
    except yaml.YAMLError as exc:
        raise ZodriveError(f"{what} is not valid YAML: {str(exc).splitlines()[0]}") from None
    finally:
        loader.dispose()


def read_text(path: Path, what: str = "file", max_bytes: int | None = MAX_CONFIG_BYTES) -> str:
    """A UTF-8 text file's contents; a missing, oversized (`max_bytes`; None: any size) or
    undecodable file is one line naming it."""
    path = Path(path)
    try:
        if max_bytes is not None and path.stat().st_size > max_bytes:
            raise ZodriveError(f"{what} {path} is {path.stat().st_size:,} bytes (at most {max_bytes:,})")
        data = path.read_bytes()
    except FileNotFoundError:
        raise ZodriveError(f"{what} not found: {path}") from None
    except IsADirectoryError:
        raise ZodriveError(f"{what} {path} is a folder, not a file") from None
    except OSError as exc:
        raise ZodriveError(f"cannot read {what} {path}: {exc.strerror}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ZodriveError(f"{what} {path} is not UTF-8 text (byte 0x{data[exc.start]:02x} on line {line})") from None


def read_yaml(path: Path) -> dict[str, Any]:
    """Load one YAML mapping, with a one-line error for missing, malformed or hostile files."""
    data = load_yaml(read_text(path, "config file"), f"config file {path}")
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ZodriveError(f"config file {path} must hold a mapping, not {type(data).__name__}")
    return data


def resolve_path(name: str, kind: str) -> Path:
    """A config by name (`configs/<kind>/<name>.yaml`) or by path to a YAML file."""
    as_path = Path(name)
    if as_path.suffix in (".yaml", ".yml"):  # a name never means a path: `--out dqn` shadows nothing
        if not as_path.is_file():
            raise ZodriveError(f"config file not found: {name}")
        return as_path
    candidate = config_root() / kind / f"{name}.yaml"
    if not candidate.is_file():
        import difflib

        names = available(kind)
        close = difflib.get_close_matches(name, names, n=1)
        raise ZodriveError(f"unknown {kind[:-1]} {name!r}" + (f"; did you mean {close[0]!r}?" if close else "")
                           + f" (known: {', '.join(names) or 'none'})")
    return candidate


def available(kind: str) -> list[str]:
    """Names of the configs shipped in `configs/<kind>/`."""
    folder = config_root() / kind
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


def load_config(
    name: str, kind: str, overrides: list[str] | None = None, _seen: tuple[str, ...] = ()
) -> dict[str, Any]:
    """Load `name` from `configs/<kind>/`, follow its `base:` chain, apply overrides."""
    path = resolve_path(name, kind)
    if str(path) in _seen:
        raise ZodriveError(f"config {name!r} inherits from itself")
    data = read_yaml(path)
    base = data.pop("base", None)
    if base is not None:
        data = deep_merge(load_config(str(base), kind, None, _seen + (str(path),)), data)
    for text in overrides or []:
        data = deep_merge(data, parse_override(text))
    return data
