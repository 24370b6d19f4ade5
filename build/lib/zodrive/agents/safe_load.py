"""Open a stable-baselines3 zip without running code from it.

SB3's own loader unpickles fields of the zip (classes, schedules, spaces), and unpickling a
stranger's file can run arbitrary code. Attack tools are pointed at models from strangers, so
zodrive's default path reads only plain data: the zip's `data` JSON (json.loads; pickled
fields are ignored) and `policy.pth` through `torch.load(weights_only=True)`. The policy
network (an MLP: SB3's Q-network for DQN, the tanh actor for DDPG) is rebuilt from the
weight shapes. Anything this cannot rebuild faithfully (a custom activation or feature
extractor) is refused; `--trust-model` opts into SB3's full loader.
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from zodrive.errors import ZodriveError

HEADS = {"dqn": "q_net.q_net", "ddpg": "actor.mu"}  # SB3 state-dict prefixes of the acting network
CHANGES_THE_NETWORK = {"activation_fn", "features_extractor_class", "features_extractor_kwargs", "net_arch_kwargs"}
MAX_MEMBER_BYTES = 512 * 2**20  # refuse zip members that would inflate beyond this


@dataclass(frozen=True)
class PolicyNetwork:
    algo: str                    # dqn | ddpg
    net: nn.Sequential           # flat observation -> Q-values (dqn) or action in [-1, 1] (ddpg)
    obs_shape: tuple[int, ...]
    n_outputs: int


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _member(archive: zipfile.ZipFile, name: str, path: Path) -> bytes:
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise ZodriveError(f"{path} is not a stable-baselines3 model (no {name!r} inside)") from None
    if info.file_size > MAX_MEMBER_BYTES:
        raise ZodriveError(f"{path}: {name!r} is implausibly large ({info.file_size} bytes)")
    return archive.read(name)


def read_plain(path: Path) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """The zip's plain JSON data and the policy's tensors; nothing is unpickled."""
    if not zipfile.is_zipfile(path):
        raise ZodriveError(f"{path} is not a stable-baselines3 model (not a zip file)")
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(_member(archive, "data", path))
            weights = torch.load(io.BytesIO(_member(archive, "policy.pth", path)), map_location="cpu",
                                 weights_only=True)
    except ZodriveError:
        raise
    except Exception as exc:  # damaged archive, non-JSON data, a pickle that needs code
        raise ZodriveError(f"{path} is corrupt or not a plain stable-baselines3 model ({type(exc).__name__})") from exc
    if not isinstance(data, dict) or not isinstance(weights, dict):
        raise ZodriveError(f"{path} is not a stable-baselines3 model (unexpected contents)")
    return data, weights


def _algo(weights: dict[str, torch.Tensor], path: Path) -> str:
    for algo, prefix in HEADS.items():
        if any(key.startswith(prefix + ".") for key in weights):
            return algo
    raise ZodriveError(f"{path}: unsupported policy (zodrive loads SB3 DQN and DDPG MLP policies)")


def _space_shape(space: Any) -> tuple[int, ...] | None:
    shape = space.get("_shape") if isinstance(space, dict) else None
    return tuple(int(v) for v in shape) if isinstance(shape, list) else None


def describe(data: dict[str, Any], weights: dict[str, torch.Tensor], path: Path) -> dict[str, Any]:
    """Algorithm and space shapes of a zip's plain contents (see `read_plain`)."""
    action = data.get("action_space") if isinstance(data.get("action_space"), dict) else {}
    n_actions = int(action["n"]) if "n" in action else (_space_shape(action) or (None,))[0]
    return {"algo": _algo(weights, path), "obs_shape": _space_shape(data.get("observation_space")),
            "n_actions": n_actions}


def load_policy_network(path: Path) -> PolicyNetwork:
    """Rebuild the acting network of an SB3 DQN/DDPG zip from plain data only."""
    return network_from(*read_plain(path), path)


def network_from(data: dict[str, Any], weights: dict[str, torch.Tensor], path: Path) -> PolicyNetwork:
    """The acting network (SB3's default MLP) rebuilt from a zip's plain contents."""
    algo = _algo(weights, path)
    kwargs = data.get("policy_kwargs", {})
    if not isinstance(kwargs, dict) or ":serialized:" in kwargs or set(kwargs) & CHANGES_THE_NETWORK:
        raise ZodriveError(f"{path} uses custom policy options ({', '.join(sorted(map(str, kwargs)))}); "
                           "zodrive can only rebuild SB3's default MLP safely (pass --trust-model to load it with SB3)")
    prefix = HEADS[algo]
    layers = sorted({int(m.group(1)) for key in weights if (m := re.fullmatch(re.escape(prefix) + r"\.(\d+)\.weight", key))})
    extra = [k for k in weights if k.startswith(prefix.split(".")[0] + ".features_extractor")]
    layout_ok = bool(layers) and not extra and layers == list(range(0, 2 * len(layers), 2)) and all(
        weights[f"{prefix}.{i}.weight"].ndim == 2
        and getattr(weights.get(f"{prefix}.{i}.bias"), "shape", None) == weights[f"{prefix}.{i}.weight"].shape[:1]
        for i in layers)  # SB3's MLP: Linear layers at even indices, an activation between them
    if not layout_ok:
        raise ZodriveError(f"{path}: unexpected policy network layout; pass --trust-model to load it with SB3")
    modules: list[nn.Module] = []
    state: dict[str, torch.Tensor] = {}
    for i, index in enumerate(layers):
        weight, bias = weights[f"{prefix}.{index}.weight"], weights[f"{prefix}.{index}.bias"]
        modules.append(nn.Linear(weight.shape[1], weight.shape[0]))
        state[f"{len(modules) - 1}.weight"], state[f"{len(modules) - 1}.bias"] = weight, bias
        if i < len(layers) - 1:
            modules.append(nn.ReLU())  # SB3's default activation for DQN and TD3/DDPG policies
    if algo == "ddpg":
        modules.append(nn.Tanh())  # SB3's actor squashes its action into [-1, 1]
    net = nn.Sequential(*modules)
    net.load_state_dict(state)
    net.eval()
    obs_shape = _space_shape(data.get("observation_space")) or (int(weights[f"{prefix}.0.weight"].shape[1]),)
    n_in = int(torch.tensor(obs_shape).prod())
    if n_in != modules[0].in_features:
        raise ZodriveError(f"{path}: observation space {obs_shape} does not match the network's input")
    n_outputs = int(weights[f"{prefix}.{layers[-1]}.weight"].shape[0])
    return PolicyNetwork(algo=algo, net=net, obs_shape=obs_shape, n_outputs=n_outputs)


def shipped_sums(folder: Path) -> dict[str, str]:
    """`models/SHA256SUMS` as {relative path: sha256}."""
    sums_file = folder / "SHA256SUMS"
    if not sums_file.is_file():
        return {}
    sums = {}
    for line in sums_file.read_text().splitlines():
        if line.strip():
            digest, _, name = line.partition("  ")
            sums[name.strip()] = digest.strip()
    return sums
