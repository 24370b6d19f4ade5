"""`baseline:rules`: a hand-written lane-changing driver that reads only the observation.

The same 5x5 Kinematics observation the learned agents get (the ego row absolute, up to four
vehicles ahead relative to it, normalized), turned into a meta-action by fixed rules, with
nothing remembered between steps. It answers two questions: how far does *this observation*
carry a driver that is not learned (the learned DQN and `baseline:idm-mobil`, which reads the
simulator, bracket it), and is a policy that is not a neural network any harder to attack
(it has no scores: an attacker sees only its decision, one-hot).

The rules, per observation (lanes 4 m wide, cars 5 m long):
1. The gap to the nearest vehicle ahead in each lane (own, left, right) and its closing speed;
   the safe gap is IDM's s* = s0 + v T + v dv / (2 sqrt(a b)) at an assumed own speed of
   25 m/s (above 20 m/s the observation does not show it: vx is clipped).
2. Too close in the own lane: change to a neighbouring lane whose gap is safe by a margin and
   where nothing is observed beside the ego (left first, to overtake), else SLOWER.
3. Free road: move right if the right lane is free far ahead (the reward pays for it), else
   FASTER if the own lane is free by a margin, else IDLE.
Lane changes start only near a lane centre and with no lateral motion, so that one change is
not asked for twice. Vehicles behind are not in the observation, so a lane change is blind to
them, as it is for the learned agents.

`baseline:robust-rules@EPS` (`eps` > 0) is the same driver made pessimistic for an attacker of
L-inf budget `eps` (normalized units, i.e. eps times each feature's range: at 0.05 and this
preset's ranges, 5 m in x and y and 1 m/s in vx and vy): every observed vehicle counts as
possibly anywhere its true state may be, i.e. in every lane within `W/2 + eps y_range` of its
observed offset, `eps x_range` closer, and closing `eps vx_range` faster, and each lane's room
is the smallest over those vehicles. Since an observed value is within eps of the true one,
the rules never see a gap larger or a closing speed smaller than the true ones: an attacker
can only make them more careful (slower, fewer lane changes), never make them accelerate
into, or change into, a gap the plain rules on the true observation would not accept. What
this cannot cover: the ego row (an attacker can shift the ego's perceived lateral position
and speed, hence its lane index and the "centred, not moving sideways" test, which can let a
lane change be asked for during another), and vehicles the observation does not list (behind,
or beyond the four nearest), which the plain rules do not see either.
"""

from __future__ import annotations


from typing import Any

import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = range(5)
LANE_WIDTH = 4.0       # [m] highway-env's StraightLane default
CAR_LENGTH = 5.0       # [m]
ASSUMED_SPEED = 25.0   # [m/s] own speed for the safe gap (the observation clips vx at its range)
S0, HEADWAY = 10.0, 1.0          # [m], [s] highway-env's IDM distance and time gap
A_MAX, B_COMF = 3.0, 5.0         # [m/s^2] IDM's comfort acceleration and deceleration
MARGIN = 15.0          # [m] extra gap asked of a lane before moving into it or speeding up
CLOSE_HEADWAY, CLOSE_MARGIN = 0.3, 5.0  # [s], [m] `baseline:close-rules`: the same rules following closer,
# tuned for return on seeds 50000-50019 (347.39 -> 375.56) and checked on 70000-70019 (356.18 -> 374.82)
# (results/close-rules/README.md)
BESIDE = 8.0           # [m] |dx| within which a vehicle beside the ego blocks a lane change
OFFSETS = np.array([0, -1, 1, -2, 2])  # the lanes `rooms` measures, from the ego's: own, left, right, and beyond each
MID_CHANGE_VY = 0.9    # [m/s] |lateral speed| from which the ego may be in the first half of a lane change
"""highway-env's lane change moves the ego sideways at >= 1.0 m/s until it crosses into the
target lane (tests/test_slow_shield.py measures it on the real env); a second LANE_RIGHT then
aims one lane beyond the target, i.e. two lanes from where the ego is."""


def top_speed(preset: dict[str, Any]) -> float:
    """[m/s] The fastest speed the meta-actions track: the preset's `target_speeds`, else highway-env's
    (`MDPVehicle.DEFAULT_TARGET_SPEEDS`, 20-30 m/s): where FASTER takes the ego."""
    speeds = (preset.get("highway") or {}).get("action", {}).get("target_speeds")
    if speeds is None:
        from highway_env.vehicle.controller import MDPVehicle

        speeds = MDPVehicle.DEFAULT_TARGET_SPEEDS
    return float(np.max(speeds))


