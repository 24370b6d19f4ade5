"""A certified safety shield (`--defense shield[@EPS]`, `close-shield[@EPS]`): the learned
driver acts, the pessimistic rules veto.

Each step the driver proposes its action (argmax of its scores). If the robust rules'
room test at budget EPS (`ObservationRules.safe_actions`, the code `baseline:robust-rules@EPS`
decides with, plus: a lane change only towards a lane that exists wherever the ego may truly
be, and, while the ego may be mid-change, only if the lane beyond is free too, since a second
change aims there) does not accept that action on the observation, the shield takes the robust
rules' own choice instead (IDLE, FASTER or a lane change they find room for; IDLE where their FASTER
fails the shield's FASTER test, which also asks for the safe gap at the speed FASTER reaches); where that is
SLOWER and the own lane is too close even to keep speed, a lane change into a lane free enough
to keep speed in for every true state (`ObservationRules.escapes`); else SLOWER.

Guarantee: the room test at EPS is pessimistic over every true state within L-inf EPS of the
observation (every observed vehicle possibly anywhere its true state may be: closer, closing
faster, in every lane it may overlap). So under any attack of budget <= EPS on the other
vehicles' rows, every action the shielded car takes is one the plain rules' test (eps 0)
accepts on the *true* observation (an escape by a weaker standard, below): no FASTER or IDLE
into an own-lane gap below the rules' safe gap, no lane change into a lane whose gap is too
small or where a listed vehicle is beside. An escape is taken only where that test rejects
even IDLE in the own lane for some true state, and only into a lane where the test accepts IDLE
for every true state (every vehicle that may be there counts, also one that may be in the own
lane too), with the lane beyond it clear enough that no car there is about to cut in. So every
action is accepted by the plain test on the true observation, an escape by the standard of
keeping speed (room >= 0) rather than that of changing lanes (room > the margin). The attacker
can make the car careful, and keep it braking behind a car shown half a lane aside (the constant
brake's failure: the meta-actions never slow it below 20 m/s), but not steer it towards a car.
What it cannot cover: the ego row beyond the lane-existence, mid-change and FASTER tests (an
attacker may shift the ego's perceived lateral position and speed; the tests other than FASTER's
assume an own speed of 25 m/s, and the ego can drive faster), vehicles the observation does not list (behind the ego,
or beyond the nearest four), attacks larger than EPS, and crashes the rules' test does not
foresee (e.g. a vehicle cutting in, or the safe gap at the assumed 25 m/s being too short).

The shield keeps no state between steps: it is a function of the observation, so the defended
system (driver + shield) is itself a memoryless policy and the attacker queries it as one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zodrive.drivers.rules import FASTER, IDLE, SLOWER, ObservationRules
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

VERSION = 6
"""The shield's behaviour, part of every result key that names it: v1 the robust rules' room
test, v2 + a lane change only towards a lane that exists for every ego position, v3 + the lane
beyond checked while the ego may be mid-change, and the escape from an own lane too close to
stay in (the fallback), v4 + an escape minds the lane beyond its target (cut-ins) and leaves out
only a shared vehicle seen nearer the own lane, v5 the sound escape: every vehicle that may be in
its target lane counts, v6 FASTER only where the own lane's safe gap holds at the speed it reaches
(the top target speed; v5 asked for it at 25 m/s, and an attacker's FASTER at 25 m/s behind traffic
slowing below 20 m/s left the ego nowhere to go, seeds 100072 and 100095). Folders made by an
earlier version are not resumed with this one."""

DEFAULT_EPS = 0.02
"""`--defense shield` = `shield@0.02`: a defense is one fixed system (its clean and attacked cells
must describe the same car, so its budget cannot follow the attack's), and 0.02 is the smallest
budget of zodrive's robustness grid, the one at which the pessimistic rules still overtake
(at 0.05 they are the brake)."""


SHIELD_RULES = {"shield": "robust-rules", "close-shield": "close-rules"}
"""Each shield by name and the rules whose room test it applies pessimistically: `shield` asks for
`baseline:rules`' gap (1 s IDM time gap, 15 m margin), `close-shield` for `baseline:close-rules`'
(0.3 s, 5 m), the gap a driver cloned from those rules (`models/dqn-close`) keeps; the
guarantee is the same, relative to that gap."""


def parse_shield(name: str) -> tuple[str, float] | None:
    """The shield's name and budget of `shield[@EPS]` / `close-shield[@EPS]` (None if `name` is
    not a shield); one-line error on a malformed budget."""
    base, at, eps = str(name).partition("@")
    if base not in SHIELD_RULES:
        return None
    if not at:
        return base, DEFAULT_EPS
    try:
        value = float(eps)
    except ValueError:
        value = float("nan")
    if not 0 < value < 1:  # also rejects nan
        raise ZodriveError(f"{name}: {base}@EPS takes a budget EPS in (0, 1) in normalized units, "
                           f"e.g. {base}@0.02")
    return base, value


class Shield:
    """`decide(obs, proposed)`: the proposed meta-actions where the robust rules' room test at
    `eps` accepts them, the robust rules' choice elsewhere. Stateless. `name` (`SHIELD_RULES`):
    whose gap the room test asks for."""

    def __init__(self, preset: dict[str, Any], eps: float = DEFAULT_EPS, name: str = "shield") -> None:
        from zodrive.drivers.rules import named_rules
        from zodrive.envs import action_kind

        if action_kind(preset) != "discrete":
            raise ZodriveError("the shield vetoes meta-actions: it guards discrete policies (preset `discrete`), "
                               "not continuous ones")
        try:
            self.rules: ObservationRules = named_rules(preset, SHIELD_RULES[name], eps)
        except ZodriveError as exc:
            raise ZodriveError(f"the shield reads what the rules read: {exc}") from None
        self.eps = float(eps)

    def guard(self, victim: Victim) -> Victim:
        """The shielded policy (`shielded_victim`)."""
        return shielded_victim(victim, self)

    def safe(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """(B, 5) booleans: the actions safe for every true state within eps of each observation: the
        rules' room test, and for FASTER the own lane's safe gap kept at the speed FASTER reaches
        (the top target speed, from the ego's lowest possible speed; v6)."""
        r = self.rules.rooms(np.asarray(batch), top=True) if rooms is None else rooms
        safe = self.rules.safe_actions(np.asarray(batch), r)
        safe[:, FASTER] &= r["own_top"] >= 0
        return safe

    def decide(self, batch: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        """Final actions (B,): `proposed` where safe, the robust rules' choice where not."""
        batch = np.asarray(batch)
        proposed = np.asarray(proposed, dtype=np.int64)
        r = self.rules.rooms(batch, top=True)
        ok = self.safe(batch, r)[np.arange(len(batch)), proposed]
        if ok.all():
            return proposed
        out = proposed.copy()
        out[~ok] = self.fallback(batch[~ok], _rows_of(r, ~ok))
        return out

    def fallback(self, batch: np.ndarray, rooms: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """The robust rules' choice where the test accepts it and it is not SLOWER (IDLE for a FASTER
        that fails only the FASTER test); else a lane
        change out of an own lane the test rejects even for IDLE, into a lane it accepts IDLE in
        for every true state (`ObservationRules.escapes`: SLOWER never slows the ego below
        20 m/s, so braking behind a slower car is no refuge); else SLOWER."""
        r = self.rules.rooms(batch, top=True) if rooms is None else rooms  # once: the choice, its test, the escape
        safe = self.safe(batch, r)
        rows = np.arange(len(batch))
        act = self.rules.actions(batch, r)
        act = np.where((act == FASTER) & ~safe[:, FASTER] & safe[:, IDLE], IDLE, act)  # keep speed, not faster
        ok = safe[rows, act] & (act != SLOWER)
        escape = self.rules.escapes(batch, r)
        return np.where(ok, act, np.where(escape >= 0, escape, SLOWER))

    def outputs(self, batch: np.ndarray, scores: np.ndarray) -> np.ndarray:
        """The defended system's scores (B, 5) given the driver's (B, 5): the driver's scores on
        the actions the shield accepts; unsafe ones shifted below every score of the row (order
        among them kept); where the driver's choice is vetoed, the rules' choice lifted to the
        row's max + 1. The argmax is the shielded decision."""
        batch = np.asarray(batch)
        scores = np.asarray(scores, dtype=np.float32)
        r = self.rules.rooms(batch, top=True)  # every query of every attack step goes through here: computed once
        safe = self.safe(batch, r)
        rows = np.arange(len(scores))
        proposed = scores.argmax(axis=-1)
        hi, lo = scores.max(axis=-1, keepdims=True), scores.min(axis=-1, keepdims=True)
        out = np.where(safe, scores, scores - (hi - lo) - 1.0).astype(np.float32)
        vetoed = ~safe[rows, proposed]
        if vetoed.any():
            out[rows[vetoed], self.fallback(batch[vetoed], _rows_of(r, vetoed))] = hi[vetoed, 0] + 1.0
        return out


def _rows_of(rooms: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, np.ndarray]:
    """The room test's per-row figures of the selected rows."""
    return {key: value[rows] for key, value in rooms.items()}


def shielded_victim(victim: Victim, shield: Shield) -> Victim:
    """The defended system (driver + shield) as the attacker and the car see it.

    Outputs are scores, not a one-hot decision: the driver's own scores wherever the shield
    lets them stand (`Shield.outputs`), so a score-based attacker learns as much from the
    defended system as from the bare driver, and the shield is not credited with hiding the
    scores (a one-hot output would flatten every score-based objective: obfuscation, not
    safety). Every query sees the shield, so every attack on it is shield-aware: it searches for
    perturbations whose *shielded* decision is its target. White-box access goes through the
    shield by BPDA (as `defended_victim`): the value is the shielded output, the gradient the
    driver network's, so PGD runs against the defended system."""
    if victim.kind != "discrete":
        raise ZodriveError("the shield guards discrete policies (their scores pick a meta-action)")
    shape = victim.obs_shape

    def shielded(batch: np.ndarray, scores: np.ndarray) -> np.ndarray:
        """Shielded outputs for any leading batch axes (the attacks query (B, ...) or (N, M, ...))."""
        out = shield.outputs(batch.reshape(-1, *shape), scores.reshape(-1, scores.shape[-1]))
        return out.reshape(scores.shape)

    def query(batch: np.ndarray) -> np.ndarray:
        batch = np.asarray(batch)
        return shielded(batch, np.asarray(victim.query(batch)))

    differentiable = None
    if victim.differentiable is not None:
        net = victim.differentiable

        def differentiable(x: Any) -> Any:
            raw = net(x)
            value = raw.new_tensor(shielded(x.detach().cpu().numpy(), raw.detach().cpu().numpy()))
            return raw + (value - raw).detach()  # value: shielded; gradient: the driver's network

    return Victim(query=query, kind="discrete", obs_shape=shape, differentiable=differentiable, reads=victim.reads)
