"""Attack objectives: the L1 term of the paper's Eq. 5-8 and the success test.

Every objective maps victim outputs of shape (N, M, k) (N environments, M candidates
each) and per-environment clean outputs (N, k) to losses (N, M) to *minimize*. They are
written in torch so that the white-box baselines can differentiate the same code the
black-box attacks only evaluate. The distortion term L2 = ||x' - x||^2 is added by the
attack loop, which owns the observations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import torch

from zodrive.errors import ZodriveError

DQN_LOSSES = ("margin", "paper")


def _others_max(q: torch.Tensor, index: torch.Tensor | int) -> torch.Tensor:
    """max_{j != index} q[..., j]; `index` (..., 1) broadcasts over the leading axes. A fixed
    action (an int) is cut out by slicing, the cheaper way on the per-query path (a max is
    exact in any order, so both ways give the same values)."""
    if isinstance(index, int) and q.shape[-1] > 1:
        return torch.cat((q[..., :index], q[..., index + 1:]), dim=-1).amax(dim=-1)
    excluded = torch.arange(q.shape[-1]) == index
    return torch.where(excluded, float("-inf"), q).amax(dim=-1)


def _avoid_margin(q: torch.Tensor, avoid: int, kappa: float) -> torch.Tensor:
    """max(q[avoid] - max_{j != avoid} q_j + kappa, 0): zero once another action wins by kappa."""
    return torch.clamp(q[..., avoid] - _others_max(q, avoid) + kappa, min=0.0)


@dataclass(frozen=True)
class Objective:
    """Base: `loss(out, clean) -> (N, M)`, `success(out, clean) -> (N, M)` booleans."""

    weight: float = 1.0  # the paper's constant `a`
    targeted: bool = True
    reads_clean: ClassVar[bool] = False
    """True where `success` depends on the clean outputs (untargeted, the victim's worst action):
    an attack that never queries the clean observation cannot judge it."""
    flat_at_clean: ClassVar[bool] = False
    """True where the loss is stationary at the clean observation (its gradient there is zero), so a
    gradient step from the clean point never moves (`PGD` then steps randomly)."""

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def already(self, clean: torch.Tensor) -> torch.Tensor:
        """(N,) True where the clean output already meets the goal (nothing to attack)."""
        return self.success(clean[:, None], clean)[:, 0]


@dataclass(frozen=True)
class DiscreteTargeted(Objective):
    """Make a discrete victim pick `target` (paper: FASTER = 3).

    `loss="margin"`: C&W-style max(max_{j!=t} Q_j - Q_t + kappa, 0) - zero once the target
    wins by kappa. `loss="paper"`: the literal Eq. 5, a * |Q_t - Q_y| with y the clean
    action, which is minimized by a tie and not by a flip.

    `avoid` (`--target FASTER,not:SLOWER`, margin loss only): where the target is out of reach,
    at least keep the victim off that action. The loss adds `DiscreteAvoid`'s term, which is zero
    once the target wins; success is still the target. Why: on models/dqn-robust at eps 0.05 the
    target is reachable on about 15 % of steps, and on the others braking delays the crash
    (results/learned-adversary).
    """

    target: int = 3
    kind: str = "margin"
    kappa: float = 0.01
    avoid: int | None = None

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        q_t = out[..., self.target]
        if self.kind == "paper":
            y = clean.argmax(dim=-1)[:, None, None].expand(*out.shape[:-1], 1)
            return self.weight * (q_t - out.gather(-1, y).squeeze(-1)).abs()
        loss = torch.clamp(_others_max(out, self.target) - q_t + self.kappa, min=0.0)
        if self.avoid is not None:
            loss = loss + _avoid_margin(out, self.avoid, self.kappa)
        return self.weight * loss

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return out.argmax(dim=-1) == self.target


@dataclass(frozen=True)
class DiscreteUntargeted(Objective):
    """Make a discrete victim pick anything but its clean action (margin loss)."""

    reads_clean: ClassVar[bool] = True

    targeted: bool = False
    kappa: float = 0.01

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        y = clean.argmax(dim=-1)[:, None, None]
        q_y = out.gather(-1, y.expand(*out.shape[:-1], 1)).squeeze(-1)
        return self.weight * torch.clamp(q_y - _others_max(out, y) + self.kappa, min=0.0)

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return out.argmax(dim=-1) != clean.argmax(dim=-1)[:, None]


@dataclass(frozen=True)
class DiscreteAvoid(Objective):
    """Keep a discrete victim from picking `avoid` (`--target not:SLOWER`: do not brake), whatever it
    picks instead. Fixed in advance like a target, so the clean output is never read (vertex hold and
    pickers take it). Which harm hurts more is an empirical question: on models/dqn-robust at eps
    0.05 random search scores lower with FASTER than with not:SLOWER (results/learned-adversary).

    Margin loss: max(Q_avoid - max_{j!=avoid} Q_j + kappa, 0), zero once another action wins by kappa."""

    targeted: bool = False  # no action to drive the victim to (a fitted start has nothing to fit)
    avoid: int = 4
    kappa: float = 0.01

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return self.weight * _avoid_margin(out, self.avoid, self.kappa)

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return out.argmax(dim=-1) != self.avoid


@dataclass(frozen=True)
class DiscreteWorst(Objective):
    """Make a discrete victim pick the action it values least on the clean observation (its
    own "worst action", per step): harm chosen by the victim's values, not fixed in advance.
    Margin loss as `DiscreteTargeted`."""

    reads_clean: ClassVar[bool] = True

    kappa: float = 0.01

    def _target(self, clean: torch.Tensor) -> torch.Tensor:
        return clean.argmin(dim=-1)[:, None, None]

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        t = self._target(clean).expand(*out.shape[:-1], 1)
        q_t = out.gather(-1, t).squeeze(-1)
        return self.weight * torch.clamp(_others_max(out, t) - q_t + self.kappa, min=0.0)

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return out.argmax(dim=-1) == self._target(clean)[..., 0]

    def already(self, clean: torch.Tensor) -> torch.Tensor:
        return torch.zeros(len(clean), dtype=torch.bool)  # argmin != argmax unless all tie


@dataclass(frozen=True)
class ContinuousTargeted(Objective):
    """Drive a continuous victim's action to `target` (paper: [1, 0.5], throttle + right).

    L1 = a * ||pi(x') - target||_2 (the paper's Eq. 6 with the target in place of the
    clean action, as its text describes). Success: every action dimension within `tol`.
    """

    target: tuple[float, ...] = (1.0, 0.5)
    tol: float = 0.2

    def _target(self, out: torch.Tensor) -> torch.Tensor:
        return torch.as_tensor(self.target, dtype=out.dtype)

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return self.weight * torch.linalg.vector_norm(out - self._target(out), dim=-1)

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return (out - self._target(out)).abs().amax(dim=-1) <= self.tol


@dataclass(frozen=True)
class ContinuousUntargeted(Objective):
    """Push a continuous victim's action away from its clean action (Eq. 6, maximized)."""

    reads_clean: ClassVar[bool] = True

    targeted: bool = False
    flat_at_clean: ClassVar[bool] = True  # the distance to the clean action is minimal there
    tol: float = 0.2

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return -self.weight * torch.linalg.vector_norm(out - clean[:, None], dim=-1)

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        return (out - clean[:, None]).abs().amax(dim=-1) >= self.tol


DISCRETE_TARGETS = {"LANE_LEFT": 0, "IDLE": 1, "LANE_RIGHT": 2, "FASTER": 3, "SLOWER": 4}


def _is_untargeted(target: Any) -> bool:
    return target is None or (isinstance(target, str) and target.lower() in ("none", "untargeted"))


def _is_worst(target: Any) -> bool:
    return isinstance(target, str) and target.lower() == "worst"


AVOID = "not:"
"""`--target not:ACTION` (a name or an index): any action but that one (`DiscreteAvoid`)."""
ELSE = ","
"""`--target TARGET,not:ACTION`: the target, else at least not that action (`DiscreteTargeted.avoid`)."""


def _action_index(target: str | int, names: dict[str, int], n_actions: int | None, given: str | None = None) -> int:
    """A discrete action given by name or index, checked against the scenario's actions (`given`: the
    target as written, for the error)."""
    if isinstance(target, str):
        name = target.upper()
        if name.lstrip("-").isdigit():
            index = int(name)
        elif name in names:
            index = names[name]
        else:
            raise ZodriveError(f"unknown target {given or target!r} (known: {', '.join(names)} or an index"
                               f"{'' if given is None else ', after not:'})")
    elif isinstance(target, int) and not isinstance(target, bool):
        index = int(target)
    else:
        raise ZodriveError(f"a discrete victim needs an action target, not {target!r}")
    if not 0 <= index < (n_actions or 5):
        raise ZodriveError(f"target action {index}{'' if given is None else f' ({given!r})'} is out of range "
                           f"0..{(n_actions or 5) - 1}")
    return index


def target_has_fallback(target: Any) -> bool:
    """Whether `target` is written ACTION,not:ACTION: its fallback is a loss term, which an attack that reads no
    loss (vertex hold) would ignore."""
    return isinstance(target, str) and (ELSE + AVOID) in target.lower()


def target_reads_clean(target: Any) -> bool:
    """Whether the objective `make_objective` builds for `target` has `reads_clean` (untargeted or
    the victim's worst action), without a victim: for checks before any episode runs."""
    return _is_untargeted(target) or _is_worst(target)


def make_objective(
    kind: str,
    target: str | int | Sequence[float] | None,
    *,
    loss: str = "margin",
    weight: float = 1.0,
    kappa: float = 0.01,
    tol: float = 0.2,
    n_actions: int | None = None,
    action_names: Sequence[str] | None = None,
    action_bounds: tuple[Any, Any] | None = None,
) -> Objective:
    """Build the objective for a victim kind (`discrete`/`continuous`) and a target.

    `target=None` or `"none"` means untargeted; `"worst"` (discrete) the action the victim
    values least on the clean observation, per step; `"not:ACTION"` (discrete) any action but
    that one; `"ACTION,not:OTHER"` (discrete) that action, else at least not the other. Discrete
    targets are an index or an action name (FASTER; `action_names` name the
    scenario's actions, highway-v0's meta-actions by default); continuous targets a sequence
    like [1, 0.5] inside `action_bounds` (default [-1, 1] per dimension).
    """
    names = {str(n).upper(): i for i, n in enumerate(action_names)} if action_names else DISCRETE_TARGETS
    untargeted, worst = _is_untargeted(target), _is_worst(target)
    if kind == "discrete":
        if untargeted:
            return DiscreteUntargeted(weight=weight, kappa=kappa)
        if worst:
            return DiscreteWorst(weight=weight, kappa=kappa)
        if loss not in DQN_LOSSES:
            raise ZodriveError(f"unknown DQN loss {loss!r} (known: {', '.join(DQN_LOSSES)})")
        given, avoid = target, None
        if isinstance(target, str) and AVOID in target.lower() and loss != "margin":
            raise ZodriveError(f"target {target} (an action to avoid) has only the margin loss, not {loss!r}")
        if isinstance(target, str) and ELSE in target:
            target, _, fallback = target.partition(ELSE)
            if not fallback.lower().startswith(AVOID) or ELSE in fallback or target.lower().startswith(AVOID):
                raise ZodriveError(f"target {given!r}: a discrete victim's target is an action, not:ACTION, or "
                                   "ACTION,not:ACTION (the action, else at least not the other; e.g. "
                                   "FASTER,not:SLOWER)")
            avoid = _action_index(fallback[len(AVOID):], names, n_actions, str(given))  # given: the str split above
        elif isinstance(target, str) and target.lower().startswith(AVOID):  # unsplit: `target` is `given`
            return DiscreteAvoid(weight=weight, avoid=_action_index(target[len(AVOID):], names, n_actions, target),
                                 kappa=kappa)
        index = _action_index(target, names, n_actions)  # type: ignore[arg-type]
        if avoid == index:
            raise ZodriveError(f"target {given!r} avoids the action it aims at")
        return DiscreteTargeted(weight=weight, target=index, kind=loss, kappa=kappa, avoid=avoid)
    if untargeted:
        return ContinuousUntargeted(weight=weight, tol=tol)
    if worst:
        raise ZodriveError("target 'worst' needs action values (a discrete victim); a continuous one has none")
    if isinstance(target, str) and target.lower().startswith(AVOID):
        raise ZodriveError(f"target {target} names a discrete action to avoid; this victim acts continuously")
    if isinstance(target, str):
        try:
            target = [float(v) for v in target.replace("[", "").replace("]", "").split(",")]
        except ValueError as exc:
            raise ZodriveError(f"invalid continuous target {target!r}: expected e.g. '1,0.5'") from exc
    try:
        values = tuple(float(v) for v in target)  # type: ignore[union-attr]
    except TypeError as exc:
        raise ZodriveError(f"a continuous victim needs a target action like [1, 0.5], not {target!r}") from exc
    if n_actions is not None and len(values) != n_actions:
        raise ZodriveError(f"target {list(values)} has {len(values)} dims; the victim has {n_actions}")
    low, high = action_bounds if action_bounds is not None else ((-1.0,) * len(values), (1.0,) * len(values))
    if any(not lo <= v <= hi for v, lo, hi in zip(values, low, high)):
        raise ZodriveError(f"target {list(values)} is outside the action range [{list(low)}, {list(high)}]")
    return ContinuousTargeted(weight=weight, target=values, tol=tol)
