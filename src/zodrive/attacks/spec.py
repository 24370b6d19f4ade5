"""An attack as configured: THE attack schema (`zodrive.attacks.schema`) with its behaviour."""

from __future__ import annotations

import logging
from typing import Any, Sequence

import numpy as np
from pydantic import ValidationError

from zodrive.attacks.victim import Victim
from zodrive.attacks.base import ENGINE_OPTIONS, Attack, GradientEstimateAttack, needs_fixed_target, refuse_unread
from zodrive.attacks.hold import PLAIN_CHECK, VertexCheck
from zodrive.attacks.objectives import Objective, make_objective, target_has_fallback, target_reads_clean
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.registry import ATTACKS, FOLDER_ONLY, KNOWN, attack_class, make_attack
from zodrive.attacks.schema import DEFAULT_FROZEN, AttackOptions, removed_message, removed_settings, without_removed
from zodrive.attacks.threat import ThreatModel
from zodrive.config import load_config
from zodrive.errors import ZodriveError
from zodrive.validation import one_line

log = logging.getLogger(__name__)

LEARNED = "learned"
TRANSFER = "transfer"
FOLDER_ATTACKS = tuple(name for name in (*FOLDER_ONLY, *ATTACKS) if attack_class(name).trained)
"""The attacks that read a trained folder (`NAME:DIR`; `Attack.trained`): the learned adversary's, a picker, a
surrogate."""
PAPER_TARGETS = {"discrete": "FASTER", "continuous": (1.0, 0.5)}
FIELDS = set(AttackOptions.model_fields)


