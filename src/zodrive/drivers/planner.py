"""`baseline:planner`: a look-ahead driver that reads the simulator, the privileged teacher of issue 22.

Why: `baseline:rules` reads the learned agents' observation and scores ~353; a DQN cloned from it
scores the same, and reinforcement learning from that start did not rise (results/finetune). A
teacher above the rules shows what the five meta-actions can reach on this road and gives a
student something better to copy ("learning by cheating": a privileged teacher, a student on
the sensor; Chen et al., CoRL 2019). It is not attackable and no policy of the observation can
equal it (it sees the whole road, behind the ego included): a reference, like IDM + MOBIL.

Each decision: every distinct meta-action is taken in a deep copy of the environment and
followed by `baseline:rules` for the rest of `HORIZON_S` seconds; the summed reward scores it, a
crash scores `CRASH_SCORE` plus the step it came at (later is better). The best score wins; ties
go to the rules' own action, so where looking ahead changes nothing the planner drives like the
rules. Cost: five rollouts of 75 steps per decision (15 Hz), about 0.3-0.5 s on one core after the
pruning below (`benchmarks/` has no claim on it: it is a teacher, not a product path).

On any other highway-env road with meta-actions (merge, roundabout, intersection) there are no
rules to follow: each available meta-action is taken and then IDLE held for the horizon (keep the
target speed and lane), on the whole road (no pruning: these roads hold few vehicles). It plans no
route beyond the horizon; the scenario's own route-following does the steering.

Pruning on the straight highway (exact where it matters): the copy keeps only vehicles within [-`REACH_BEHIND`,
+`REACH_AHEAD`] m of the ego along the road. In 5 s no vehicle closes more than ~75 m on the ego
(speeds 20-30 m/s), and the observation reads at most 200 m ahead, so the rollouts see the same
neighbours; highway-env's cost per step is quadratic in the vehicles.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from zodrive.drivers.rules import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, SLOWER, ObservationRules

HORIZON_S = 5.0       # [s] look-ahead (2 s crashed at 28 m/s on a tuning seed: results/finetune/planner-probe.md)
CRASH_SCORE = -1000.0  # a crash in a rollout, plus the step it came at
REACH_BEHIND = 100.0   # [m] vehicles further behind the ego are dropped from the copies
REACH_AHEAD = 250.0    # [m] ... and further ahead


class LookAheadPlanner:
    """The planner bound to `env` (a discrete straight-highway preset's environment); call it
    for the action at the environment's current state. Deterministic: highway-env's vehicles
    behave deterministically once placed, so a rollout is the future under that action."""

    def __init__(self, env: Any, preset: dict[str, Any], horizon_s: float = HORIZON_S, *,
                 straight: bool = True) -> None:
        """`straight`: the paper's straight highway, where the rules follow each first action and the
        copies are pruned; otherwise IDLE follows on the whole road."""
        self.env = env
        self.rules = ObservationRules(preset) if straight else None
        self.steps = max(1, round(horizon_s * env.unwrapped.config["policy_frequency"]))

    def __call__(self) -> int:
        base = self.env.unwrapped
        idle = base.action_type.actions_indexes["IDLE"]
        if self.rules is None:  # any road: every available action, and IDLE's on a tie
            own, actions = idle, [int(a) for a in base.action_type.get_available_actions()]
        else:  # the straight highway: the actions that differ here, and the rules' own on a tie
            obs = base.observation_type.observe()
            own, actions = int(self.rules.actions(np.asarray(obs, dtype=np.float32)[None])[0]), self.candidates(base)
        scores = {a: self._rollout(base, a) for a in actions}
        own_score = scores.get(own, scores[idle])  # an action with no effect here is IDLE
        return own if own_score >= max(scores.values()) else max(scores, key=lambda a: scores[a])

    @staticmethod
    def candidates(base: Any) -> list[int]:
        """The meta-actions that differ here: a lane change beyond the road's edge, FASTER at the
        top target speed and SLOWER at the bottom one do what IDLE does."""
        ego = base.vehicle
        lanes = len(base.road.network.all_side_lanes(ego.target_lane_index))
        lane = ego.target_lane_index[2]
        out = [IDLE]
        if lane > 0:
            out.append(LANE_LEFT)
        if lane < lanes - 1:
            out.append(LANE_RIGHT)
        index = ego.speed_to_index(ego.target_speed)
        if index < len(ego.target_speeds) - 1:
            out.append(FASTER)
        if index > 0:
            out.append(SLOWER)
        return out

    def _rollout(self, base: Any, action: int) -> float:
        sim = copy.deepcopy(base)
        ego = sim.vehicle
        if self.rules is not None:
            x = ego.position[0]
            sim.road.vehicles = [v for v in sim.road.vehicles
                                 if v is ego or -REACH_BEHIND <= v.position[0] - x <= REACH_AHEAD]
        total = 0.0
        for k in range(self.steps):
            obs, reward, terminated, truncated, info = sim.step(action)
            total += float(reward)
            if info.get("crashed", False):
                return CRASH_SCORE + k
            if terminated or truncated:
                break
            action = (int(self.rules.actions(np.asarray(obs, dtype=np.float32)[None])[0]) if self.rules is not None
                      else sim.action_type.actions_indexes["IDLE"])
        return total
