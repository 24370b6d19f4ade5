"""What a policy named by text means: a trained model (SB3 zip, run folder, ONNX file), a Python
factory (`FILE.py:NAME`) or `baseline:NAME`.

These readers stand behind `zodrive.policies.policy.resolve`, through which the rest of the
package reads a policy: `policy_kind` picks the default preset, `policy_label` names it in
tables, `policy_ref` is what an evaluation is keyed on, `check_policy` and `load_victim` read it
on a preset. Only `resolve_preset` / `resolve_scenario`, which say where a policy drives when the
user did not, are called from outside `policies/`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from zodrive.attacks.victim import Victim
from zodrive.drivers import baselines as bl
from zodrive.drivers.rules import rules_victim
from zodrive.envs import (action_kind, action_names, differences_from_training, gym_preset, load_preset, n_actions,
                          observation_shape, preset_for_env)
from zodrive.errors import ZodriveError
from zodrive.policies.factory import factory_victim, is_factory, split_factory
from zodrive.policies.folders import TrainedWith, trained_with
from zodrive.policies.loading import check_fits, inspect_model, load_model, load_network, model_file, model_kind
from zodrive.policies.normalize import ObsNormalization, normalized_victim, read_normalization
from zodrive.policies.onnx_policy import is_onnx, onnx_metadata, onnx_victim
from zodrive.policies.victims import network_victim, sb3_victim

log = logging.getLogger("zodrive")


def policy_kind(model: str) -> str:
    """`discrete` or `continuous`: the preset kind the policy drives by default."""
    if bl.is_baseline(model):
        return bl.get_baseline(model).kinds[0]
    if is_factory(model):
        raise ZodriveError(f"{model} is Python code: say where it drives with --preset or --env-id")

    if is_onnx(model):
        return onnx_metadata(Path(model))["kind"]

    return model_kind(model)


def policy_ref(model: str) -> str:
    """What identifies the policy in results: `baseline:NAME`, the model file's path, or
    `FILE.py:NAME` with the file's path resolved."""
    if bl.is_baseline(model):
        return f"{bl.PREFIX}{bl.get_baseline(model).name}"
    if is_factory(model):

        file, name = split_factory(model)
        return f"{file}:{name}"

    return str(model_file(model))


def policy_label(model: str) -> str:
    """A short name for tables: `baseline:NAME`, the run folder's name, the zip's stem, or
    `STEM:NAME` for a Python factory."""
    if bl.is_baseline(model):
        return policy_ref(model)
    if is_factory(model):
        file, _, name = str(model).rpartition(":")
        return f"{Path(file).stem}:{name}"
    path = Path(model)
    return path.name if path.is_dir() else path.stem


def resolve_preset(model: str, preset: str | None, env_set: list[str] | None = None, env_id: str | None = None,
                   obs_bounds: tuple[float, float] | None = None, *, shifted: bool = False) -> dict[str, Any]:
    """Where `model` drives (`resolve_scenario` without the source)."""
    return resolve_scenario(model, preset, env_set, env_id, obs_bounds, shifted=shifted)[0]


def resolve_scenario(model: str, preset: str | dict[str, Any] | None, env_set: list[str] | None = None,
                     env_id: str | None = None, obs_bounds: tuple[float, float] | None = None, *, shifted: bool = False,
                     said: TrainedWith | None = None) -> tuple[dict[str, Any], str | None]:
    """Where `model` drives: `preset`, `env_id` (any gymnasium id), or where the model's files say
    it was trained (`said`, else its run folder, rl-zoo3 / Hugging Face files, `<env id>.zip`); a
    baseline drives the paper's preset of its kind. A model that says nothing is refused, never
    given a default, and so is a named scenario that differs from what the model's files say
    (another env id, a stated setting with another value) unless `shifted` says the shift is meant:
    a return on a scenario the policy never saw is a wrong number unless asked for. The second value
    says where a scenario the user did not name came from, or that a named one is shifted (starting
    `shifted:`; for `summary.json`), else None."""
    if said is None and not (bl.is_baseline(model) or is_factory(model) or is_onnx(model)
                             or model.startswith("memory:")):
        said = _trained_with(model)
    states = said is not None and (said.preset is not None or said.env_id is not None)
    if env_id is not None or preset is not None:
        if env_id is not None and preset is not None:
            raise ZodriveError("--preset and --env-id both say where the policy drives: give one")
        if obs_bounds is not None and env_id is None:
            raise ZodriveError("--obs-bounds applies to --env-id (a preset states its own observation range)")
        if env_id is not None:
            config = gym_preset(env_id, env_set, obs_bounds)
        elif isinstance(preset, dict):
            config = named_preset(preset)
        else:
            assert preset is not None  # one of the two is given
            config = load_preset(preset, env_set)
        why = _not_as_trained(config, said) if states and said is not None else []  # (states: said is not None)
        if not why:  # nothing shifted (a caller refuses a --shifted that shifted no model: it was ignored)
            return config, None
        assert said is not None
        where = f"{config['name']} differs from where {', '.join(said.said_by)} says {model} was trained"
        if not shifted:
            if not model.startswith("memory:"):
                check_policy(model, config)  # a model that cannot drive it at all is refused for that first
            raise ZodriveError(f"{where} ({'; '.join(why)}): drop --preset / --env-id to run it there, or pass "
                               "--shifted to measure it on this scenario anyway")
        return config, f"shifted: {where} ({'; '.join(why)})"
    if obs_bounds is not None:
        raise ZodriveError("--obs-bounds applies to --env-id (a preset states its own observation range)")
    if shifted:
        raise ZodriveError("--shifted applies to a scenario named by --preset or --env-id")
    if said is not None and said.preset is not None:
        log.info("scenario: %s, the preset its run folder records", said.preset)
        return load_preset(said.preset, env_set), f"the preset its run folder records ({', '.join(said.said_by)})"
    if said is not None and said.env_id is not None:
        found = preset_for_env(said.env_id, said.env_kwargs, env_set)
        log.warning("scenario: %s, where %s says the model was trained", found["name"], ", ".join(said.said_by))
        return found, f"where {', '.join(said.said_by)} says the model was trained"
    if bl.is_baseline(model):  # a baseline is zodrive's own: it drives the paper's preset of its kind
        return load_preset(policy_kind(model), env_set), None
    if model.startswith("memory:"):
        raise ZodriveError(f"{model.removeprefix('memory:')} holds no environment that says where it was trained: say "
                           "where it drives: scenario='discrete', 'highway-fast', ... (`zodrive env` lists them) or "
                           "env_id='CartPole-v1'")
    policy_kind(model)  # a damaged or foreign file is refused for what it is first
    raise ZodriveError(f"{model} does not say where it was trained (no run folder, rl-zoo3 or Hugging Face files "
                       "beside it): say where it drives with --preset or --env-id")