class AttackSpec(AttackOptions):
    """Everything that defines an attack run: the schema's options, typed and range-checked when
    the spec is made (`AttackSpec(eps=0)` is a one-line `ZodriveError`) and immutable after;
    `with_overrides` makes a changed copy."""

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise ZodriveError(one_line(exc, "attack options", FIELDS)) from None
        _known(self)
        _sparse(self)

    @classmethod
    def from_mapping(cls, data: dict[str, Any], context: str = "attack config") -> "AttackSpec":
        """A spec from a mapping (YAML, overrides, a record), typed and range-checked by the schema
        (a boolean must be a boolean, a number a number); `name` and `description` are a config
        file's words about itself. A removed option (`schema.REMOVED`) at the behaviour left is dropped;
        at another value it is refused."""
        if removed_settings(data):
            raise ZodriveError(f"{context}: {removed_message(removed_settings(data))}")
        data = without_removed(data)
        try:
            spec = cls.model_validate({k: v for k, v in data.items() if k not in ("name", "description")})
        except ValidationError as exc:
            raise ZodriveError(one_line(exc, context, FIELDS)) from None
        _known(spec)
        _sparse(spec)
        return spec

    def with_overrides(self, clear: Sequence[str] = (), **changes: Any) -> "AttackSpec":
        """The spec with `changes` (None: unchanged) and the options in `clear` set to None,
        validated as a whole."""
        data = {**self.to_dict(), **{k: v for k, v in changes.items() if v is not None}, **{k: None for k in clear}}
        return AttackSpec.from_mapping(data, "attack options")

    def to_dict(self) -> dict[str, Any]:
        """The options as plain data, in the schema's order (lists for `frozen` and a continuous
        `target`): what run folders record and are keyed on."""
        data = self.model_dump()
        data["frozen"] = list(self.frozen)
        if isinstance(self.target, tuple):
            data["target"] = list(self.target)
        return data

    def resolved_target(self, kind: str, action_names: tuple[str, ...] | None = None) -> Any:
        """The target to aim at; `auto` is the paper's (FASTER, or [1, 0.5] = full throttle and
        steer right), which exists only where the scenario has that action."""
        if self.target not in ("auto", None):
            return self.target
        target = PAPER_TARGETS[kind]
        if action_names is not None:
            fits = target in action_names if kind == "discrete" else tuple(action_names) == ("acceleration", "steering")
            if not fits:
                raise ZodriveError(f"target auto is the paper's {target!r}, which this scenario's actions "
                                   f"({', '.join(action_names)}) do not have: pass --target none, worst or an action")
        return target

    def objective(self, kind: str, n_actions: int, action_names: tuple[str, ...] | None = None,
                  action_bounds: tuple[Any, Any] | None = None) -> Objective:
        """The per-step objective for a victim of this kind (a learned adversary has no per-step
        target: untargeted; its fitted start, `agents.amortized`, asks a search spec for one)."""
        goal = attack_class(self.attack).goal
        return make_objective(kind, self.resolved_target(kind, action_names) if goal else None,
                              loss=self.loss, weight=self.weight, kappa=self.kappa, tol=self.tol,
                              n_actions=n_actions, action_names=action_names, action_bounds=action_bounds)

    def threat(self, features: tuple[str, ...], bounds: tuple[Any, Any], feature_axis: int = -1) -> ThreatModel:
        """The threat model on these features (named along `feature_axis`) in the box `bounds` (two numbers,
        or two flattened per-dimension bounds); the default mask freezes `presence` where the observation has
        such a feature (an unnamed observation has none to freeze)."""
        frozen = self.frozen
        if frozen == DEFAULT_FROZEN and "presence" not in features:
            frozen = ()
        low, high = (float(b) if np.ndim(b) == 0 else tuple(map(float, np.ravel(b))) for b in bounds)
        return ThreatModel(eps=self.eps, norm=self.norm, mode=self.mode, frozen=frozen,
                           features=features, low=low, high=high, feature_axis=feature_axis, vehicles=self.vehicles)

    def _make(self, threat: ThreatModel, load_network: Any = None) -> Attack:
        return make_attack(self.attack, threat, **{name: getattr(self, name) for name in ENGINE_OPTIONS},
                           **{k: v for k, v in (("adversary", self.adversary), ("check_below", self.check_below),
                                                ("load_network", load_network)) if v is not None})

    def check_folder(self, *, model_file: str, preset: dict[str, Any], defense: str | None,
                     defense_version: int | None = None) -> None:
        """Refuse the attack's trained folder (`adversary`; `Attack.trained` says what it holds) where it was
        fitted against another model file, preset or defense: one line saying which."""
        attack_class(self.attack).check_folder(self.adversary, model_file=model_file, preset=preset, defense=defense,
                                               defense_version=defense_version)

    def folder_digest(self) -> str | None:
        """The content digest of the attack's trained folder, which an evaluation's key records (a refitted
        folder is another attack); None without one."""
        return None if self.adversary is None else attack_class(self.attack).folder_digest(self.adversary)

    @property
    def sparse_in_time(self) -> bool:
        """Whether a frequency budget skips steps (`attack_share` below 1, or `when` gap): an episode's
        steps are then decided one by one, by `zodrive.system.Schedule`."""
        return self.attack_share < 1 or self.when != "every"

    def check(self) -> None:
        """Validate the attack's options and budgets without a victim (before any episode runs)."""
        self._check_unread()
        self._check_budgets(self._make(ThreatModel(eps=self.eps, norm=self.norm, mode=self.mode, frozen=())))

    def _check_unread(self) -> None:
        """An option the attack never reads is an error (`Attack.reads`), and so is a goal defined by the
        clean observation for an attack that never queries it (`queries_clean`)."""
        cls = attack_class(self.attack)
        refuse_unread(cls, self.model_dump())
        if self.access == "decision" and not cls.on_decisions:
            raise ZodriveError(decision_refusal(cls))
        if not cls.queries_clean and target_reads_clean(self.target):
            raise ZodriveError(needs_fixed_target(cls.name))
        if "loss" not in cls.reads and target_has_fallback(self.target):
            raise ZodriveError(f"attack {cls.name} reads no loss, so the fallback of target {self.target} would be "
                               "ignored: give the target alone")

    def _check_budgets(self, attack: Attack) -> None:
        one = attack.first_iteration_cost()
        if self.query_budget is not None and 1 <= self.query_budget < one:  # < 1: the oracle says so
            raise ZodriveError(f"query budget {self.query_budget} is below one iteration of {self.attack} "
                               f"({one} queries with these settings): the attack could do nothing")

    def build(
        self, victim: Victim, features: tuple[str, ...], bounds: tuple[float, float], n_actions: int,
        action_names: tuple[str, ...] | None = None, action_bounds: tuple[Any, Any] | None = None,
        load_network: Any = None, feature_axis: int = -1,
    ) -> tuple[Attack, Objective, QueryOracle]:
        """The attack, its objective for this victim, and the oracle that counts queries.

        `features`, `bounds` (the observation box) and `n_actions` describe the preset
        (`zodrive.envs.attack_context`); `action_names` name the discrete actions (targets by
        name) and `action_bounds` the continuous action box (targets inside it); `load_network`
        reads a learned adversary's network (`zodrive.system.build_attacker` passes the safe loader);
        `feature_axis` is the axis the features are named along."""
        self._check_unread()
        threat = self.threat(features, bounds, feature_axis)
        if not np.isfinite(np.asarray(threat.low)).any() and not np.isfinite(np.asarray(threat.high)).any():
            log.warning("the observation box is unbounded (the environment declares none): eps alone bounds the "
                        "perturbation, and a perturbed value may be one the sensor never produces; pass --obs-bounds "
                        "LOW,HIGH if the observations have a range")
        widths = np.asarray(threat.high) - np.asarray(threat.low)
        width, widest = np.min(widths), np.max(widths)
        if self.mode == "budgeted" and self.norm == "linf" and self.eps > widest:
            raise ZodriveError(f"eps={self.eps:g} is more than any observation value can move (the box's widest side "
                               f"is {widest:g} wide): the run would record eps={self.eps:g} while {widest:g} ran; "
                               f"pass eps <= {widest:g}")
        if self.mode == "budgeted" and self.norm == "linf" and self.eps >= width:
            log.warning("eps=%g covers the whole observation box (its narrowest side is %g wide): the budget "
                        "constrains nothing, only the box clips the perturbation", self.eps, width)
        if self.access == "decision" and victim.kind != "discrete":
            raise ZodriveError("access decision changes nothing for a continuous victim (its output is its action, the "
                               "decision, already): drop --access decision")
        if self.when == "gap" and victim.kind != "discrete":
            raise ZodriveError("when gap reads a preference gap over discrete actions; a continuous victim states "
                               "none: use --when every")
        if self.vehicles is not None:
            rows = threat.vehicle_rows(victim.obs_shape)
            if self.vehicles >= rows:
                raise ZodriveError(f"vehicles {self.vehicles} constrains nothing: the observation has {rows} rows; "
                                   "drop --vehicles or give fewer")
        attack = self._make(threat, load_network)
        if victim.decisions_only and isinstance(attack, GradientEstimateAttack):
            log.warning("the policy answers with its decision alone (one-hot), so %s, which follows differences of "
                        "scores, sees a change only where a probe crosses a decision boundary: its success here is a "
                        "lower bound (random-search needs only decisions)", self.attack)
        if self.attack == LEARNED:
            attack.check_mask(threat)  # type: ignore[attr-defined]
        self._check_budgets(attack)
        objective = self.objective(victim.kind, n_actions, action_names, action_bounds)
        attack.check_objective(objective)
        if not attack.black_box and victim.differentiable is None:
            raise ZodriveError(f"{self.attack} is a white-box baseline: it needs a victim with gradients "
                               "(an SB3 model or a torch module, in memory or from FILE.py:NAME), "
                               "not one that only answers queries")
        return attack, objective, QueryOracle(victim, self.query_budget, self.access)


