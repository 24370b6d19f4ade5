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
from functools import cached_property
from pathlib import Path
from typing import Any, Literal, cast

import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from zodrive.attacks.victim import Victim
from zodrive.drivers import baselines as bl
from zodrive.drivers.rules import rules_victim
from zodrive.envs import Scenario, action_kind, action_names, n_actions, observation_shape, scenario
from zodrive.errors import ZodriveError
from zodrive.policies.factory import build, factory_victim, is_factory, split_factory
from zodrive.policies.folders import trained_with
from zodrive.policies.loading import (check_fits, inspect_model, load_model, load_network, model_file, model_kind,
                                      stacking_hint)
from zodrive.policies.normalize import ObsNormalization, normalized_victim, read_normalization
from zodrive.policies.onnx_policy import is_onnx, onnx_metadata, onnx_victim
from zodrive.policies.victims import check_sb3_model, network_victim, object_victim, sb3_victim
from zodrive.runinfo import sha256

Kind = Literal["model", "onnx", "factory", "baseline", "sb3", "module", "callable"]
IN_MEMORY: tuple[Kind, ...] = ("sb3", "module", "callable")
Reads = Literal["observation", "simulator", "nothing"]


@dataclass(frozen=True, eq=False)
class Policy:
    """What drives: resolved once from what the user passed (`resolve`); everything after asks its
    `kind`, never the text it came from."""

    kind: Kind                 # model (SB3 zip or folder), onnx, factory (FILE.py:NAME), baseline, or in memory
    ref: str                   # what results name it by: a path, `baseline:NAME`, `FILE.py:NAME`, `memory:LABEL`
    label: str                 # a short name for tables
    gradients: bool            # white-box attacks can differentiate it
    obj: Any = field(default=None, repr=False)  # the object in memory (kind sb3 / module / callable)
    baseline: bl.Baseline | None = field(default=None, repr=False)  # kind baseline: which one

    @property
    def in_memory(self) -> bool:
        return self.kind in IN_MEMORY

    @property
    def reads(self) -> Reads:
        """What its decisions depend on: the observation (what an observation attack or defense
        reaches), the simulator (a driver that reads it: IDM + MOBIL, the planner), or nothing (a
        constant action)."""
        return self.baseline.reads if self.baseline is not None else "observation"

    @property
    def reads_simulator(self) -> bool:
        """A driver that reads the simulator, not the observation (no observation attack reaches it)."""
        return self.reads == "simulator"

    def key(self) -> str:
        """What a run folder is keyed on: the content of the model file (SHA-256, so a moved
        checkout still matches and a swapped file does not), the factory's code file and name,
        or the baseline's name; hashed once per `Policy`. An object in memory has no content key:
        it is never resumed."""
        return self._content_key

    @cached_property
    def _content_key(self) -> str:
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
        if self.baseline is not None:
            return self.baseline.kinds[0]
        if self.kind == "onnx":
            return onnx_metadata(Path(self.ref))["kind"]
        return model_kind(self.ref)

    def check(self, preset: dict[str, Any], *, attacked: bool = False) -> None:
        """A one-line error if it cannot drive `preset` (or be attacked there)."""
        if self.baseline is not None:
            bl.check_baseline_fits(self.baseline, preset)
            name = f"{bl.PREFIX}{self.baseline.name}"
            if attacked and self.reads == "simulator":
                raise ZodriveError(f"{name} reads the simulator, not the observation: an observation attack cannot "
                                   "reach it")
            if attacked and self.reads == "nothing":
                raise ZodriveError(f"{name} takes one constant action whatever it observes: an observation attack "
                                   "cannot change it (evaluate it clean: it is the floor)")
            if self.reads == "observation":
                self.victim(preset)  # the rules check the observation they are given
        elif self.kind in ("model", "onnx"):
            file = Path(self.ref)
            check_fits(onnx_metadata(file) if self.kind == "onnx" else inspect_model(file), preset, file)
        else:  # code, and objects in memory: built (or asked) and checked against the scenario
            self.victim(preset)

    def victim(self, preset: dict[str, Any], *, trust: bool = False) -> Victim:
        """Its black-box victim on `preset`'s observation (`trust`: read an SB3 zip with SB3's
        own loader, which unpickles)."""
        if self.baseline is not None:
            return _baseline_victim(self.baseline, preset)
        if self.kind == "factory":
            return factory_victim(self.ref, preset)
        if self.kind == "onnx":
            return onnx_victim(Path(self.ref), preset)
        if self.kind == "model":
            if trust:
                victim = sb3_victim(load_model(self.ref, preset, trust=True))
            else:
                network = load_network(self.ref, preset)  # rebuilt from plain data: nothing in the file is unpickled
                victim = network_victim(network.net, action_kind(preset), network.obs_shape)
            return self._normalized(victim)
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
            victim = self._normalized(network_victim(network.net, network.kind, network.obs_shape))
        else:
            raise ZodriveError(f"{self.label} is a {self.kind}: give it a zodrive preset (zodrive.evaluate), "
                               "not an environment of your own")
        if tuple(victim.obs_shape) != tuple(where.obs_shape) or victim.kind != where.kind:
            raise ZodriveError(f"{self.label} reads observations of shape {victim.obs_shape} and acts {victim.kind}; "
                               f"{where.name} gives {where.obs_shape}, {where.kind}")
        return victim

    def normalization(self) -> ObsNormalization | None:
        """The VecNormalize statistics a model file was trained with (None: none beside it, or no model file)."""
        found = trained_with(Path(self.ref)).normalization if self.kind == "model" else None
        return read_normalization(found) if found is not None else None

    def _normalized(self, victim: Victim) -> Victim:
        norm = self.normalization()
        return victim if norm is None else normalized_victim(victim, norm)


