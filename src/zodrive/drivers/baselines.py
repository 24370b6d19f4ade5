"""Built-in baseline policies: the trivial answers every learned agent must beat.

`baseline:slower`, `baseline:idle`, `baseline:faster` (discrete) and `baseline:brake`,
`baseline:accelerate` (continuous) issue one constant action and ignore their input, so no
observation attack can touch them: they are the robustness floor. `baseline:idm-mobil` is a
classical lane-changing driver (IDM for speed, MOBIL for lane changes, highway-env's own models
and constants, target speed 30 m/s) that reads the **simulator**, not the observation: it is
the reference a learned driver should beat, and an observation attack does not apply to it.
`baseline:planner` (`zodrive.drivers.planner`) also reads the simulator: it tries each meta-action
in a copy of it, 5 s ahead, a privileged teacher that shows what the meta-actions can reach.
`baseline:rules` is a hand-written driver that reads the same observation as the learned
agents (`zodrive.drivers.rules`): attackable like them, but it shows the attacker only its decision.
`baseline:robust-rules@EPS` is that driver made pessimistic for an attacker of budget EPS
(default 0.05): it only ever sees gaps as small as they may truly be, so an attack can make it
careful, not reckless (the robustness a defense should be measured against).
`baseline:brake-escape` is the constant brake that changes lanes only where braking cannot keep
the gap ahead (the rule-based row on merge, where the return pays for a slow ego).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Literal

import numpy as np
import torch

from zodrive.attacks.victim import ActionKind, Victim
from zodrive.envs.presets import ACTION_NAMES, CONTINUOUS_NAMES, scenario
from zodrive.errors import ZodriveError

PREFIX = "baseline:"
IDM_TARGET_SPEED = 30.0  # [m/s] the top of the reward's speed range
KEEP_RIGHT_BIAS = 0.3    # [m/s^2] asymmetric MOBIL: moving right needs less gain, left more
SPEED_CHANGE_ACC = 0.5   # [m/s^2] |IDM acceleration| above which a meta-action changes speed


@dataclass(frozen=True)
class Baseline:
    name: str
    kinds: tuple[str, ...]                    # presets it can drive: discrete and/or continuous
    reads: Literal["nothing", "observation", "simulator"]    # what its decisions depend on
    description: str
    label: str                                # short name for tables
    action: Any = None                        # constant action (None: a driver)
    eps: float | None = None                  # budget a robust driver is built for (`NAME@EPS`)


BASELINES: dict[str, Baseline] = {b.name: b for b in (
    Baseline("slower", ("discrete",), "nothing", "always SLOWER: on the paper's preset, 20 m/s",
             "always SLOWER", "SLOWER"),
    Baseline("idle", ("discrete",), "nothing", "always IDLE: keeps its start speed and lane",
             "always IDLE", "IDLE"),
    Baseline("faster", ("discrete",), "nothing", "always FASTER: the DQN attack's target",
             "always FASTER (the attack's target)", "FASTER"),
    Baseline("brake", ("continuous",), "nothing", "always [-1, 0]: full brake, straight",
             "always [-1, 0] (full brake)", (-1.0, 0.0)),
    Baseline("accelerate", ("continuous",), "nothing", "always [1, 0.5]: the DDPG attack's target",
             "always [1, 0.5] (the attack's target)", (1.0, 0.5)),
    Baseline("rules", ("discrete", "continuous"), "observation",
             "hand-written lane-changing rules on the observation (zodrive.drivers.rules; on continuous presets "
             "with a lane-keeping controller and IDM); attackable, decisions only",
             "rules on the observation"),
    Baseline("close-rules", ("discrete",), "observation",
             "the rules following closer (IDM time gap 0.3 s instead of 1 s, 5 m of margin instead of 15 m; "
             "tuned for return on seeds 50000-50019): faster, an imitation teacher for the DQN",
             "rules, following closer"),
    Baseline("robust-rules", ("discrete",), "observation",
             "the rules made pessimistic for an attacker of L-inf budget eps (NAME@EPS, default 0.05): they see "
             "every gap as small as it may truly be", "rules, pessimistic for the attack budget", eps=0.05),
    Baseline("brake-escape", ("discrete",), "observation",
             "always SLOWER, except a lane change where braking cannot keep the gap to the car ahead (the rules' "
             "room test): the brake without its rear-end crashes", "SLOWER, escaping where braking cannot help"),
    Baseline("idm-mobil", ("discrete", "continuous"), "simulator",
             "IDM + MOBIL lane-changing driver (highway-env's models), target 30 m/s; reads the simulator",
             "IDM + MOBIL driver (reads the simulator)"),
    Baseline("planner", ("discrete",), "simulator",
             "look-ahead planner: each meta-action then the rules (straight highway) or IDLE (any other road) for "
             "5 s in a copy of the simulator (zodrive.drivers.planner); reads the simulator, 0.1-0.5 s per decision",
             "look-ahead planner (reads the simulator)"),
)}


def is_baseline(model: str) -> bool:
    return str(model).startswith(PREFIX)


def get_baseline(model: str) -> Baseline:
    """The baseline named `baseline:NAME` (or `baseline:NAME@EPS` for one built for a budget);
    a one-line error lists the known ones."""
    name, _, eps = str(model)[len(PREFIX):].partition("@")
    if name not in BASELINES:
        known = ", ".join(PREFIX + n + ("[@EPS]" if BASELINES[n].eps is not None else "") for n in BASELINES)
        raise ZodriveError(f"unknown baseline {model!r}; known: {known}")
    baseline = BASELINES[name]
    if not eps:
        return baseline
    try:
        value = float(eps)
    except ValueError:
        value = float("nan")
    if baseline.eps is None or not 0 <= value < 1:
        raise ZodriveError(f"{model!r}: only {', '.join(PREFIX + n for n, b in BASELINES.items() if b.eps is not None)}"
                           " take @EPS, a budget in [0, 1)")
    return replace(baseline, name=f"{name}@{eps}", eps=value,
                   label=f"{baseline.label} (eps {eps})")


HIGHWAYS = ("zodrive/highway-v0", "zodrive/highway-fast-v0")  # straight multi-lane highways
RULES_ENVS = (*HIGHWAYS, "zodrive/merge-v1")  # straight roads the observation-reading rules drive
RULES_FEATURES = ("presence", "x", "y", "vx", "vy")


def check_baseline_fits(baseline: Baseline, preset: dict[str, Any]) -> None:
    """Raise a one-line error where the baseline has no meaning: a constant action the scenario
    does not have, the rules off a straight highway, IDM + MOBIL off a highway-env road."""
    from zodrive.envs import scenario

    env = scenario(preset)
    name = f"{PREFIX}{baseline.name}"
    if env.kind not in baseline.kinds:
        raise ZodriveError(f"{name} drives {' or '.join(baseline.kinds)} presets, not a {env.kind} one")
    if env.kind == "discrete" and isinstance(baseline.action, str) and baseline.action not in env.action_names:
        raise ZodriveError(f"{name} always takes {baseline.action}, which preset {preset['name']!r} does not have "
                           f"(its actions: {', '.join(env.action_names)})")
    if env.kind == "continuous" and baseline.action is not None and env.action_names != CONTINUOUS_NAMES:
        raise ZodriveError(f"{name} is an [acceleration, steering] action; preset {preset['name']!r} acts on "
                           f"{', '.join(env.action_names)}")
    if baseline.reads == "observation" and (preset.get("env_id") not in RULES_ENVS or env.features != RULES_FEATURES
                                            or env.action_names not in (ACTION_NAMES, CONTINUOUS_NAMES)):
        kinds = ("its five meta-actions: presets discrete, highway, highway-fast, merge"
                 if baseline.kinds == ("discrete",) else "the five meta-actions or [acceleration, steering]: presets "
                 "discrete, continuous, highway, highway-fast, merge")
        raise ZodriveError(f"{name} reads a straight road's Kinematics observation (presence x y vx vy) and "
                           f"issues {kinds}")
    if baseline.name == "planner":
        if not env.road or env.kind != "discrete" or "IDLE" not in env.action_names:
            raise ZodriveError(f"{name} looks ahead with highway-env's meta-actions (IDLE among them) on a "
                               "highway-env road")
        return
    if baseline.reads == "simulator" and (preset.get("env_id") not in HIGHWAYS
                                          or (env.kind == "discrete" and env.action_names != ACTION_NAMES)
                                          or (env.kind == "continuous" and env.action_names != CONTINUOUS_NAMES)):
        raise ZodriveError(f"{name} drives a straight highway (it plans no route: no merge, exit or turn) with the "
                           "five meta-actions or [acceleration, steering]: presets discrete, continuous, highway, "
                           "highway-fast")


def constant_victim(baseline: Baseline, obs_shape: tuple[int, ...], n_actions: int,
                    action_names: tuple[str, ...] = ACTION_NAMES) -> Victim:
    """A victim that outputs the same thing for every observation (one-hot scores or the action)."""
    kind: ActionKind
    if isinstance(baseline.action, str):
        index = action_names.index(baseline.action)
        out, kind = np.eye(n_actions, dtype=np.float32)[index], "discrete"
    else:
        out, kind = np.asarray(baseline.action, dtype=np.float32), "continuous"
    const = torch.from_numpy(out)

    def query(obs: np.ndarray) -> np.ndarray:
        return np.repeat(out[None], len(obs), axis=0)

    def forward(obs: torch.Tensor) -> torch.Tensor:  # zero gradient: the input is ignored
        flat = obs.reshape(len(obs), -1).float()
        return const.expand(len(obs), -1) + 0.0 * flat.sum(dim=1, keepdim=True)

    return Victim(query=query, kind=kind, obs_shape=obs_shape, differentiable=forward, reads="nothing")


class IdmMobilDriver:
    """IDM + MOBIL on the ego vehicle's true state, issuing the preset's actions.

    Every decision builds a shadow `IDMVehicle` at the ego's state (target 30 m/s) and asks it
    what highway-env's own IDM and MOBIL would do: MOBIL is consulted at most once per
    `LANE_CHANGE_DELAY` (1 s) while no lane change is under way, with the keep-right bias of
    asymmetric MOBIL (the reward pays for the right lane); IDM gives the acceleration towards
    the vehicle ahead in the current (and, while changing, the target) lane. Discrete presets
    get meta-actions (a lane change first, else FASTER/SLOWER when IDM wants to accelerate or
    brake by more than 0.5 m/s^2, else IDLE); continuous presets get [acceleration, steering]
    normalized to the preset's ranges.

    `replan` (for labelling another driver's states, `defense.distill`): where the ego is in a
    lane it neither chose nor started from (another policy drove it there), that lane becomes
    its target, as if it had arrived by its own decision; otherwise it would steer hard back to
    a lane the state does not show. When it drives itself this never happens, so its driving
    is the same with or without it.
    """

    def __init__(self, env, kind: ActionKind, target_speed: float = IDM_TARGET_SPEED, *, replan: bool = False):
        self.env, self.kind, self.target_speed, self.replan = env, kind, target_speed, replan
        self._ego = None
        self._target_lane = self._origin_lane = None
        self._since_decision = 0

    def _config(self) -> dict[str, Any]:
        return self.env.unwrapped.config

    def __call__(self) -> Any:
        from highway_env.vehicle.behavior import IDMVehicle

        ego = self.env.unwrapped.vehicle
        if ego is not self._ego:  # a new episode: the environment made a new ego vehicle
            self._ego, self._target_lane, self._since_decision = ego, ego.lane_index, 10**9
            self._origin_lane = ego.lane_index
        road = ego.road
        if self.kind == "discrete":
            self._target_lane = ego.target_lane_index
        elif self.replan and ego.lane_index not in (self._target_lane, self._origin_lane):
            self._target_lane = self._origin_lane = ego.lane_index
        shadow = IDMVehicle(road, ego.position, heading=ego.heading, speed=ego.speed,
                            target_lane_index=self._target_lane, target_speed=self.target_speed)
        slot = road.vehicles.index(ego)
        road.vehicles[slot] = shadow  # neighbour searches must see the shadow, not the ego
        try:
            lane_change = self._lane_change(shadow, ego)
            front, rear = road.neighbour_vehicles(shadow, shadow.lane_index)
            acc = shadow.acceleration(shadow, front, rear)
            if self._target_lane != shadow.lane_index:
                front, rear = road.neighbour_vehicles(shadow, self._target_lane)
                acc = min(acc, shadow.acceleration(shadow, front, rear))
        finally:
            road.vehicles[slot] = ego
        if self.kind == "discrete":
            return self._meta_action(ego, lane_change, acc)
        steering = shadow.steering_control(self._target_lane)
        acc_range = self._config()["action"].get("acceleration_range", (-5.0, 5.0))
        steer_range = self._config()["action"].get("steering_range", (-np.pi / 4, np.pi / 4))
        return np.clip([np.interp(acc, acc_range, (-1, 1)), np.interp(steering, steer_range, (-1, 1))], -1, 1)

    def _lane_change(self, shadow, ego) -> int:
        """-1 (left), +1 (right) or 0 per MOBIL with a keep-right bias; sets the target lane."""
        self._since_decision += 1
        delay = shadow.LANE_CHANGE_DELAY * self._config()["policy_frequency"]
        if ego.lane_index != self._target_lane or self._since_decision < delay:
            return 0
        self._since_decision = 0
        for lane in ego.road.network.side_lanes(ego.lane_index):
            if not ego.road.network.get_lane(lane).is_reachable_from(ego.position):
                continue
            direction = int(np.sign(lane[2] - ego.lane_index[2]))
            if mobil_gain(shadow, lane) > shadow.LANE_CHANGE_MIN_ACC_GAIN - KEEP_RIGHT_BIAS * direction:
                self._origin_lane, self._target_lane = ego.lane_index, lane
                return direction
        return 0

    @staticmethod
    def _meta_action(ego, lane_change: int, acc: float) -> int:
        if lane_change:
            return 0 if lane_change < 0 else 2  # LANE_LEFT / LANE_RIGHT
        if acc < -SPEED_CHANGE_ACC and ego.target_speed > 20.0:
            return 4  # SLOWER
        if acc > SPEED_CHANGE_ACC and ego.target_speed < IDM_TARGET_SPEED:
            return 3  # FASTER
        return 1  # IDLE


def mobil_gain(vehicle, lane_index) -> float:
    """MOBIL's incentive (Kesting, Treiber & Helbing 2007) for `vehicle` to move to `lane_index`:
    its own acceleration gain plus politeness times its followers' (highway-env's IDM and
    constants); -inf when the new follower would have to brake harder than is safe."""
    road = vehicle.road
    new_front, new_rear = road.neighbour_vehicles(vehicle, lane_index)
    new_rear_a = vehicle.acceleration(ego_vehicle=new_rear, front_vehicle=new_front)
    new_rear_pred_a = vehicle.acceleration(ego_vehicle=new_rear, front_vehicle=vehicle)
    if new_rear_pred_a < -vehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED:
        return -np.inf
    old_front, old_rear = road.neighbour_vehicles(vehicle)
    self_pred_a = vehicle.acceleration(ego_vehicle=vehicle, front_vehicle=new_front)
    if self_pred_a < -vehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED:
        return -np.inf
    self_a = vehicle.acceleration(ego_vehicle=vehicle, front_vehicle=old_front)
    old_rear_a = vehicle.acceleration(ego_vehicle=old_rear, front_vehicle=vehicle)
    old_rear_pred_a = vehicle.acceleration(ego_vehicle=old_rear, front_vehicle=old_front)
    return float(self_pred_a - self_a + vehicle.POLITENESS * (
        new_rear_pred_a - new_rear_a + old_rear_pred_a - old_rear_a))


def simulator_driver(baseline: Baseline, env: Any, preset: dict[str, Any], kind: ActionKind, *,
                     replan: bool = False) -> Callable[[], Any]:
    """The simulator-reading `baseline` bound to `env` (called for the action at its current state)."""
    if baseline.name == "planner":
        from zodrive.drivers.planner import LookAheadPlanner

        straight = preset.get("env_id") in HIGHWAYS and scenario(preset).features == RULES_FEATURES
        return LookAheadPlanner(env, preset, straight=straight)
    return IdmMobilDriver(env, kind, replan=replan)


def driver_victim(driver: Callable[[], Any], kind: ActionKind, obs_shape: tuple[int, ...], n_actions: int) -> Victim:
    """A simulator-reading driver as a `Victim` (its outputs do not depend on the observation)."""

    def query(obs: np.ndarray) -> np.ndarray:
        action = driver()
        out = np.eye(n_actions, dtype=np.float32)[action] if kind == "discrete" else np.asarray(action, np.float32)
        return np.repeat(out[None], len(obs), axis=0)

    return Victim(query=query, kind=kind, obs_shape=obs_shape, reads="simulator")