def decision_attacks() -> list[str]:
    """The registered attacks that run on decisions (`Attack.on_decisions`)."""
    return [name for name, cls in ATTACKS.items() if cls.on_decisions]


def decision_refusal(cls: type[Attack]) -> str:
    """Why attack `cls` does not run with `access: decision` (queries return only the action taken), in one line."""
    if cls.name == LEARNED:
        why = "the learned adversary makes no query at attack time, so access changes nothing"
    elif cls.name == TRANSFER:
        why = "transfer crafts on its surrogate and makes no victim query at attack time, so access changes nothing"
    elif not cls.black_box:
        why = "it reads the network's gradient, which a decision-only attacker never sees"
    elif issubclass(cls, GradientEstimateAttack):
        why = ("it follows finite differences of a loss over the outputs, which over one-hot decisions are zero except "
               "where a probe crosses a decision boundary")
    else:
        why = "it reads the victim's scores"
    return (f"attack {cls.name} does not run with access decision ({why}); decision-based attacks: "
            f"{', '.join(decision_attacks())}")


def _sparse(spec: AttackOptions) -> None:
    """The sparse fields' rules that need no victim: `when gap` reads scores and needs its threshold,
    `min_gap` is read by `when gap` alone, and `vehicles` fits neither the drift box of `max_change` nor
    an adversary trained on every row."""
    if spec.when == "gap" and spec.access == "decision":
        raise ZodriveError("when gap reads the victim's scores (its preference gap), which access decision never "
                           "shows: use --when every, or --access score")
    if spec.when == "gap" and spec.min_gap is None:
        raise ZodriveError("when gap attacks the steps whose preference gap is at least --min-gap B: give it")
    if spec.when != "gap" and spec.min_gap is not None:
        raise ZodriveError(f"min_gap is the threshold of --when gap; when {spec.when} never reads it")
    if spec.vehicles is not None and spec.max_change is not None:
        raise ZodriveError("vehicles with max_change: a row set back to clean may leave the drift box around "
                           "the last step's perturbation; give one of them")
    if spec.vehicles is not None and spec.attack == LEARNED:
        raise ZodriveError("attack learned: the adversary was trained to move every row; vehicles would cut "
                           "its perturbation to rows it was not trained for")


