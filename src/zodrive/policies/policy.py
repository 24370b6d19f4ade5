"""A policy is an object: `resolve` turns whatever a user passes into a `Policy`, once.

What a user may pass: a model file or folder (SB3 / sb3-contrib zip, read without unpickling),
an ONNX file, `FILE.py:NAME` (the user's code, run by design), `baseline:NAME`, or an object
in memory (a stable-baselines3 model, a torch `nn.Module`, a numpy callable). Everything
downstream (evaluation, comparison, training on a victim, reports) asks the `Policy`, never
the string: its kind, its label for tables, the key its results are filed under, whether
white-box attacks can differentiate it, and its `Victim` on a scenario.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, cast

import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from zodrive.attacks.victim import Victim
from zodrive.drivers import baselines as bl
from zodrive.envs import Scenario, scenario
from zodrive.errors import ZodriveError
from zodrive.policies import resolve as text
from zodrive.policies.factory import build, is_factory, split_factory
from zodrive.policies.folders import trained_with
from zodrive.policies.loading import load_network, stacking_hint
from zodrive.policies.onnx_policy import is_onnx
from zodrive.policies.normalize import normalized_victim
from zodrive.policies.victims import check_sb3_model, network_victim, object_victim, sb3_victim
from zodrive.runinfo import sha256

Kind = Literal["model", "onnx", "factory", "baseline", "sb3", "module", "callable"]
IN_MEMORY: tuple[Kind, ...] = ("sb3", "module", "callable")


@dataclass(frozen=True, eq=False)
class Policy:
    """What drives: resolved once from what the user passed (`resolve`)."""

    kind: Kind                 # model (SB3 zip or folder), onnx, factory (FILE.py:NAME), baseline, or in memory
    ref: str                   # what results name it by: a path, `baseline:NAME`, `FILE.py:NAME`, `memory:LABEL`
    label: str                 # a short name for tables
    gradients: bool            # white-box attacks can differentiate it
    obj: Any = field(default=None, repr=False)  # the object in memory (kind sb3 / module / callable)

    @property
    def in_memory(self) -> bool:
        return self.kind in IN_MEMORY

    @property
    def reads_simulator(self) -> bool:
        """A driver that reads the simulator, not the observation (no observation attack reaches it)."""
        return self.kind == "baseline" and bl.get_baseline(self.ref).reads == "simulator"

    def key(self) -> str:
        """What a run folder is keyed on: the content of the model file (SHA-256, so a moved
        checkout still matches and a swapped file does not), the factory's code file and name,
        or the baseline's name. An object in memory has no content key: it is never resumed."""
        if self.kind == "baseline":
            return self.ref
        if self.kind == "factory":
            file, name = split_factory(self.ref)
            return f"sha256:{sha256(file)}:{name}"
        if self.in_memory:
            raise ZodriveError(f"{self.label} lives in memory: it has no content to key a run folder on "
                               "(save it and pass the file to resume runs)")
        key = "sha256:" + sha256(Path(self.ref))
        norm = trained_with(Path(self.ref)).normalization  # the statistics decide what the policy sees
        return key if norm is None else f"{key}+vecnormalize:sha256:{sha256(norm)}"

    def action_kind(self) -> str:
        """`discrete` or `continuous`: the kind of scenario it drives by default."""
        if self.kind == "sb3":
            return "discrete" if hasattr(self.obj.action_space, "n") else "continuous"
        if self.kind in ("module", "callable", "factory"):
            raise ZodriveError(f"{self.label} is code: say where it drives (a preset or an env id)")
        return text.policy_kind(self.ref)

    def check(self, preset: dict[str, Any], *, attacked: bool = False) -> None:
        """A one-line error if it cannot drive `preset` (or be attacked there)."""
        if self.in_memory:
            self.victim(preset)
        else:
            text.check_policy(self.ref, preset, attacked=attacked)

    def victim(self, preset: dict[str, Any], *, trust: bool = False) -> Victim:
        """Its black-box victim on `preset`'s observation (`trust`: read an SB3 zip with SB3's
        own loader, which unpickles)."""
        if not self.in_memory:
            return text.load_victim(self.ref, preset, trust=trust)
        env = scenario(preset)
        if self.kind == "sb3":
            victim = sb3_victim(self.obj)
            if tuple(victim.obs_shape) != tuple(env.obs_shape) or victim.kind != env.kind:
                raise ZodriveError(f"{self.label} reads observations of shape {victim.obs_shape} and acts "
                                   f"{victim.kind}; preset {preset.get('name')!r} gives {env.obs_shape}, {env.kind}"
                                   + stacking_hint(victim.obs_shape, env.obs_shape))
            return victim
        return object_victim(self.obj, preset, self.label)

    def victim_on(self, where: Scenario) -> Victim:
        """Its victim on an environment built elsewhere (`where`: its `Scenario`), for the
        in-memory kinds, model files and factories (a baseline needs its preset)."""
        if self.kind == "sb3":
            victim = sb3_victim(self.obj)
        elif self.kind in ("module", "callable"):
            return object_victim(self.obj, where, self.label)
        elif self.kind == "factory":
            return object_victim(build(self.ref), where, self.ref)
        elif self.kind == "model":
            network = load_network(self.ref)  # the safe loader: nothing unpickled
            victim = network_victim(network.net, network.kind, network.obs_shape)
            norm = text.normalization(self.ref)
            victim = victim if norm is None else normalized_victim(victim, norm)
        else:
            raise ZodriveError(f"{self.label} is a {self.kind}: give it a zodrive preset (zodrive.evaluate), "
                               "not an environment of your own")
        if tuple(victim.obs_shape) != tuple(where.obs_shape) or victim.kind != where.kind:
            raise ZodriveError(f"{self.label} reads observations of shape {victim.obs_shape} and acts {victim.kind}; "
                               f"{where.name} gives {where.obs_shape}, {where.kind}")
        return victim


