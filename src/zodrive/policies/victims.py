"""Adapters that turn models into `Victim`s (query functions) for the attack library.

Attacks only ever see a `zodrive.attacks.victim.Victim`; SB3 / sb3-contrib models, torch
networks and plain callables are wrapped here. The outputs are what the policy acts on
(see `zodrive.policies.safe_load`): scores of discrete actions, or the continuous action.
"""

from __future__ import annotations

from typing import Any, Callable, Literal, cast

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from zodrive.policies.safe_load import unscale
from zodrive.attacks.victim import ActionKind, Victim
from zodrive.envs import Scenario, scenario
from zodrive.errors import ZodriveError, cause


def network_victim(net: torch.nn.Module, kind: Literal["discrete", "continuous"], obs_shape: tuple[int, ...]) -> Victim:
    """A torch network over flattened observations (scores or action) as a victim."""
    flat = int(np.prod(obs_shape))
    net.eval()

    def query(obs: np.ndarray) -> np.ndarray:
        batch = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32)).reshape(-1, flat)
        with torch.inference_mode():
            return net(batch).numpy()

    def forward(obs: torch.Tensor) -> torch.Tensor:
        return net(obs.reshape(-1, flat).float())

    # zodrive built this network from a file: the harness may call it for itself (calibration)
    return Victim(query=query, kind=kind, obs_shape=tuple(obs_shape), differentiable=forward, calibrate=query)


def module_victim(module: torch.nn.Module, kind: Literal["discrete", "continuous"],
                  obs_shape: tuple[int, ...]) -> Victim:
    """A user's torch module over observation batches (B, *obs_shape) as a victim (white-box
    attacks may differentiate it)."""
    module.eval()

    def forward(obs: torch.Tensor) -> torch.Tensor:
        return module(obs.reshape(-1, *obs_shape).float())

    def query(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            out = forward(torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32)))
        return np.asarray(out.detach().cpu().numpy(), dtype=np.float32).reshape(len(obs), -1)

    return Victim(query=query, kind=kind, obs_shape=tuple(obs_shape), differentiable=forward)


def callable_victim(fn: Callable[[np.ndarray], Any], kind: Literal["discrete", "continuous"],
                    obs_shape: tuple[int, ...]) -> Victim:
    """Any numpy callable (observation batch -> scores or actions) as a black-box victim."""

    def query(obs: np.ndarray) -> np.ndarray:
        batch = np.ascontiguousarray(obs, dtype=np.float32).reshape(-1, *obs_shape)
        return np.asarray(fn(batch), dtype=np.float32).reshape(len(batch), -1)

    return Victim(query=query, kind=kind, obs_shape=tuple(obs_shape))


def _acting_forward(model: BaseAlgorithm) -> tuple[Callable[[torch.Tensor], torch.Tensor], ActionKind]:
    """What the loaded SB3 policy acts on, as a torch function of an observation batch."""
    from stable_baselines3 import DQN, TD3, SAC
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor

    policy: Any = model.policy  # its class (and attributes) depend on the algorithm, told apart below
    space = model.action_space
    if isinstance(model, DQN):  # the MLP after the flatten extractor: same arithmetic, less Python per query
        net = policy.q_net
        head = net.q_net if isinstance(net.features_extractor, FlattenExtractor) else None
        return (lambda x: head(x.flatten(1))) if head is not None else net, "discrete"
    name = type(model).__name__
    if name == "QRDQN":
        net = policy.quantile_net
        return (lambda x: net(x).mean(dim=1)), "discrete"  # (B, quantiles, actions) -> mean per action
    low = torch.as_tensor(getattr(space, "low", np.zeros(0)), dtype=torch.float32)
    high = torch.as_tensor(getattr(space, "high", np.zeros(0)), dtype=torch.float32)
    identity = bool(low.numel()) and bool(torch.all(low == -1.0) and torch.all(high == 1.0))

    def squashed(action: torch.Tensor) -> torch.Tensor:
        return action if identity else unscale(action, low, high)

    if isinstance(model, TD3):  # DDPG is a TD3 subclass; the actor's MLP ends in tanh
        actor = policy.actor
        mu = actor.mu if isinstance(actor.features_extractor, FlattenExtractor) else None
        return (lambda x: squashed(mu(x.flatten(1)) if mu is not None else actor(x))), "continuous"
    if isinstance(model, SAC) or name == "TQC":
        return (lambda x: squashed(policy.actor(x, deterministic=True))), "continuous"
    if isinstance(policy, ActorCriticPolicy):
        def forward(x: torch.Tensor) -> torch.Tensor:
            # one extractor named: one tensor
            features = cast(torch.Tensor, policy.extract_features(x, policy.pi_features_extractor))
            out = policy.action_net(policy.mlp_extractor.forward_actor(features))
            if not hasattr(space, "n"):
                out = squashed(torch.tanh(out)) if policy.squash_output else torch.clamp(out, low, high)
            return out

        return forward, "discrete" if hasattr(space, "n") else "continuous"
    raise TypeError(f"no victim adapter for {name}")


