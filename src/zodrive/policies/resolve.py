"""Where a policy drives: the scenario the user named, checked against where the model's files say it
was trained, or, where the user named none, the one they say (`resolve_scenario`).

What a policy is (`Policy`, its kind read once from the text or object given) is `zodrive.policies.policy`'s;
here it is asked, never the text. `load_victim` is a shorthand for scripts: `resolve(model).victim(preset)`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from zodrive.attacks.victim import Victim
from zodrive.envs import differences_from_training, gym_preset, load_preset, preset_for_env
from zodrive.errors import ZodriveError
from zodrive.policies.folders import TrainedWith, trained_in_memory, trained_with
from zodrive.policies.policy import resolve

log = logging.getLogger("zodrive")


def resolve_preset(model: Any, preset: str | None, env_set: list[str] | None = None, env_id: str | None = None,
                   obs_bounds: tuple[float, float] | None = None, *, shifted: bool = False) -> dict[str, Any]:
    """Where `model` drives (`resolve_scenario` without the source)."""
    return resolve_scenario(model, preset, env_set, env_id, obs_bounds, shifted=shifted)[0]


def resolve_scenario(model: Any, preset: str | dict[str, Any] | None, env_set: list[str] | None = None,
                     env_id: str | None = None, obs_bounds: tuple[float, float] | None = None, *,
                     shifted: bool = False) -> tuple[dict[str, Any], str | None]:
    """Where `model` (a `Policy`, or anything `resolve` reads) drives: `preset`, `env_id` (any gymnasium id), or
    where the model's files say it was trained (its run folder, rl-zoo3 / Hugging Face files, `<env id>.zip`,
    or the environment an SB3 model in memory holds); a baseline drives the paper's preset of its kind. A model
    that says nothing is refused, never given a default, and so is a named scenario that differs from what the
    model's files say (another env id, a stated setting with another value) unless `shifted` says the shift is
    meant: a return on a scenario the policy never saw is a wrong number unless asked for. The second value
    says where a scenario the user did not name came from, or that a named one is shifted (starting
    `shifted:`; for `summary.json`), else None."""
    policy = resolve(model)
    name = str(model) if isinstance(model, (str, Path)) else policy.ref  # the user's words, where there are some
    said = (trained_with(Path(policy.ref)) if policy.kind == "model"
            else trained_in_memory(policy.obj) if policy.kind == "sb3" else None)
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
        where = f"{config['name']} differs from where {', '.join(said.said_by)} says {name} was trained"
        if not shifted:
            if not policy.in_memory:
                policy.check(config)  # a model that cannot drive it at all is refused for that first
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
    if policy.kind == "baseline":  # a baseline is zodrive's own: it drives the paper's preset of its kind
        return load_preset(policy.action_kind(), env_set), None
    if policy.in_memory:
        raise ZodriveError(f"{policy.label} holds no environment that says where it was trained: say "
                           "where it drives: scenario='discrete', 'highway-fast', ... (`zodrive env` lists them) or "
                           "env_id='CartPole-v1'")
    if policy.kind == "factory":
        raise ZodriveError(f"{name} is Python code: say where it drives with --preset or --env-id")
    policy.action_kind()  # a damaged or foreign file is refused for what it is first
    raise ZodriveError(f"{name} does not say where it was trained (no run folder, rl-zoo3 or Hugging Face files "
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


def load_victim(model: Any, preset: dict[str, Any], *, trust: bool = False) -> Victim:
    """The black-box victim of `model` (anything `resolve` reads) on `preset`: `resolve(model).victim(preset)`.
    `trust` reads an SB3 zip with SB3's own loader (unpickles: only for files you trust)."""
    return resolve(model).victim(preset, trust=trust)