def _baseline_victim(baseline: bl.Baseline, preset: dict[str, Any]) -> Victim:
    """The victim of an observation-reading or constant baseline on `preset`."""
    bl.check_baseline_fits(baseline, preset)
    if baseline.reads == "simulator":
        raise ZodriveError(f"{bl.PREFIX}{baseline.name} reads the simulator; it needs its environment "
                           "(use make_policy_env)")
    if baseline.reads == "observation":
        return rules_victim(preset, observation_shape(preset), n_actions(preset),
                            baseline.name.partition("@")[0], baseline.eps or 0.0)  # NAME@EPS: the budget is eps
    return bl.constant_victim(baseline, observation_shape(preset), n_actions(preset), action_names(preset))


def resolve(policy: Any, *, label: str | None = None) -> Policy:
    """The `Policy` of whatever names or holds one: a path (`str` or `Path`) to an SB3 zip,
    model folder or ONNX file, `FILE.py:NAME`, `baseline:NAME`, a `Policy`, a stable-baselines3
    model, a torch `nn.Module` or a numpy callable (observation batch in, scores or actions out).
    The only place that reads what a text means.

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
        return _from_text(str(policy))
    if callable(policy):
        name = label or cast(str, getattr(policy, "__name__", type(policy).__name__))
        return Policy("callable", f"memory:{name}", name, gradients=False, obj=policy)
    raise ZodriveError(f"cannot read a policy from a {type(policy).__name__}: pass a model path, FILE.py:NAME, "
                       "baseline:NAME, an SB3 model, a torch module or a numpy callable")


def _from_text(text: str) -> Policy:
    """The policy a text names: `baseline:NAME`, `FILE.py:NAME` (its file resolved), an ONNX file, or an SB3
    zip or model folder (its model file); a table names it by the baseline, `STEM:NAME`, or the folder's
    name or the file's stem."""
    if not text:
        raise ZodriveError("no policy given: name a model file, FILE.py:NAME or baseline:NAME")
    if bl.is_baseline(text):
        baseline = bl.get_baseline(text)
        ref = f"{bl.PREFIX}{baseline.name}"
        return Policy("baseline", ref, ref, gradients=False, baseline=baseline)
    if is_factory(text):
        file, name = split_factory(text)
        return Policy("factory", f"{file}:{name}", f"{Path(text.rpartition(':')[0]).stem}:{name}", gradients=True)
    path = Path(text)
    label = path.name if path.is_dir() else path.stem
    if is_onnx(text):
        return Policy("onnx", str(model_file(text)), label, gradients=False)
    return Policy("model", str(model_file(text)), label, gradients=True)