def named_preset(config: dict[str, Any]) -> dict[str, Any]:
    """A preset given as a mapping (Python API): checked as a preset file is, and named."""
    from zodrive.envs.presets import validate_preset

    name = config.get("name")
    if not isinstance(name, str) or not name:
        raise ZodriveError("a scenario given as a mapping needs a 'name' (a preset from load_preset has one)")
    validate_preset(config, name)
    return config


def refuse_unused_shift(sources: list[str | None], what: str) -> None:
    """`--shifted` / `shifted=True` that shifted no model was ignored: refused (`sources`: the second values
    of `resolve_scenario` for each model it applied to)."""
    if not any((source or "").startswith("shifted:") for source in sources):
        raise ZodriveError(f"{what}: no model says it was trained elsewhere than this scenario (or it says nothing): "
                           "drop it")


def _not_as_trained(config: dict[str, Any], said: TrainedWith) -> list[str]:
    """How the named scenario `config` differs from where `said` says the model was trained."""
    if said.preset is not None:
        return [] if config["name"] == said.preset else [f"preset {config['name']}, not {said.preset}"]
    assert said.env_id is not None
    return differences_from_training(config, said.env_id, said.env_kwargs)


def _trained_with(model: str) -> TrainedWith:

    return trained_with(model_file(model))


def check_policy(model: str, preset: dict[str, Any], *, attacked: bool = False) -> None:
    """Raise a one-line error if `model` cannot drive `preset` (or be attacked there)."""
    if bl.is_baseline(model):
        baseline = bl.get_baseline(model)
        bl.check_baseline_fits(baseline, preset)
        if attacked and baseline.reads == "simulator":
            raise ZodriveError(f"{bl.PREFIX}{baseline.name} reads the simulator, not the observation: "
                               "an observation attack cannot reach it")
        if attacked and baseline.reads == "nothing":
            raise ZodriveError(f"{bl.PREFIX}{baseline.name} takes one constant action whatever it observes: an "
                               "observation attack cannot change it (evaluate it clean: it is the floor)")
        if baseline.reads == "observation":
            load_victim(model, preset)  # the rules check the observation they are given
        return
    if is_factory(model):
        load_victim(model, preset)  # builds the policy and checks its outputs against the scenario
        return

    file = model_file(model)
    check_fits(onnx_metadata(file) if is_onnx(file) else inspect_model(file), preset, file)


def load_victim(model: str, preset: dict[str, Any], *, trust: bool = False) -> Victim:
    """The black-box victim of an observation-reading policy (a model, a Python factory, or an
    observation-reading or constant baseline). `trust` reads an SB3 zip with SB3's own loader
    (unpickles: only for files you trust)."""
    kind = action_kind(preset)
    if bl.is_baseline(model):
        baseline = bl.get_baseline(model)
        bl.check_baseline_fits(baseline, preset)
        if baseline.reads == "simulator":
            raise ZodriveError(f"{bl.PREFIX}{baseline.name} reads the simulator; it needs its environment "
                               "(use make_policy_env)")
        if baseline.reads == "observation":

            return rules_victim(preset, observation_shape(preset), n_actions(preset),
                                baseline.name.partition("@")[0], baseline.eps or 0.0)  # NAME@EPS: the budget is eps

        return bl.constant_victim(baseline, observation_shape(preset), n_actions(preset), action_names(preset))

    if is_factory(model):

        return factory_victim(model, preset)
    if is_onnx(model):
        return onnx_victim(Path(model), preset)
    if trust:
        victim = sb3_victim(load_model(model, preset, trust=True))
    else:
        network = load_network(model, preset)  # rebuilt from plain data: nothing in the file is unpickled
        victim = network_victim(network.net, kind, network.obs_shape)
    norm = normalization(model)
    return victim if norm is None else normalized_victim(victim, norm)


def normalization(model: str | Path) -> ObsNormalization | None:
    """The VecNormalize statistics a model file was trained with (None: none beside it)."""
    found = trained_with(model_file(model)).normalization
    return read_normalization(found) if found is not None else None
