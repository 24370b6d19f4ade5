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
    if "=" not in text:
        raise ZodriveError(f"invalid override {text!r}: expected KEY.PATH=VALUE")
    path, _, raw = text.partition("=")
    keys = [k for k in path.strip().split(".")]
    if not all(keys):
        raise ZodriveError(f"invalid override {text!r}: empty key in {path!r}")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError as exc:
        raise ZodriveError(f"invalid override {text!r}: value is not valid YAML") from exc
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


def read_yaml(path: Path) -> dict[str, Any]:
    """Load one YAML mapping, with a one-line error for missing or malformed files."""
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError as exc:
        raise ZodriveError(f"config file not found: {path}") from exc
    except yaml.YAMLError as exc:
        raise ZodriveError(f"config file {path} is not valid YAML") from exc
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
        known = ", ".join(available(kind)) or "none"
        raise ZodriveError(f"unknown {kind[:-1]} {name!r} (known: {known})")
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
