"""THE attack schema: every option of an attack, written once, with its type, range, default and
a one-line description.

`AttackSpec` (`zodrive.attacks.spec`) is this model with its behaviour (build, check, objective,
threat); YAML attack configs, `--attack-set KEY=VALUE` and Python keywords are validated by it;
the command line's attack flags (`zodrive.cli.attack`) are generated from it: flag name from the
field name (`n_directions` -> `--n-directions`, or the field's `flag`), help from the description,
the default shown, the value parsed by the field's type and checked by the field's range.

This module imports pydantic and nothing heavy (no torch): `zodrive --help` reads it.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, Literal, Mapping, Optional, Union

from pydantic import ConfigDict, Field, StrictBool, StrictInt, field_validator

from zodrive.validation import Strict

DEFAULT_MU = 0.005         # smoothing radius of finite differences [normalized units]
DEFAULT_STEP_SIZE = 0.02   # per-iteration step; chosen by measurement (studies/tune-attack/tune_attack.py)
DEFAULT_FROZEN = ("presence",)
MAX_NUMBER = 1e6
"""The largest value of a real option (eps, mu, step, weights): observations are normalized to about [-1, 1],
and 1e300 would overflow float32 into inf and NaN halfway through a run; a bound refuses it at the edge."""
MAX_ITERATIONS = 100_000    # T, patience: 100,000 iterations of one environment step is already days
MAX_DIRECTIONS = 10_000     # q: 10,000 probes of a 35-feature observation on 8 rows are 22 MB a batch
MAX_QUERIES = 10**9         # a query budget per step (10**30 overflowed the int64 counters)


def option(default: Any, description: str, *, flag: str | None = None, off: str | None = None,
           clear: str | None = None, metavar: str | None = None, **bounds: float) -> Any:
    """A field of the schema. `bounds` are pydantic's `gt`, `ge`, `lt`, `le`; the rest say how the
    command line shows it: `flag` when it is not `--NAME` (`--attack` sets `attack` and, as
    `NAME:DIR`, `adversary`); `off` the help of a boolean's `--no-NAME`; `clear` the help of a
    `--no-NAME` that sets an optional option back to none; `metavar` the value's name in --help."""
    cli: dict[str, Any] = {k: v for k, v in (("flag", flag), ("off", off), ("clear", clear), ("metavar", metavar))
                           if v is not None}
    limits: dict[str, Any] = bounds
    return Field(default, description=description, json_schema_extra=cli or None, **limits)