def resolve(policy: Any, *, label: str | None = None) -> Policy:
    """The `Policy` of whatever names or holds one: a path (`str` or `Path`) to an SB3 zip,
    model folder or ONNX file, `FILE.py:NAME`, `baseline:NAME`, a `Policy`, a stable-baselines3
    model, a torch `nn.Module` or a numpy callable (observation batch in, scores or actions out).

    :param policy: what drives.
    :param label: the name tables use for an object in memory (default: its class name).
    """
    if isinstance(policy, Policy):
        return policy
    if isinstance(policy, BaseAlgorithm):
        check_sb3_model(policy)  # at the door: a recurrent, Dict-observing or frame-stacked model, in its words
        name = label or type(policy).__name__.lower()
        return Policy("sb3", f"memory:{name}", name, gradients=True, obj=policy)
    if isinstance(policy, torch.nn.Module):
        name = label or type(policy).__name__
        return Policy("module", f"memory:{name}", name, gradients=True, obj=policy)
    if isinstance(policy, (str, Path)):
        ref = str(policy)
        if not ref:
            raise ZodriveError("no policy given: name a model file, FILE.py:NAME or baseline:NAME")
        if bl.is_baseline(ref):
            return Policy("baseline", text.policy_ref(ref), text.policy_label(ref), gradients=False)
        if is_factory(ref):
            return Policy("factory", text.policy_ref(ref), text.policy_label(ref), gradients=True)
        if is_onnx(ref):
            return Policy("onnx", text.policy_ref(ref), text.policy_label(ref), gradients=False)
        return Policy("model", text.policy_ref(ref), text.policy_label(ref), gradients=True)
    if callable(policy):
        name = label or cast(str, getattr(policy, "__name__", type(policy).__name__))
        return Policy("callable", f"memory:{name}", name, gradients=False, obj=policy)
    raise ZodriveError(f"cannot read a policy from a {type(policy).__name__}: pass a model path, FILE.py:NAME, "
                       "baseline:NAME, an SB3 model, a torch module or a numpy callable")
