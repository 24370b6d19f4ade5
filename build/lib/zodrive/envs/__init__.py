"""Environment presets and the highway-env factory."""

from zodrive.envs.presets import (
    ACTION_NAMES,
    action_kind,
    attack_context,
    feature_names,
    load_preset,
    make_env,
    n_actions,
    observation_bounds,
    observation_shape,
    preset_names,
)

__all__ = [
    "ACTION_NAMES",
    "action_kind",
    "attack_context",
    "feature_names",
    "load_preset",
    "make_env",
    "n_actions",
    "observation_bounds",
    "observation_shape",
    "preset_names",
]
