"""Environment presets, the scenarios behind them and the gymnasium factory."""

from zodrive.envs.presets import (
    ACTION_NAMES,
    Scenario,
    action_kind,
    action_names,
    attack_context,
    feature_names,
    gym_preset,
    load_preset,
    make_env,
    n_actions,
    observation_bounds,
    observation_shape,
    preset_names,
    preset_summary,
    scenario,
    scenario_of_env,
)

__all__ = [
    "ACTION_NAMES",
    "Scenario",
    "action_kind",
    "action_names",
    "attack_context",
    "feature_names",
    "gym_preset",
    "load_preset",
    "make_env",
    "n_actions",
    "observation_bounds",
    "observation_shape",
    "preset_names",
    "preset_summary",
    "scenario",
    "scenario_of_env",
]
