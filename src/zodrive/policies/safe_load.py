"""Open a stable-baselines3 / sb3-contrib zip without running code from it.

SB3's own loader unpickles fields of the zip (classes, schedules, spaces), and unpickling a
stranger's file can run arbitrary code. Attack tools are pointed at models from strangers, so
zodrive's default path reads only plain data: the zip's `data` JSON (json.loads; the pickled
blobs in it are never decoded, only the readable copies SB3 writes beside them) and
`policy.pth` through `torch.load(weights_only=True)`. The acting network is rebuilt from the
weight names and shapes, for every MLP policy of DQN, QR-DQN, DDPG, TD3, SAC, TQC, PPO and
A2C, with the output SB3's `predict(deterministic=True)` acts on:

| family | weights | outputs (what the attacker's queries return) |
|---|---|---|
| dqn    | `q_net.q_net.*`                 | Q-values; action = argmax |
| qrdqn  | `quantile_net.quantile_net.*`   | mean of each action's quantiles; action = argmax |
| ddpg   | `actor.mu.*` (DDPG, TD3)        | tanh action mapped to the action space |
| sac    | `actor.latent_pi.*`, `actor.mu` (SAC, TQC) | tanh of the mean, mapped to the action space |
| ppo    | `mlp_extractor.policy_net.*`, `action_net` (PPO, A2C) | discrete: logits; continuous: the mean, clipped |

Anything this cannot rebuild faithfully (a custom feature extractor, a recurrent policy,
an unknown activation or option) is refused with a one-line reason; `--trust-model` opts into
SB3's full loader.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from zodrive.errors import ZodriveError
from zodrive.runinfo import sha256  # noqa: F401  (re-exported: safe_load.sha256)

if TYPE_CHECKING:
    from zodrive.attacks.victim import ActionKind

MAX_MEMBER_BYTES = 512 * 2**20  # refuse zip members that would inflate beyond this

FAMILIES = {  # family -> (what it covers, kind of policy it is)
    "dqn": "DQN", "qrdqn": "QR-DQN (sb3-contrib)", "ddpg": "DDPG or TD3",
    "sac": "SAC or TQC (sb3-contrib)", "ppo": "PPO or A2C",
}
SUPPORTED = "SB3 / sb3-contrib MLP policies of DQN, QR-DQN, DDPG, TD3, SAC, TQC, PPO and A2C"
ACTIVATIONS = {"ReLU": nn.ReLU, "Tanh": nn.Tanh, "ELU": nn.ELU, "LeakyReLU": nn.LeakyReLU, "GELU": nn.GELU,
               "SiLU": nn.SiLU, "Sigmoid": nn.Sigmoid, "Softplus": nn.Softplus, "SELU": nn.SELU, "Mish": nn.Mish}
DEFAULT_ACTIVATION = {"dqn": "ReLU", "qrdqn": "ReLU", "ddpg": "ReLU", "sac": "ReLU", "ppo": "Tanh"}
# policy_kwargs that do not change the deterministic forward pass, or that are read below
HARMLESS_KWARGS = {"net_arch", "activation_fn", "optimizer_class", "optimizer_kwargs", "ortho_init",
                   "share_features_extractor", "normalize_images", "log_std_init", "use_sde", "n_quantiles",
                   "use_expln", "full_std", "squash_output", "n_critics", "features_extractor_class",
                   "features_extractor_kwargs", "dueling", "clip_mean"}


@dataclass(frozen=True)
class PolicyNetwork:
    algo: str                    # family: dqn | qrdqn | ddpg | sac | ppo (see FAMILIES)
    net: nn.Module               # flat observation -> scores (discrete) or the action taken (continuous)
    obs_shape: tuple[int, ...]
    n_outputs: int
    kind: ActionKind = "discrete"


class ActingNetwork(nn.Module):
    """An MLP body and what SB3 does to its output before acting, as torch operations in
    SB3's float32 order (so the safe and the full loader agree bit for bit)."""

    low: torch.Tensor  # buffers (register_buffer)
    high: torch.Tensor

    def __init__(self, body: nn.Sequential, post: str = "none", *, n_quantiles: int = 0,
                 low: np.ndarray | None = None, high: np.ndarray | None = None) -> None:
        super().__init__()
        self.body, self.post, self.n_quantiles = body, post, n_quantiles
        self.register_buffer("low", torch.as_tensor(np.zeros(0) if low is None else low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(np.zeros(0) if high is None else high, dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.body(x)
        if self.post == "quantiles":   # QR-DQN: (B, quantiles, actions) -> the mean over quantiles
            return out.view(-1, self.n_quantiles, out.shape[-1] // self.n_quantiles).mean(dim=1)
        if self.post == "unscale":     # squashed action in [-1, 1] -> the action space [low, high]
            return unscale(out, self.low, self.high)
        if self.post == "clip":        # Gaussian mean -> clipped to the action space
            return torch.clamp(out, self.low, self.high)
        return out


def unscale(action: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """SB3's `unscale_action`, in its order of float32 operations."""
    return low + (0.5 * (action + 1.0) * (high - low))


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
    odd = next((k for k, v in weights.items() if not isinstance(v, torch.Tensor)), None)
    if odd is not None:
        raise ZodriveError(f"{path}: policy.pth holds {type(weights[odd]).__name__} where the tensor {odd!r} belongs")
    return data, weights


def _family(weights: dict[str, torch.Tensor], path: Path) -> str:
    def has(prefix: str) -> bool:
        return any(key.startswith(prefix) for key in weights)

    if has("lstm_actor.") or has("lstm_critic."):
        raise ZodriveError(f"{path}: recurrent policies (RecurrentPPO) are not supported: zodrive attacks "
                           "memoryless policies; pass a feed-forward policy")
    for family, prefix in (("qrdqn", "quantile_net.quantile_net."), ("dqn", "q_net.q_net."),
                           ("sac", "actor.latent_pi."), ("ddpg", "actor.mu."), ("ppo", "action_net.")):
        if has(prefix):
            return family
    raise ZodriveError(f"{path}: unsupported policy (zodrive loads {SUPPORTED})")


def _space_shape(space: Any) -> tuple[int, ...] | None:
    shape = space.get("_shape") if isinstance(space, dict) else None
    if isinstance(shape, str):  # SB3 writes some readable fields as their repr
        shape = json.loads(shape) if re.fullmatch(r"\[[\d, ]*\]", shape.strip()) else None
    if not isinstance(shape, list) or not all(_count(v) is not None for v in shape):
        return None  # absent or damaged (text or a negative where a size belongs)
    return tuple(_count(v) for v in shape)  # type: ignore[misc]


def _count(value: Any) -> int | None:
    """A size or count as the zip writes it (an integer, or its digits), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value if value >= 0 else None
    return int(value) if isinstance(value, str) and value.strip().isdigit() else None


def _space_type(space: Any) -> str:
    text = space.get(":type:", "") if isinstance(space, dict) else ""
    return text.rsplit(".", 1)[-1].strip("'>") if text else ""


def _array(text: Any, size: int, what: str, path: Path) -> np.ndarray:
    """A readable numpy repr such as '[-1. -1.]' (never a pickle) as float32."""
    if isinstance(text, list):
        values = np.asarray(text, dtype=np.float32)
    else:
        body = str(text).strip().strip("[]").replace("\n", " ")
        if "..." in body:
            raise ZodriveError(f"{path}: the action space's {what} is abbreviated in the file; pass --trust-model")
        try:
            values = np.asarray([float(v) for v in body.split()], dtype=np.float32)
        except ValueError:
            raise ZodriveError(f"{path}: cannot read the action space's {what} ({str(text)[:40]!r})") from None
    if values.size == 1 and size > 1:
        values = np.full(size, values.item(), dtype=np.float32)
    if values.size != size:
        raise ZodriveError(f"{path}: the action space's {what} has {values.size} values for {size} dimensions")
    return values


def describe(data: dict[str, Any], weights: dict[str, torch.Tensor], path: Path) -> dict[str, Any]:
    """Family, kind, space shapes and action bounds of a zip's plain contents (see `read_plain`)."""
    action: dict[str, Any] = data["action_space"] if isinstance(data.get("action_space"), dict) else {}
    family = _family(weights, path)
    space = _space_type(action)
    if space == "Discrete" or "n" in action:
        if str(action.get("start", "0")) not in ("0", "[0]"):
            raise ZodriveError(f"{path}: a Discrete action space that does not start at 0 is not supported")
        n = _count(action.get("n"))
        if not n:
            raise ZodriveError(f"{path}: the action space's n is {action.get('n')!r}, not a number of actions")
        info = {"kind": "discrete", "n_actions": n, "action_low": None, "action_high": None}
    elif space in ("Box", ""):
        shape = _space_shape(action)
        if shape is None or len(shape) != 1:
            raise ZodriveError(f"{path}: zodrive attacks policies with Discrete or 1-D Box actions, not {shape}")
        info = {"kind": "continuous", "n_actions": shape[0],
                "action_low": _array(action.get("low", -1.0), shape[0], "low", path).tolist(),
                "action_high": _array(action.get("high", 1.0), shape[0], "high", path).tolist()}
    else:
        raise ZodriveError(f"{path}: unsupported action space {space} (zodrive attacks Discrete or Box actions)")
    continuous_family = family in ("ddpg", "sac")
    if continuous_family and info["kind"] != "continuous":
        raise ZodriveError(f"{path}: a {FAMILIES[family]} policy with a discrete action space is not an SB3 model")
    if family in ("dqn", "qrdqn") and info["kind"] != "discrete":
        raise ZodriveError(f"{path}: a {FAMILIES[family]} policy with continuous actions is not an SB3 model")
    observation = data.get("observation_space")
    return {"algo": family, "sb3_class": sb3_class_name(data, family),
            "obs_space": _space_type(observation) if isinstance(observation, dict) else "",
            "obs_shape": _space_shape(observation), "obs_low": _bounds(observation, "low"),
            "obs_high": _bounds(observation, "high"), **info}


def _bounds(space: Any, which: str) -> list[float] | None:
    """The observation space's `low` / `high` as written in the zip's readable repr (None where the
    repr is abbreviated or absent: then only the shape is compared)."""
    text = space.get(which) if isinstance(space, dict) else None
    if not isinstance(text, str) or "..." in text:
        return None
    try:
        return [float(v) for v in text.replace("[", " ").replace("]", " ").split()]
    except ValueError:
        return None


def sb3_class_name(data: dict[str, Any], family: str) -> str:
    """The SB3 / sb3-contrib class that wrote the zip, told apart by its plain hyperparameters."""
    if family == "ppo":
        return "PPO" if "clip_range" in data else "A2C"
    if family == "sac":
        return "TQC" if "top_quantiles_to_drop_per_net" in data else "SAC"
    if family == "ddpg":
        return "TD3"  # DDPG is a TD3 with one critic update per actor update: TD3's loader reads both
    return {"dqn": "DQN", "qrdqn": "QRDQN"}[family]


def load_policy_network(path: Path) -> PolicyNetwork:
    """Rebuild the acting network of an SB3 zip from plain data only."""
    return network_from(*read_plain(path), path)


def _activation(kwargs: dict[str, Any], family: str, path: Path) -> type[nn.Module]:
    text = kwargs.get("activation_fn")
    if text is None:
        return ACTIVATIONS[DEFAULT_ACTIVATION[family]]
    match = re.fullmatch(r"<class 'torch\.nn\.modules\.activation\.(\w+)'>", str(text))
    if match is None or match.group(1) not in ACTIVATIONS:
        raise ZodriveError(f"{path}: activation {text} is not one zodrive rebuilds safely "
                           f"({', '.join(ACTIVATIONS)}); pass --trust-model to load it with SB3")
    return ACTIVATIONS[match.group(1)]


def _check_options(data: dict[str, Any], kwargs: Any, family: str, path: Path) -> None:
    """Refuse options that would make the rebuilt network differ from the one SB3 builds."""
    if not isinstance(kwargs, dict):
        raise ZodriveError(f"{path}: unreadable policy options; pass --trust-model to load it with SB3")
    unknown = sorted(k for k in kwargs if not k.startswith(":") and k not in HARMLESS_KWARGS)
    extractor = kwargs.get("features_extractor_class")
    if extractor is not None and "FlattenExtractor'" not in str(extractor):
        unknown.append("features_extractor_class")
    if kwargs.get("features_extractor_kwargs"):
        unknown.append("features_extractor_kwargs")
    if kwargs.get("dueling"):
        unknown.append("dueling")
    if family == "sac" and (kwargs.get("use_sde") or data.get("use_sde")):
        unknown.append("use_sde")
    if unknown:
        raise ZodriveError(f"{path} uses policy options zodrive cannot rebuild safely ({', '.join(unknown)}); "
                           "pass --trust-model to load it with SB3")


def _mlp(weights: dict[str, torch.Tensor], prefix: str, activation: type[nn.Module], *, act_after_last: bool,
         path: Path) -> list[nn.Module]:
    """SB3's `create_mlp`: Linear layers at even indices with an activation between them (and
    after the last one for the latent networks of SAC and PPO)."""
    layers = sorted({int(m.group(1)) for key in weights
                     if (m := re.fullmatch(re.escape(prefix) + r"\.(\d+)\.weight", key))})
    if layers != list(range(0, 2 * len(layers), 2)):
        raise ZodriveError(f"{path}: unexpected policy network layout; pass --trust-model to load it with SB3")
    modules: list[nn.Module] = []
    for i, index in enumerate(layers):
        modules.append(_linear(weights, f"{prefix}.{index}", path))
        if i < len(layers) - 1 or act_after_last:
            modules.append(activation())
    return modules


def _linear(weights: dict[str, torch.Tensor], prefix: str, path: Path) -> nn.Linear:
    weight, bias = weights.get(f"{prefix}.weight"), weights.get(f"{prefix}.bias")
    if weight is None or weight.ndim != 2 or bias is None or tuple(bias.shape) != tuple(weight.shape[:1]):
        raise ZodriveError(f"{path}: unexpected policy network layout at {prefix}; pass --trust-model")
    layer = nn.Linear(weight.shape[1], weight.shape[0])
    with torch.no_grad():
        layer.weight.copy_(weight)
        layer.bias.copy_(bias)
    return layer


def network_from(data: dict[str, Any], weights: dict[str, torch.Tensor], path: Path) -> PolicyNetwork:
    """The acting network rebuilt from a zip's plain contents (see the module docstring)."""
    info = describe(data, weights, path)
    family = info["algo"]
    broken = [k for k, v in weights.items()
              if torch.is_tensor(v) and v.is_floating_point() and not torch.isfinite(v).all()]
    if broken:
        raise ZodriveError(f"{path}: {broken[0]} holds NaN or infinite weights ({len(broken)} tensors): its outputs "
                           "decide nothing (an argmax of NaN is action 0)")
    kwargs = data.get("policy_kwargs", {})
    _check_options(data, kwargs, family, path)
    extractors = [k for k in weights if "features_extractor" in k]
    if extractors:
        raise ZodriveError(f"{path}: the policy has a learned feature extractor ({extractors[0]}); zodrive "
                           "rebuilds MLP policies only; pass --trust-model to load it with SB3")
    activation = _activation(kwargs, family, path)
    low = None if info["action_low"] is None else np.asarray(info["action_low"], dtype=np.float32)
    high = None if info["action_high"] is None else np.asarray(info["action_high"], dtype=np.float32)
    identity = low is not None and bool(np.all(low == -1.0) and np.all(high == 1.0))
    post, n_quantiles = "none", 0
    if family in ("dqn", "qrdqn", "ddpg"):
        prefix = {"dqn": "q_net.q_net", "qrdqn": "quantile_net.quantile_net", "ddpg": "actor.mu"}[family]
        modules = _mlp(weights, prefix, activation, act_after_last=False, path=path)
        if family == "ddpg":
            modules.append(nn.Tanh())  # SB3's actor squashes its action into [-1, 1]
            post = "none" if identity else "unscale"
        if family == "qrdqn":
            n_quantiles = int(kwargs.get("n_quantiles", 0) or 0) or modules[-1].out_features // info["n_actions"]
            if modules[-1].out_features != n_quantiles * info["n_actions"]:
                raise ZodriveError(f"{path}: {modules[-1].out_features} outputs are not {n_quantiles} quantiles "
                                   f"of {info['n_actions']} actions")
            post = "quantiles"
    elif family == "sac":
        modules = _mlp(weights, "actor.latent_pi", activation, act_after_last=True, path=path)
        modules += [_linear(weights, "actor.mu", path), nn.Tanh()]  # deterministic: tanh of the mean
        post = "none" if identity else "unscale"
    else:  # ppo / a2c
        modules = _mlp(weights, "mlp_extractor.policy_net", activation, act_after_last=True, path=path)
        modules.append(_linear(weights, "action_net", path))
        if info["kind"] == "continuous":
            if kwargs.get("squash_output"):
                modules.append(nn.Tanh())
                post = "none" if identity else "unscale"
            else:
                post = "clip"
    body = nn.Sequential(*modules)
    linears = [m for m in modules if isinstance(m, nn.Linear)]
    if any(a.out_features != b.in_features for a, b in zip(linears, linears[1:])):
        raise ZodriveError(f"{path}: the policy's layers do not chain; the file is damaged")
    net = body.eval() if post == "none" else ActingNetwork(body, post, n_quantiles=n_quantiles, low=low,
                                                          high=high).eval()
    obs_shape = info["obs_shape"] or (int(linears[0].in_features),)
    if int(np.prod(obs_shape)) != linears[0].in_features:
        raise ZodriveError(f"{path}: observation space {obs_shape} does not match the network's input")
    n_outputs = info["n_actions"]
    head = linears[-1].out_features // (n_quantiles or 1)
    if head != n_outputs:
        raise ZodriveError(f"{path}: the network has {head} outputs for {n_outputs} actions")
    return PolicyNetwork(algo=family, net=net, obs_shape=tuple(obs_shape), n_outputs=n_outputs, kind=info["kind"])


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
