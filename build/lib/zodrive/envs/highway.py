"""`zodrive/highway-v0`: highway-env's `HighwayEnv` that also knows the `FastKinematics`
observation type. The simulator is untouched; only the observation factory is extended."""

from __future__ import annotations

from highway_env.envs.highway_env import HighwayEnv

from zodrive.envs.fast_kinematics import FastKinematicObservation

FAST_TYPE = "FastKinematics"


class ZodriveHighwayEnv(HighwayEnv):
    """`highway-v0` with `observation.type: FastKinematics` available."""

    def define_spaces(self) -> None:
        obs_config = self.config["observation"]
        if obs_config.get("type") != FAST_TYPE:
            super().define_spaces()
            return
        # Let highway-env build everything from the stock type, then swap the observer.
        self.config["observation"] = {**obs_config, "type": "Kinematics"}
        try:
            super().define_spaces()
        finally:
            self.config["observation"] = obs_config
        kwargs = {k: v for k, v in obs_config.items() if k != "type"}
        self.observation_type = FastKinematicObservation(self, **kwargs)
        self.observation_space = self.observation_type.space()