def desired_gap(speed: Any, closing: Any, headway: float = HEADWAY) -> Any:
    """IDM's desired gap s* = s0 + v T + v dv / (2 sqrt(a b)) [m] at own speed `speed`, closing
    speed `closing` [m/s] and time headway T = `headway` [s]: the rules' safe gap and the
    continuous rules' following law."""
    return S0 + speed * headway + speed * closing / (2 * np.sqrt(A_MAX * B_COMF))


class ObservationRules:
    """Vectorized rules: `actions(obs)` maps observations (B, V, 5) to meta-actions (B,)."""

    def __init__(self, preset: dict[str, Any], eps: float = 0.0, still_vy: float = 0.3, *,
                 headway: float = HEADWAY, margin: float = MARGIN) -> None:
        """`still_vy` [m/s]: the largest |lateral speed| at which the ego counts as centred (a
        lane change may start); the continuous rules widen it (`ContinuousRules`). `headway` [s]
        (IDM's time gap in the safe gap) and `margin` [m] (the room asked beyond it before
        speeding up or changing lanes): the defaults are `baseline:rules`'s, CLOSE_HEADWAY and
        CLOSE_MARGIN `baseline:close-rules`'s."""
        from zodrive.envs import scenario

        env = scenario(preset)  # the observation as the environment builds it: highway-env's defaults filled in
        if env.features != ("presence", "x", "y", "vx", "vy") or not env.relative or not env.normalized:
            raise ZodriveError("baseline:rules reads the relative, normalized Kinematics observation "
                               "(features presence, x, y, vx, vy)")
        ranges = env.feature_ranges
        self.scale = np.array([1.0, ranges["x"][1], ranges["y"][1], ranges["vx"][1], ranges["vy"][1]],
                              dtype=np.float64)
        self.lanes = int(env.lanes or 4)
        self.eps = float(eps)
        self.still_vy = float(still_vy)
        self.headway, self.margin = float(headway), float(margin)
        self.slack = eps * self.scale  # [physical units] how far each observed feature may be from the truth
        self.top_speed = top_speed(preset)

    def rooms(self, batch: np.ndarray, *, top: bool = False) -> dict[str, np.ndarray]:
        """Per observation (B, V, 5): each lane's room ahead beyond the safe gap [m] (own, left,
        right and the lanes beyond those; -inf where the lane does not exist), whether a vehicle
        may be beside the ego there, whether the ego is centred and whether it may be
        mid-change; with `top`, also `own_top`, the own lane's room at the top target speed, which
        FASTER reaches (the shield's FASTER test; the rules' own choices do not read it, so their
        queries skip it); pessimistic within eps."""
        x = np.asarray(batch, dtype=np.float64) * self.scale  # physical units
        ego, others = x[:, 0], x[:, 1:]
        present = others[:, :, 0] > 0.5
        dx, dy, dvx = others[:, :, 1], others[:, :, 2], others[:, :, 3]
        lane = np.clip(np.rint(ego[:, 2] / LANE_WIDTH), 0, self.lanes - 1)
        centred = (np.abs(ego[:, 2] - lane * LANE_WIDTH) < 0.5) & (np.abs(ego[:, 4]) < self.still_vy)

        _, sx, sy, svx, svy = self.slack
        closing = np.maximum(-dvx + svx, 0.0)
        safe = desired_gap(ASSUMED_SPEED, closing, self.headway)
        slack = dx - sx - CAR_LENGTH - safe   # per vehicle: its gap beyond the safe gap, if ahead

        # (B, lanes, V), the lanes `OFFSETS` from the ego's: the vehicles that may be in each (pessimistic
        # within the budget when eps > 0), those of them ahead, and their gaps beyond the safe gap
        within = present[:, None, :] & (np.abs(dy[:, None, :] - OFFSETS[None, :, None] * LANE_WIDTH)
                                        < LANE_WIDTH / 2 + sy)
        ahead = within & (dx + sx > 0)[:, None, :]
        gaps = np.where(ahead, slack[:, None, :], np.inf)
        if self.eps > 0:  # every vehicle that may be ahead in the lane counts
            value = gaps.min(axis=2)
        else:  # the nearest one, as tuned
            nearest = np.where(ahead, dx[:, None, :], np.inf).argmin(axis=2)
            value = np.take_along_axis(gaps, nearest[:, :, None], axis=2)[:, :, 0]
        beside = (within & (np.abs(dx) < BESIDE + sx)[:, None, :]).any(axis=2)  # (see the module docstring)

        def exists(offset: int) -> np.ndarray:
            return (lane + offset >= 0) & (lane + offset <= self.lanes - 1)

        out: dict[str, np.ndarray] = {"own": np.where(exists(0), value[:, 0], -np.inf)}
        if top:  # the own lane's room at the speed FASTER reaches (the top target speed) from the ego's lowest
            # possible speed: its closing speed on each vehicle grows by the difference
            reach = np.maximum(self.top_speed - np.maximum(ego[:, 3] - svx, 0.0), 0.0)
            safe_top = desired_gap(max(self.top_speed, ASSUMED_SPEED), closing + reach[:, None], self.headway)
            gaps_top = np.where(ahead[:, 0], dx - sx - CAR_LENGTH - safe_top, np.inf)
            own_top = (gaps_top.min(axis=1) if self.eps > 0
                       else np.take_along_axis(gaps_top, nearest[:, :1], axis=1)[:, 0])
            out["own_top"] = np.where(exists(0), own_top, -np.inf)
        for side, sign, near, beyond in (("left", -1, 1, 3), ("right", +1, 2, 4)):
            out[side] = np.where(exists(sign), value[:, near], -np.inf)
            out[f"{side}_blocked"] = beside[:, near] | ~exists(sign)
            out[f"{side}2"], out[f"{side}2_blocked"] = value[:, beyond], beside[:, beyond]
        # the lanes the ego may truly be in, its lateral position being within eps too (the shield's test)
        lane_lo = np.clip(np.rint((ego[:, 2] - sy) / LANE_WIDTH), 0, self.lanes - 1)
        lane_hi = np.clip(np.rint((ego[:, 2] + sy) / LANE_WIDTH), 0, self.lanes - 1)
        out.update(centred=centred, moving=np.abs(ego[:, 4]) + svy >= MID_CHANGE_VY,
                   left_exists=lane_lo - 1 >= 0, right_exists=lane_hi + 1 <= self.lanes - 1)
        return out

    def actions(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        r = self.rooms(batch) if rooms is None else rooms  # `rooms`: this batch's, already computed
        own, left, right, centred = r["own"], r["left"], r["right"], r["centred"]
        left_blocked, right_blocked = r["left_blocked"], r["right_blocked"]
        act = np.full(len(own), IDLE)
        act[own > self.margin] = FASTER
        keep_right = centred & ~right_blocked & (right > self.margin)
        act[keep_right] = LANE_RIGHT
        close = own < 0
        act[close] = SLOWER
        go_left = close & centred & ~left_blocked & (left > self.margin)
        go_right = close & centred & ~right_blocked & (right > self.margin) & ~go_left
        act[go_left], act[go_right] = LANE_LEFT, LANE_RIGHT
        return act

    def safe_actions(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """(B, 5) booleans: the meta-actions these rules' room test accepts on each observation,
        whatever the rules would choose. FASTER: the own lane free by the margin (as the rules ask
        before speeding up); IDLE: the own lane not too close (the rules keep speed there);
        LANE_LEFT / LANE_RIGHT: the target lane exists, nothing may be beside the ego there, and
        its room exceeds the margin (as the rules ask before any change; the "centred" test is left
        out: it decides when to ask, not whether the target lane is free) and, where the ego may
        be in the first half of a lane change (a second change aims one lane further), the same
        of the lane beyond; SLOWER: always.
        With eps > 0 every test is the pessimistic one, so an action accepted on an observation
        is accepted by the same test on every true state within eps of it. The rules' own
        choice is always accepted."""
        r = self.rooms(batch) if rooms is None else rooms  # `rooms`: this batch's, already computed
        safe = np.zeros((len(r["own"]), 5), dtype=bool)
        safe[:, FASTER] = r["own"] > self.margin
        safe[:, IDLE] = r["own"] >= 0
        for side, action in (("left", LANE_LEFT), ("right", LANE_RIGHT)):
            beyond = ~r["moving"] | (~r[f"{side}2_blocked"] & (r[f"{side}2"] > self.margin))
            safe[:, action] = ~r[f"{side}_blocked"] & (r[side] > self.margin) & r[f"{side}_exists"] & beyond
        safe[:, SLOWER] = True
        return safe

    def escapes(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """(B,) the lane change that leaves an own lane the room test rejects even for IDLE, or
        -1: SLOWER cannot always save the ego there (a meta-action never slows it below the
        preset's lowest target speed, 20 m/s, and the car ahead may be slower). A side qualifies
        if it exists wherever the ego may be, the ego is not mid-change, every vehicle that may
        be there leaves room >= 0 (the test IDLE passes) and none may be beside, and so does
        every vehicle that may be in the lane beyond (it may cut in). Every vehicle that may be
        in the target lane counts, also one that may be in the own lane too: at eps 0.02 a car
        seen half a lane aside may truly be in either, and no rule on its seen position tells
        which (v4 left out the one seen nearer the own lane and drove in behind it, seed 100031).
        So an escape never moves towards a car the test would not keep speed behind; an attacker
        who shows the car ahead half a lane aside keeps the ego braking, as the constant brake
        would. The side with more room; -1 where none qualifies or the own lane's room is >= 0."""
        r = self.rooms(batch) if rooms is None else rooms  # `rooms`: this batch's, already computed
        room = {}
        for side in ("left", "right"):
            ok = (r[f"{side}_exists"] & ~r["moving"] & ~r[f"{side}_blocked"] & (r[side] >= 0)
                  & ~r[f"{side}2_blocked"] & (r[f"{side}2"] >= 0))
            room[side] = np.where(ok, r[side], -np.inf)
        pick = np.where(room["right"] >= room["left"], LANE_RIGHT, LANE_LEFT)
        found = np.maximum(room["left"], room["right"]) > -np.inf
        return np.where(found & (r["own"] < 0), pick, -1)


class BrakeEscape(ObservationRules):
    """`baseline:brake-escape`: the constant brake (SLOWER) that leaves its lane only where braking
    cannot keep the gap ahead, to the side `escapes` names. On merge the return pays for a slow
    ego in the right lane (an episode ends past x = 370 m, so a slower ego earns more steps), and
    the constant brake collides where a car merges in ahead slower than SLOWER's 20 m/s; this is
    the brake without those crashes (studies/zoo-recipe)."""

    def actions(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        r = self.rooms(batch) if rooms is None else rooms  # `rooms`: this batch's, already computed
        escape = self.escapes(batch, r)
        return np.where(escape >= 0, escape, SLOWER)


# The continuous rules (`ContinuousRules`): highway-env's own lane-keeping gains (read from its
# ControlledVehicle) and IDM's free-road law; tuned on seeds 50000-50019 only
# (results/rules-continuous/README.md).
MAX_LATERAL_SPEED = 4.0  # [m/s] the lateral speed command's bound (a lane change takes about 1.5 s)
MOVING_VY = 1.0        # [m/s] |vy| from which the ego is taken to be changing lanes (its own changes pass
                       # it within one step); below it the ego counts as centred, so a change may start or
                       # go on: its labels run "start" -> "go on", never "start" -> "back" -> "go on"
FREE_SPEED = 30.0      # [m/s] IDM's desired speed: the top of the reward's speed range
LEAD_WINDOW = 0.75     # [lanes] a vehicle counts as in a lane within this share of a lane width of its centre


class ContinuousRules:
    """`baseline:rules` on a continuous preset: [acceleration, steering] from the observation alone.

    The lane is the discrete rules' choice (`ObservationRules.actions`: a change only from a
    lane centre, to a lane free by a margin), kept without memory: while the ego moves sideways
    (|vy| > `MOVING_VY`) its target is the next lane centre in that direction, so a change once
    begun is finished. Steering follows highway-env's own cascade (lateral position -> lateral
    speed -> heading -> heading rate -> steering angle through the bicycle model), reading the
    heading off vy. Acceleration is IDM's (the same s0, T, a, b as the rules' safe gap) towards
    the nearest vehicle ahead in the current and the target lane, the smaller of the two.
    The ego's speed is the observed one: the observation clips it at its vx range (20 m/s here),
    so above that the driver believes it drives at 20 m/s; on the tuning seeds that reading
    beat assuming 25 or 30 m/s (it keeps shorter gaps and accelerates on free road)."""

    def __init__(self, preset: dict[str, Any]) -> None:
        from highway_env.vehicle.controller import ControlledVehicle

        self.rules = ObservationRules(preset, still_vy=MOVING_VY)
        # [1/s] lateral position error -> lateral speed command; heading error -> heading rate command
        self.kp_lateral, self.kp_heading = ControlledVehicle.KP_LATERAL, ControlledVehicle.KP_HEADING
        action = preset.get("highway", {}).get("action", {})  # highway-env's ContinuousAction defaults below
        self.acc_range = tuple(float(v) for v in action.get("acceleration_range", (-5.0, 5.0)))
        self.steer_range = tuple(float(v) for v in action.get("steering_range", (-np.pi / 4, np.pi / 4)))

    def controls(self, batch: np.ndarray) -> np.ndarray:
        """(B, V, 5) observations -> (B, 2) actions in [-1, 1] (the preset's ranges mapped linearly)."""
        batch = np.asarray(batch, dtype=np.float64)
        x = batch * self.rules.scale
        ego, others = x[:, 0], x[:, 1:]
        y, vy = ego[:, 2], ego[:, 4]
        v = np.maximum(ego[:, 3], 1.0)  # [m/s] as observed (clipped at the vx range); never divide by ~0
        top = self.rules.lanes - 1
        lane = np.clip(np.rint(y / LANE_WIDTH), 0, top)
        choice = self.rules.actions(batch)
        change = np.where(choice == LANE_LEFT, -1, np.where(choice == LANE_RIGHT, 1, 0))
        onward = np.where(vy < 0, np.floor(y / LANE_WIDTH), np.ceil(y / LANE_WIDTH))
        target = np.clip(np.where(np.abs(vy) > MOVING_VY, onward, lane + change), 0, top)

        vy_cmd = np.clip(-self.kp_lateral * (y - target * LANE_WIDTH), -MAX_LATERAL_SPEED, MAX_LATERAL_SPEED)
        heading_cmd = np.arcsin(np.clip(vy_cmd / v, -1, 1))
        heading = np.arcsin(np.clip(vy / v, -1, 1))
        slip = np.arcsin(np.clip(CAR_LENGTH / 2 / v * self.kp_heading * (heading_cmd - heading), -1, 1))
        steering = np.arctan(2 * np.tan(slip))

        acc = np.full(len(x), A_MAX * (1 - (v / FREE_SPEED) ** 4))
        present = others[:, :, 0] > 0.5
        dx, dvx = others[:, :, 1], others[:, :, 3]
        their_y = y[:, None] + others[:, :, 2]
        rows = np.arange(len(x))
        for lane_index in (lane, target):
            in_lane = np.abs(their_y - lane_index[:, None] * LANE_WIDTH) < LEAD_WINDOW * LANE_WIDTH
            inside = present & (dx > 0) & in_lane
            nearest = np.where(inside, dx, np.inf).argmin(axis=1)
            has = inside[rows, nearest]
            gap = np.maximum(dx[rows, nearest] - CAR_LENGTH, 0.1)
            closing = -dvx[rows, nearest]
            desired = np.maximum(desired_gap(v, closing), 0.0)
            follow = A_MAX * (1 - (v / FREE_SPEED) ** 4 - (desired / gap) ** 2)
            acc = np.where(has, np.minimum(acc, follow), acc)

        def normalized(value: np.ndarray, bounds: tuple[float, ...]) -> np.ndarray:  # (low, high)
            low, high = bounds
            return np.clip(2 * (value - low) / (high - low) - 1, -1, 1)

        return np.stack([normalized(acc, self.acc_range), normalized(steering, self.steer_range)], axis=1)


def named_rules(preset: dict[str, Any], name: str, eps: float = 0.0) -> ObservationRules:
    """The discrete rules by their baseline name: `rules`, `robust-rules` (pessimistic for `eps`),
    `close-rules` (following closer) or `brake-escape` (the brake that dodges), e.g. as a victim,
    a teacher or a recipe's guide."""
    if name == "brake-escape":
        return BrakeEscape(preset)
    if name == "close-rules":
        return ObservationRules(preset, eps, headway=CLOSE_HEADWAY, margin=CLOSE_MARGIN)
    if name in ("rules", "robust-rules"):
        return ObservationRules(preset, eps)
    raise ZodriveError(f"unknown rules {name!r} (rules, robust-rules, close-rules, brake-escape)")


def rules_victim(preset: dict[str, Any], obs_shape: tuple[int, ...], n_actions: int, name: str = "rules",
                 eps: float = 0.0) -> Victim:
    """The rules baseline `name` (`named_rules`) as a victim: decisions only (one-hot on discrete
    presets; on continuous ones, where only `rules` drives, the action itself), no scores and no
    gradients."""
    from zodrive.envs import action_kind

    if action_kind(preset) == "continuous":
        if name != "rules":
            raise ZodriveError(f"baseline:{name} drives discrete presets only")
        driver = ContinuousRules(preset)

        def controls(obs: np.ndarray) -> np.ndarray:
            return driver.controls(np.asarray(obs).reshape(len(obs), *obs_shape)).astype(np.float32)

        return Victim(query=controls, kind="continuous", obs_shape=obs_shape, reads="observation")
    rules = named_rules(preset, name, eps)
    eye = np.eye(n_actions, dtype=np.float32)

    def query(obs: np.ndarray) -> np.ndarray:
        return eye[rules.actions(np.asarray(obs).reshape(len(obs), *obs_shape))]

    return Victim(query=query, kind="discrete", obs_shape=obs_shape, reads="observation", decisions_only=True)
