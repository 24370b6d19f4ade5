"""One name for "what drives": a trained model (SB3 zip or run folder) or `baseline:NAME`.

Every command that accepts a model goes through here, so a baseline can stand wherever a
model can: `policy_kind` picks the default preset, `policy_label` names it in tables,
`policy_ref` is what an evaluation is keyed on, and `make_policy_env` builds the victim with
its (optionally attacked) environment.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from zodrive.agents import baselines as bl
from zodrive.attacks.victim import Victim
from zodrive.envs import action_kind, n_actions, observation_shape
from zodrive.errors import ZodriveError


def policy_kind(model: str) -> str:
    """`discrete` or `continuous`: the preset kind the policy drives by default."""
    if bl.is_baseline(model):
        return bl.get_baseline(model).kinds[0]
    from zodrive.agents.onnx_policy import is_onnx, onnx_metadata

    if is_onnx(model):
        return onnx_metadata(Path(model))["kind"]
    from zodrive.agents.loading import model_algo
    from zodrive.agents.training import KIND_OF_ALGO

    return KIND_OF_ALGO[model_algo(model)]


def has_gradients(model: str) -> bool:
    """Whether white-box attacks can differentiate the policy (SB3 networks; not baselines or ONNX)."""
    if bl.is_baseline(model):
        return False
    from zodrive.agents.onnx_policy import is_onnx

    return not is_onnx(model)


def policy_ref(model: str) -> str:
    """What identifies the policy in results: `baseline:NAME` or the model file's path."""
    if bl.is_baseline(model):
        return f"{bl.PREFIX}{bl.get_baseline(model).name}"
    from zodrive.agents.loading import model_file

    return str(model_file(model))


def policy_label(model: str) -> str:
    """A short name for tables: `baseline:NAME`, the run folder's name or the zip's stem."""
    if bl.is_baseline(model):
        return policy_ref(model)
    path = Path(model)
    return path.name if path.is_dir() else path.stem


def check_policy(model: str, preset: dict[str, Any], *, attacked: bool = False) -> None:
    """Raise a one-line error if `model` cannot drive `preset` (or be attacked there)."""
    if bl.is_baseline(model):
        baseline = bl.get_baseline(model)
        bl.check_baseline_fits(baseline, action_kind(preset))
        if attacked and baseline.reads == "simulator":
            raise ZodriveError(f"{bl.PREFIX}{baseline.name} reads the simulator, not the observation: "
                               "an observation attack cannot reach it")
        return
    from zodrive.agents.loading import check_fits, inspect_model, model_file
    from zodrive.agents.onnx_policy import is_onnx, onnx_metadata

    file = model_file(model)
    check_fits(onnx_metadata(file) if is_onnx(file) else inspect_model(file), preset, file)


def load_victim(model: str, preset: dict[str, Any]) -> Victim:
    """The black-box victim of an observation-reading policy (a model or an observation-reading or constant baseline)."""
    kind = action_kind(preset)
    if bl.is_baseline(model):
        baseline = bl.get_baseline(model)
        bl.check_baseline_fits(baseline, kind)
        if baseline.reads == "simulator":
            raise ZodriveError(f"{bl.PREFIX}{baseline.name} reads the simulator; it needs its environment "
                               "(use make_policy_env)")
        if baseline.reads == "observation":
            from zodrive.agents.rules import rules_victim

            return rules_victim(preset, observation_shape(preset), n_actions(preset), baseline.eps or 0.0)
        return bl.constant_victim(baseline, observation_shape(preset), n_actions(preset))
    from zodrive.agents.loading import load_network
    from zodrive.agents.onnx_policy import is_onnx, onnx_victim
    from zodrive.agents.victims import network_victim

    if is_onnx(model):
        return onnx_victim(Path(model), preset)
    network = load_network(model, preset)  # rebuilt from plain data: nothing in the file is unpickled
    return network_victim(network.net, kind, network.obs_shape)


def make_policy_env(model: str, preset: dict[str, Any], spec=None, *, render_mode: str | None = None,
                    trace: bool = False, defense: str | None = None) -> tuple[Victim, gym.Env]:
    """The policy's victim and the preset's environment, wrapped in the attack `spec` if given
    and, with `defense`, in the defense between the (attacked) sensor and the policy; the
    attacker then queries the defended system."""
    from zodrive.envs import make_env
    from zodrive.wrappers import make_attacked_env

    if bl.is_baseline(model) and bl.get_baseline(model).reads == "simulator":
        check_policy(model, preset, attacked=spec is not None)
        if defense is not None:
            raise ZodriveError(f"{model} reads the simulator: an observation defense does not apply to it")
        env = make_env(preset, render_mode=render_mode)
        kind = action_kind(preset)
        driver = bl.IdmMobilDriver(env, kind)
        victim = bl.driver_victim(driver, kind, observation_shape(preset), n_actions(preset))
        return victim, env
    victim = load_victim(model, preset)  # checks that the policy fits the preset
    if defense is None:
        return victim, make_attacked_env(preset, victim, spec, render_mode=render_mode, trace=trace)
    from zodrive.defense.kinematic import FilterWrapper, defended_victim, make_defense

    filt = make_defense(defense, preset)
    env = make_attacked_env(preset, defended_victim(victim, filt), spec, render_mode=render_mode, trace=trace)
    return victim, FilterWrapper(env, filt)