class AttackOptions(Strict):
    """Everything that defines an attack run: types, ranges, defaults and what each option means."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    attack: str = option(
        "zo-signsgd", "the attack: a registry name; on the command line also an attack config (name or YAML), "
        "learned:DIR (an adversary trained by attack-train), vertex-hold:DIR or vertex-check:DIR (a picker fitted by "
        "picker-train), transfer:DIR (a surrogate fitted by surrogate-train)", flag="--attack", metavar="NAME")
    eps: float = option(0.2, "budget radius of the perturbation [normalized units]", gt=0, le=MAX_NUMBER)
    norm: Literal["linf", "l2"] = option("linf", "the norm of the budget ball")
    mode: Literal["budgeted", "paper"] = option(
        "budgeted", "budgeted: projected onto the eps-ball; paper: unconstrained as published (eps only scales the "
        "reported distortion)")
    frozen: tuple[str, ...] = option(DEFAULT_FROZEN, "features the attacker may not touch (none: every feature may "
                                     "change)", metavar="FEATURE")
    vehicles: Optional[StrictInt] = option(
        None, "at most this many vehicle rows of a Kinematics observation perturbed per step (the ego's row counts; "
        "the rows the attack moved most are kept, the others set back to clean); none: every row", ge=1,
        metavar="K")
    steps: StrictInt = option(100, "T, iterations per environment step", ge=1, le=MAX_ITERATIONS, metavar="T")
    n_directions: StrictInt = option(20, "q, random directions per iteration", ge=1, le=MAX_DIRECTIONS, metavar="Q")
    mu: float = option(DEFAULT_MU, "smoothing radius of the finite differences", gt=0, le=MAX_NUMBER)
    step_size: float = option(DEFAULT_STEP_SIZE, "delta, the per-iteration step", gt=0, le=MAX_NUMBER, metavar="DELTA")
    l2_weight: float = option(0.0, "weight of L2 = ||x' - x||^2 in the objective", ge=0, le=MAX_NUMBER, metavar="W")
    target: Union[str, StrictInt, tuple[float, ...]] = option(
        "auto", "FASTER, an action index, '1,0.5', auto (the paper's: FASTER / [1, 0.5]), none (untargeted), worst, "
        "not:ACTION (discrete: any action but that one, e.g. not:SLOWER) or ACTION,not:ACTION (the action, else at "
        "least not the other: FASTER,not:SLOWER)")
    loss: Literal["margin", "paper"] = option(
        "margin", "the objective of a targeted attack on a discrete policy: margin (C&W) or paper (the literal Eq. 5)")
    weight: float = option(1.0, "the paper's constant a in front of L1", gt=0, le=MAX_NUMBER, metavar="A")
    kappa: float = option(0.01, "margin confidence (discrete)", ge=0, le=MAX_NUMBER)
    tol: float = option(0.2, "success tolerance on continuous actions", gt=0, le=MAX_NUMBER)
    early_stop: StrictBool = option(True, "stop a step's iterations once the goal is met",
                                    off="run all T iterations of every step")
    patience: Optional[StrictInt] = option(
        None, "give up a step after N iterations without progress", ge=1, le=MAX_ITERATIONS, metavar="N",
        clear="run every step until its goal is met or T iterations are spent")
    warm_start: StrictBool = option(False, "start each step's search from the previous step's perturbation",
                                    off="start each step's search at the clean observation")
    max_change: Optional[float] = option(
        None, "defense-aware attacker: the perturbation changes by at most this (L-inf) between steps",
        gt=0, le=MAX_NUMBER, metavar="D")
    access: Literal["score", "decision"] = option(
        "score", "what each query returns to the attacker: score (the victim's outputs: Q-values, or a continuous "
        "action) or decision (a discrete victim's action alone, one-hot; only decision-based attacks run on it)")
    attack_share: float = option(
        1.0, "the frequency budget: at most this share of an episode's steps is attacked (at every step, of the steps "
        "so far); the others feed the clean observation", gt=0, le=1, metavar="F")
    when: Literal["every", "gap"] = option(
        "every", "which steps the frequency budget attacks: every (as soon as it allows: every 1/F-th step) or gap "
        "(only where the victim's preference gap, max - min of softmax(scores), is at least --min-gap; Lin et al. "
        "2017; one counted query a step)")
    min_gap: Optional[float] = option(
        None, "with --when gap: the least preference gap (0-1) of a step that is attacked", ge=0, lt=1, metavar="B")
    query_budget: Optional[StrictInt] = option(None, "max queries per environment step; none: no cap",
                                                ge=1, le=MAX_QUERIES, metavar="N")
    seed: StrictInt = option(0, "the attack's random stream", ge=0, flag="--attack-seed", metavar="SEED")
    adversary: Optional[str] = option(
        None, "the trained folder of learned / vertex-hold / vertex-check / transfer (on the command line: --attack "
        "NAME:DIR)",
        flag="--attack")
    check_below: Optional[float] = option(
        None, "vertex-check:DIR: a held vertex the picker rates at least this (0-1) is fed without a check; the saved "
        "queries pay for checks of fresh vertices (at most 1 query per step on average)", ge=0, le=1,
        metavar="R")

    @field_validator("eps", "mu", "step_size", "l2_weight", "weight", "kappa", "tol", "max_change",
                     "check_below", "attack_share", "min_gap", mode="before")
    @classmethod
    def _finite_number(cls, value: Any) -> Any:
        if isinstance(value, bool) or (value is not None and not isinstance(value, numbers.Real)):
            raise ValueError(f"must be a number, not {value!r}")
        if value is not None and not math.isfinite(value):
            raise ValueError(f"must be a finite number, not {value}")
        return float(value) if value is not None else None

    @field_validator("steps", "n_directions", "patience", "query_budget", "seed", "vehicles",
                     mode="before")
    @classmethod
    def _integer(cls, value: Any) -> Any:
        """A numpy integer is an integer (text, booleans and floats are not)."""
        return int(value) if isinstance(value, numbers.Integral) and not isinstance(value, bool) else value

    @field_validator("frozen", mode="before")
    @classmethod
    def _names(cls, value: Any) -> Any:
        if value is None:
            return ()
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ValueError(f"must be a list of feature names, not {value!r}")
        return tuple(value)

    @field_validator("target", mode="before")
    @classmethod
    def _target(cls, value: Any) -> Any:
        if isinstance(value, (list, tuple)):
            if not all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in value):
                raise ValueError(f"a continuous target is a list of numbers, not {list(value)!r}")
            return tuple(float(v) for v in value)
        if isinstance(value, bool) or value is None:
            raise ValueError(f"must be auto, none, worst, an action name or index, or a list, not {value!r}")
        return int(value) if isinstance(value, numbers.Integral) else value


REMOVED: dict[str, tuple[Any, str]] = {
    "on_failure": ("best", "results/on-failure/"),  # clean: 321.77 against best's 70.21 (DQN driver, eps 0.05)
    "timing": (None, "none committed"),  # the strategically timed attack (Lin et al., IJCAI 2017)
    "episode_query_budget": (None, "none committed"),  # a cap on an episode's queries
    "restarts": (0, "results/ceiling/ (per state only)"),  # further runs from random points of the budget set
}
"""Options zodrive no longer has (issue 45: no committed result put them on the front of queries per step
against damage): each one's value that is the behaviour left, and where its measurement lives (`access`,
removed in c645e5d, is an option again since issue 65: decision-only access and a decision-based attack). A record
written while the option existed (an `eval_key.json`, a config) that holds it at that value is the same
attack today; one that holds another value describes an attack zodrive can no longer run."""


def removed_settings(data: Mapping[str, Any]) -> list[str]:
    """The removed options `data` (recorded attack options) sets to a value other than the behaviour left,
    as `NAME=VALUE`."""
    return [f"{name}={data[name]}" for name, (kept, _) in REMOVED.items() if name in data and data[name] != kept]


def without_removed(data: Mapping[str, Any]) -> dict[str, Any]:
    """`data` without the removed options that hold the behaviour left (a removed option at another value
    stays, so that the record differs from every attack zodrive runs today)."""
    return {k: v for k, v in data.items() if k not in REMOVED or v != REMOVED[k][0]}


def removed_message(settings: list[str]) -> str:
    """Why a record or config that sets removed options cannot run, and where their measurements live."""
    where = "; ".join(f"{s} (its measurement: {REMOVED[s.split('=')[0]][1]})" for s in settings)
    return f"{where}: removed from zodrive (docs/attacks.md, section \"Removed options\")"


SIGNS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def bounds_of(name: str) -> dict[str, float]:
    """The range of a field: its `gt`, `ge`, `lt`, `le` bounds."""
    found: dict[str, float] = {}
    for rule in AttackOptions.model_fields[name].metadata:
        for key in ("gt", "ge", "lt", "le"):
            if getattr(rule, key, None) is not None:
                found[key] = getattr(rule, key)
    return found


def range_text(name: str) -> str:
    """A field's range in words: `>= 1`, `> 0`, `in [0, 1)`."""
    rules = bounds_of(name)
    low = next(((k, v) for k, v in rules.items() if k in ("gt", "ge")), None)
    high = next(((k, v) for k, v in rules.items() if k in ("lt", "le")), None)
    if low and high:
        return f"in {'(' if low[0] == 'gt' else '['}{low[1]:g}, {high[1]:g}{')' if high[0] == 'lt' else ']'}"
    if low or high:
        key, value = low or high  # type: ignore[misc]
        return f"{SIGNS[key]} {value:g}"
    return ""