def check_sb3_model(model: BaseAlgorithm) -> None:
    """Refuse, in one line and in its own words, an SB3 model in memory that zodrive cannot query as
    one observation in, one action out: a recurrent policy (its action depends on a hidden state), a
    Dict or Tuple observation, or one trained on stacked frames (it holds a VecFrameStack)."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecFrameStack, unwrap_vec_wrapper

    name = type(model).__name__
    if name == "RecurrentPPO" or hasattr(model.policy, "lstm_actor"):
        raise ZodriveError(f"{name}: recurrent policies are not supported: the action depends on an LSTM state that "
                           "zodrive's one-observation queries do not carry")
    if not isinstance(model.observation_space, spaces.Box):
        raise ZodriveError(f"{name} observes a {type(model.observation_space).__name__} (a goal-conditioned or "
                           "multi-part observation, as parking-v0's): zodrive attacks policies that observe one Box")
    broken = [n for n, p in model.policy.named_parameters() if not torch.isfinite(p).all()]
    if broken:
        raise ZodriveError(f"{name}: {broken[0]} holds NaN or infinite weights: its outputs decide nothing")
    env = model.get_env()
    stack = unwrap_vec_wrapper(env, VecFrameStack) if env is not None else None
    if stack is not None:
        raise ZodriveError(f"{name} was trained on {stack.stacked_obs.n_stack} stacked frames (its environment is a "
                           "VecFrameStack): zodrive feeds one observation per step and does not stack frames")


def sb3_victim(model: BaseAlgorithm) -> Victim:
    """Wrap a loaded SB3 / sb3-contrib model as a black-box victim: a live view of its
    networks (training them changes the victim)."""
    check_sb3_model(model)
    assert model.observation_space.shape is not None  # a Box (`check_sb3_model`)
    obs_shape = tuple(model.observation_space.shape)
    model.policy.set_training_mode(False)
    forward_fn, kind = _acting_forward(model)

    def forward(obs: torch.Tensor) -> torch.Tensor:
        return forward_fn(obs.reshape(-1, *obs_shape).float())

    def query(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return forward(torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))).numpy()

    return Victim(query=query, kind=kind, obs_shape=obs_shape, differentiable=forward)


def _one_hot(actions: np.ndarray, n: int, label: str) -> np.ndarray:
    """Discrete actions (B,) as scores: 1 for the action taken, 0 elsewhere."""
    index = np.rint(actions)
    if not (np.all(index == actions) and np.all((index >= 0) & (index < n))):
        raise ZodriveError(f"{label} returns one value per observation, so its outputs are actions; these are not "
                           f"action indices 0..{n - 1} ({actions[:3].tolist()} ...)")
    return np.eye(n, dtype=np.float32)[index.astype(np.int64)]


def object_victim(policy: Any, where: dict[str, Any] | Scenario, label: str) -> Victim:
    """The victim of a torch module or a numpy callable on the scenario of `where` (a preset or
    an environment's `Scenario`). Its outputs are checked on every call, the first included: the
    harness sends the user's code no rows of its own."""
    env = where if isinstance(where, Scenario) else scenario(where)
    if isinstance(policy, torch.nn.Module):
        inner = module_victim(policy, env.kind, env.obs_shape)
    elif callable(policy):
        inner = callable_victim(policy, env.kind, env.obs_shape)
    else:
        raise ZodriveError(f"{label} is a {type(policy).__name__}, not a torch module or a callable")

    def query(obs: np.ndarray) -> np.ndarray:
        try:
            out = inner.query(obs)
        except ZodriveError:
            raise
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the user's code may raise anything, exit included
            raise ZodriveError(f"{label}: the policy failed on a batch of observations of shape "
                               f"{tuple(np.shape(obs))}: {cause(exc)}") from exc
        if env.kind == "discrete" and out.shape[1:] in ((), (1,)):  # actions, not scores: one-hot scores
            out = _one_hot(out.reshape(len(obs)), env.n_actions, label)
        if out.shape != (len(obs), env.n_actions):
            raise ZodriveError(f"{label} returns outputs of shape {out.shape[1:]} per observation; "
                               f"{env.name!r} needs {env.n_actions} "
                               f"({'scores' if env.kind == 'discrete' else 'action dims'})")
        if not np.all(np.isfinite(out)):  # an argmax of NaN scores is action 0: a decision nobody made
            raise ZodriveError(f"{label} returned NaN or infinite outputs on "
                               f"{int((~np.isfinite(out)).any(axis=1).sum())} of {len(obs)} observations")
        return out

    return Victim(query=query, kind=inner.kind, obs_shape=inner.obs_shape, differentiable=inner.differentiable)
