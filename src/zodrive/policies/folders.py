"""What a model's folder says about how it was trained: plain SB3 (`model.zip`), rl-zoo3
(`<env id>.zip`, `<env id>/args.yml`, `config.yml`, `env_kwargs.yml`, `vecnormalize.pkl`) and
Hugging Face model repos (`<algo>-<env id>.zip`, `args.yml`, `env_kwargs.yml`, `vec_normalize.pkl`).

Read as data only: rl-zoo3 writes its YAML with `!!python/object/apply:collections.OrderedDict`,
which this reader takes as a list of pairs; every other Python tag is refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from zodrive.errors import ZodriveError
from zodrive.policies.normalize import find_normalization

ZOO_FILES = ("args.yml", "env_kwargs.yml", "config.yml")


class _ZooLoader(yaml.SafeLoader):
    """YAML as rl-zoo3 writes it: ordered mappings as lists of pairs, nothing else from Python."""


def _ordered(loader: yaml.SafeLoader, node: yaml.Node) -> dict[str, Any]:
    pairs = loader.construct_sequence(node, deep=True)
    items = pairs[0] if len(pairs) == 1 and isinstance(pairs[0], list) else pairs
    try:
        return {str(k): v for k, v in items}
    except (TypeError, ValueError):
        raise yaml.constructor.ConstructorError(None, None, "an OrderedDict that is not a list of pairs",
                                                node.start_mark) from None


_ZooLoader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered)


def read_zoo_yaml(path: Path) -> Any:
    """One of rl-zoo3's YAML files, as data; a one-line error naming the file otherwise."""
    try:
        return yaml.load(path.read_text(encoding="utf-8"), Loader=_ZooLoader)  # noqa: S506 - a safe loader
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ZodriveError(f"{path} is not YAML zodrive reads as data: {str(exc).splitlines()[0]}") from None


def model_zip(folder: Path) -> Path:
    """The model file in `folder`: `model.zip`, or the one zip there (rl-zoo3's `<env id>.zip`,
    Hugging Face's `<algo>-<env id>.zip`); several zips are named, never guessed between."""
    if (folder / "model.zip").is_file():
        return folder / "model.zip"
    zips = sorted(p for p in folder.glob("*.zip") if p.is_file())
    if len(zips) == 1:
        return zips[0]
    if not zips:
        raise ZodriveError(f"model file not found: {folder} holds no .zip")
    raise ZodriveError(f"{folder} holds {len(zips)} models ({', '.join(p.name for p in zips)}): "
                       "name the one you mean")


@dataclass(frozen=True)
class TrainedWith:
    """Where a model says it was trained, and by which files."""

    env_id: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    preset: str | None = None          # a zodrive run folder's preset, by name (its config.yaml)
    normalization: Path | None = None
    said_by: tuple[str, ...] = ()


def trained_with(model: Path) -> TrainedWith:
    """What the files beside the model file `model` say: the env id (rl-zoo3 / Hugging Face
    `args.yml`, or the zip's name `<algo>-<env id>.zip` when that is a registered environment),
    `env_kwargs` and the VecNormalize statistics."""
    folder = model.parent
    said: list[str] = []
    env_id, env_kwargs, preset = None, {}, _zodrive_preset(folder)
    if preset is not None:
        said.append(str(folder / "config.yaml"))
    for base in (folder / model.stem, folder):  # rl-zoo3 keeps its files in `<env id>/` beside `<env id>.zip`
        args_file, kwargs_file = base / "args.yml", base / "env_kwargs.yml"
        if args_file.is_file() and env_id is None:
            args = read_zoo_yaml(args_file)
            if isinstance(args, dict) and isinstance(args.get("env"), str):
                env_id = args["env"]
                said.append(str(args_file))
                # rl-zoo3's training records --env-kwargs here; env_kwargs.yml appears only when a model is pushed
                from_args = _kwargs(args.get("env_kwargs"), args_file, "its env_kwargs")
                if from_args:
                    env_kwargs = from_args
        if kwargs_file.is_file():
            kwargs = _kwargs(read_zoo_yaml(kwargs_file), kwargs_file, "it")
            if kwargs and env_kwargs and kwargs != env_kwargs:
                raise ZodriveError(f"{kwargs_file} and the args.yml beside it give different env_kwargs: "
                                   "zodrive cannot tell which the model was trained with")
            if kwargs and not env_kwargs:
                env_kwargs = kwargs
                said.append(str(kwargs_file))
    if env_id is None and preset is None:
        env_id = _script_env_id(folder / "train.json")
        if env_id is not None:
            said.append(str(folder / "train.json"))
    if env_id is None and preset is None:
        env_id = _env_id_from_name(model.stem)
        if env_id is not None:
            said.append(str(model))
    norm = find_normalization(model)
    return TrainedWith(env_id=env_id, env_kwargs=env_kwargs, preset=preset, normalization=norm, said_by=tuple(said))


def _kwargs(value: Any, path: Path, what: str) -> dict[str, Any]:
    """rl-zoo3's env_kwargs as a mapping (none: empty); anything else is refused, naming the file."""
    if value in (None, {}):
        return {}
    if not isinstance(value, dict) or not isinstance(value.get("config", {}), dict):
        raise ZodriveError(f"{path}: {what} is not a mapping of keyword arguments (with `config` a mapping)")
    return value


def trained_in_memory(model: Any) -> TrainedWith | None:
    """What an SB3 model in memory says of where it was trained: the id of the environment it still
    holds, and the settings that environment has changed from its id's defaults (highway-env's
    `config`). None when it holds none (loaded without `env=`) or holds several different ones."""
    env = model.get_env()
    if env is None:
        return None
    try:
        specs, configs = env.get_attr("spec"), env.get_attr("config")
    except AttributeError:  # not a highway-env scenario: its id only
        specs, configs = env.get_attr("spec"), None
    ids = {getattr(spec, "id", None) for spec in specs}
    if len(ids) != 1 or None in ids:
        return None
    env_id = ids.pop()
    assert env_id is not None  # refused above
    said = ("the environment the model holds in memory",)
    if configs is None:
        return TrainedWith(env_id=env_id, env_kwargs=dict(specs[0].kwargs or {}), said_by=said)
    from zodrive.envs.presets import changed_settings

    changed = changed_settings(env_id, configs[0])
    return TrainedWith(env_id=env_id, env_kwargs={"config": changed} if changed else {}, said_by=said)


def _zodrive_preset(folder: Path) -> str | None:
    """The preset a zodrive run folder was trained on (`config.yaml`: `preset: {name: ...}`)."""
    path = folder / "config.yaml"
    if not path.is_file():
        return None
    data = read_zoo_yaml(path)
    preset = data.get("preset") if isinstance(data, dict) else None
    name = preset.get("name") if isinstance(preset, dict) else None
    return name if isinstance(name, str) and name else None


def _script_env_id(path: Path) -> str | None:
    """The env id a training script recorded (`train.json`: `env_id`, as the zoo's and the examples' do)."""
    if not path.is_file():
        return None
    import json

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    env_id = data.get("env_id") if isinstance(data, dict) else None
    return env_id if isinstance(env_id, str) else None


def _env_id_from_name(stem: str) -> str | None:
    import gymnasium as gym

    import highway_env  # noqa: F401  (registers highway-env's ids)

    for candidate in (stem, re.sub(r"^[a-z0-9]+-", "", stem)):  # `<env id>` (rl-zoo3) or `<algo>-<env id>` (HF)
        if re.fullmatch(r"[\w/-]+-v\d+", candidate) and candidate in gym.registry:
            return candidate
    return None
