"""Environment presets and the highway-env factory."""

from zodrive.envs.presets import (
    ACTION_NAMES,
    action_kind,
    feature_names,
    load_preset,
    make_env,
    observation_shape,
    preset_names,
)

__all__ = [
    "ACTION_NAMES",
    "action_kind",
    "feature_names",
    "load_preset",
    "make_env",
    "observation_shape",
    "preset_names",
]