def _known(spec: AttackOptions) -> None:
    if spec.attack not in ATTACKS and spec.attack not in FOLDER_ONLY:
        import difflib

        close = difflib.get_close_matches(spec.attack, list(KNOWN), n=1)
        raise ZodriveError(f"unknown attack {spec.attack!r}" + (f"; did you mean {close[0]!r}?" if close else "")
                           + f" (known: {', '.join(KNOWN)})")
    if spec.attack == VertexCheck.name and spec.adversary is None:
        raise ZodriveError(PLAIN_CHECK)


def load_attack(name: str, overrides: list[str] | None = None) -> AttackSpec:
    """An attack spec from `configs/attacks/<name>.yaml` (or a path); registry names work too,
    `learned:DIR` is the adversary trained into DIR (`zodrive attack-train`), `vertex-hold:DIR` and
    `vertex-check:DIR` vertex hold and vertex check with the picker fitted into DIR (`zodrive picker-train`;
    vertex check has no other form), `transfer:DIR` PGD on the surrogate fitted into DIR (`zodrive surrogate-train`)."""
    from zodrive.config import available

    head, colon, folder = name.partition(":")
    if name in FOLDER_ONLY or (colon and head in FOLDER_ATTACKS):
        if colon and not folder:
            raise ZodriveError(f"attack {name!r} names no folder: {head}:DIR")
        data: dict[str, Any] = {"attack": head, "adversary": folder or None}
        for text in overrides or []:
            from zodrive.config import deep_merge, parse_override

            data = deep_merge(data, parse_override(text))
        return AttackSpec.from_mapping(data, f"attack {name!r}")
    if name in ATTACKS and name not in available("attacks"):
        data = {"attack": name}
        for text in overrides or []:
            from zodrive.config import deep_merge, parse_override

            data = deep_merge(data, parse_override(text))
    else:
        data = load_config(name, "attacks", overrides)
        if not data or "attack" not in data:
            raise ZodriveError(f"attack config {name!r} names no attack (an empty or partial file would run the "
                               "default attack): give `attack: NAME`")
    return AttackSpec.from_mapping(data, f"attack config {name!r}")
