"""Open DQN/DDPG zips and check that they fit a preset, with one-line errors.

By default nothing in a model file is unpickled (see `safe_load`): the acting network is
rebuilt from the zip's plain JSON and its weights. `load_model(..., trust=True)` uses SB3's
full loader, which unpickles and can run code from the file: only for models you trust
(the shipped ones are checked against the package's own copy of `models/SHA256SUMS`), and only where an SB3 object is
needed (adversarial training continues training one).
"""

from __future__ import annotations

import functools

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import DDPG, DQN, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

from zodrive.policies.safe_load import PolicyNetwork, describe, network_from, read_plain, sha256, shipped_sums
from zodrive.errors import ZodriveError, cause
from zodrive.policies.folders import model_zip

ALGOS: dict[str, type[OffPolicyAlgorithm]] = {"dqn": DQN, "ddpg": DDPG, "td3": TD3}
"""The algorithms zodrive trains, by recipe name (`algo:`); other SB3 classes load by their class name."""


def model_file(path: str | Path) -> Path:
    """`path` itself, or the model in a model folder (`model.zip`, or the one zip of an rl-zoo3
    or Hugging Face folder; several are named, never guessed between)."""
    path = Path(path)
    if path.is_dir():
        path = model_zip(path)
    if not path.is_file():
        raise ZodriveError(f"model file not found: {path}")
    return path


def inspect_model(path: Path) -> dict[str, Any]:
    """Algorithm and space shapes stored in an SB3 zip, read without unpickling anything."""
    return describe(*read_plain(path), path)


def check_fits(info: dict[str, Any], preset: dict[str, Any], path: Path) -> None:
    """Raise if the model's kind of action or its spaces do not match the preset's environment."""
    from zodrive.envs import scenario

    env = scenario(preset)
    if info.get("obs_space") in ("Dict", "Tuple"):
        raise ZodriveError(f"{path} observes a {info['obs_space']} (a goal-conditioned or multi-part observation, "
                           "as parking-v0's): zodrive attacks policies that observe one Box")
    if info["kind"] != env.kind:
        raise ZodriveError(
            f"{path} is a {info.get('sb3_class', info['algo'].upper())} policy with {info['kind']} actions; "
            f"preset {preset['name']!r} has {env.kind} actions"
        )
    if info["obs_shape"] is None:
        raise ZodriveError(f"{path} records no readable observation shape (its observation_space is damaged); "
                           "zodrive cannot tell which scenario it was trained on")
    if tuple(info["obs_shape"]) != env.obs_shape:
        raise ZodriveError(f"{path} expects observations of shape {info['obs_shape']}; preset "
                           f"{preset['name']!r} gives {env.obs_shape}{stacking_hint(info['obs_shape'], env.obs_shape)}")
    for which, declared in (("low", env.space_low), ("high", env.space_high)):
        recorded = info.get(f"obs_{which}")
        if recorded is not None and declared and (len(recorded) != len(declared) or not np.all(
                np.isclose(recorded, declared, rtol=1e-6, atol=0.0))):  # the zip writes float32 to 8 digits
            raise ZodriveError(f"{path} was trained on observations whose box {which} is {_short(recorded)}; preset "
                               f"{preset['name']!r} declares {_short(declared)}: not the scenario it was trained on "
                               "(pass the one it was, with --preset or --env-id)")
    if info["n_actions"] != env.n_actions:
        raise ZodriveError(f"{path} has {info['n_actions']} actions; preset {preset['name']!r} has {env.n_actions}")
    if env.kind == "continuous" and info.get("action_low") is not None:
        if (list(map(float, info["action_low"])) != list(env.action_low)
                or list(map(float, info["action_high"])) != list(env.action_high)):
            raise ZodriveError(f"{path} acts in [{info['action_low']}, {info['action_high']}]; preset "
                               f"{preset['name']!r} takes actions in [{list(env.action_low)}, {list(env.action_high)}]")


def stacking_hint(trained: Any, given: tuple[int, ...]) -> str:
    """When `trained` is `given` with one axis k times longer, the likely reason: stacked frames."""
    trained = tuple(trained)
    if len(trained) != len(given) or not given:
        return ""
    longer = [i for i, (a, b) in enumerate(zip(trained, given)) if a != b]
    if len(longer) != 1 or given[longer[0]] == 0 or trained[longer[0]] % given[longer[0]]:
        return ""
    k = trained[longer[0]] // given[longer[0]]
    return (f" ({k} times as long on axis {longer[0]}: trained on {k} stacked frames, as VecFrameStack makes? zodrive "
            "feeds one observation per step and does not stack frames)") if k > 1 else ""


def _short(values: Any) -> str:
    values = [float(v) for v in values]
    return str(values) if len(values) <= 6 else f"[{', '.join(map(str, values[:6]))}, ...]"


def raw_network_only(path: str | Path, what: str) -> None:
    """Refuse `what` (certify, export) on a model trained inside VecNormalize: it works on the network alone,
    which would give bounds or a file for inputs the policy never sees."""
    from zodrive.policies.folders import trained_with

    norm = trained_with(model_file(path)).normalization
    if norm is not None:
        raise ZodriveError(f"{what} works on the network alone, and {path} was trained on observations normalized "
                           f"by {norm}: its result would not be this policy's")


def load_network(path: str | Path, preset: dict[str, Any] | None = None) -> PolicyNetwork:
    """The acting network of a model file, rebuilt safely; with `preset`, checked to fit it.

    Loaded once per process and file version (path, size, modification time): validating a
    command and running its episodes share one load."""
    file = model_file(path)
    stat = file.stat()
    info, network = _load_network(str(file.resolve()), stat.st_size, stat.st_mtime_ns)
    if preset is not None:
        check_fits(info, preset, file)
    return network


@functools.lru_cache(maxsize=8)
def _load_network(file: str, size: int, mtime_ns: int) -> tuple[dict[str, Any], PolicyNetwork]:
    data, weights = read_plain(Path(file))  # the zip is read once
    return describe(data, weights, Path(file)), network_from(data, weights, Path(file))


TRUSTED_SUMS = Path(__file__).resolve().parents[1] / "data" / "SHA256SUMS"
"""The shipped models' SHA-256, inside the installed package: the only list zodrive trusts to
unpickle a model without --trust-model. A `SHA256SUMS` in a working directory or a `--models`
folder is someone's claim, not the package's, and trusts nothing."""


def is_shipped(file: Path) -> bool:
    """True if `file`'s content is one of the shipped models (by the package's own SHA-256 list)."""
    return sha256(file) in set(shipped_sums(TRUSTED_SUMS.parent).values())


def require_trust(path: str | Path, trust: bool) -> None:
    """Refuse to unpickle `path` unless the user trusts it or it is a shipped model (checked first by
    the commands that must unpickle, before anything else is read or said)."""
    file = model_file(path)
    if not (trust or is_shipped(file)):
        raise ZodriveError(f"loading {file} with stable-baselines3 would unpickle it, which can run code from "
                           "the file; pass --trust-model if you trust where it came from")


def load_model(path: str | Path, preset: dict[str, Any] | None = None, *, trust: bool = False,
               cls: type[BaseAlgorithm] | None = None) -> BaseAlgorithm:
    """Load a DQN/DDPG zip as an SB3 object (unpickles: needs `trust` unless it is a shipped model);
    `cls` loads it as a subclass of its algorithm (e.g. `SADQN` to continue with a regularizer)."""
    file = model_file(path)
    info = inspect_model(file)
    if preset is not None:
        check_fits(info, preset, file)
    require_trust(file, trust)
    try:
        with warnings.catch_warnings():  # SB3 warns that saved n-step settings are not re-applied
            warnings.filterwarnings("ignore", message=".*n_steps.*ignored.*")
            algo = ALGOS.get(info["algo"]) or sb3_class(info["sb3_class"])
            if cls is not None and not issubclass(cls, algo):
                raise ZodriveError(f"{file} is a {info['algo'].upper()} model; {cls.__name__} cannot continue it")
            return (cls or algo).load(file, device="cpu")
    except ZodriveError:
        raise
    except ModuleNotFoundError as exc:  # a network class of the user's own, e.g. a feature extractor
        raise ZodriveError(f"{file} could not be loaded: it names code from module {exc.name!r}, which is not "
                           "importable here (put its folder on PYTHONPATH)") from exc
    except Exception as exc:
        raise ZodriveError(f"{file} could not be loaded ({cause(exc)})") from exc


def sb3_class(name: str) -> type[BaseAlgorithm]:
    """An SB3 or sb3-contrib algorithm class by name (QRDQN and TQC need sb3-contrib)."""
    import stable_baselines3

    if hasattr(stable_baselines3, name):
        return getattr(stable_baselines3, name)
    try:
        import sb3_contrib
    except ImportError:
        raise ZodriveError(f"loading a {name} with stable-baselines3 needs sb3-contrib: "
                           "pip install sb3-contrib") from None
    return getattr(sb3_contrib, name)


def model_algo(path: str | Path) -> str:
    """The model's family (dqn, qrdqn, ddpg, sac, ppo), read from its weights."""
    return inspect_model(model_file(path))["algo"]


def model_kind(path: str | Path) -> str:
    """`discrete` or `continuous`: the model's action space, read from its plain data."""
    return inspect_model(model_file(path))["kind"]
