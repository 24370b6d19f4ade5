"""Defenses by name (`--defense NAME`): what stands between the sensor and the policy.

Two kinds. A stateless defense is a function of the observation, so the defended policy is itself a
policy (`guard(victim)` returns it) and episodes run side by side: `shield[@EPS]` (a certified safety
shield that vetoes the policy's action when the pessimistic rules at budget EPS do not find it safe;
default EPS 0.02; `zodrive.defense.shield`), `close-shield[@EPS]` (the same with `baseline:close-rules`'
shorter gap) and `smooth@SIGMA` (randomized smoothing: a vote over Gaussian copies;
`zodrive.defense.randomized`). A stateful one tracks an episode, so it wraps the environment (one
filter per episode row when episodes run side by side: `wrappers.RowFilters`): `kinematic` (physics
between two decisions; `zodrive.defense.kinematic`) and `temporal[@K]` (each row the median of its
last K sightings, carried to now; `zodrive.defense.temporal`). A stateful defense is an `EpisodeFilter`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from zodrive.errors import ZodriveError

if TYPE_CHECKING:
    from zodrive.attacks.victim import Victim

DEFENSE_NAMES = ("kinematic", "temporal", "temporal@K", "shield", "shield@EPS", "close-shield", "close-shield@EPS",
                 "smooth@SIGMA")  # as the user may write them


class EpisodeFilter(Protocol):
    """A defense that tracks an episode: `reset(obs)` at its start, `update(obs)` each step (both return
    what the policy receives); `peek(batch)` filters candidates against the current state without
    advancing it (what an attacker of the defended system may query); `state` None between episodes."""

    state: Any

    def reset(self, obs: np.ndarray) -> np.ndarray: ...

    def update(self, obs: np.ndarray) -> np.ndarray: ...

    def peek(self, batch: np.ndarray) -> np.ndarray: ...


class Guard(Protocol):
    """A stateless defense: `guard(victim)` is the defended policy, as the car and the attacker see it."""

    def guard(self, victim: Victim) -> Victim: ...


def parse_defense(name: str) -> str:
    """The canonical name of a defense (`shield` -> `shield@0.02`, `shield@.050` -> `shield@0.05`,
    `temporal` -> `temporal@3`), or a one-line error: a result is keyed on this name, so one system has
    one key."""
    from zodrive.defense.randomized import parse_smooth
    from zodrive.defense.shield import parse_shield
    from zodrive.defense.temporal import parse_temporal

    if name == "kinematic":
        return name
    shield = parse_shield(name)
    if shield is not None:
        return f"{shield[0]}@{shield[1]:g}"
    sigma = parse_smooth(name)
    if sigma is not None:
        return f"smooth@{sigma:g}"
    window = parse_temporal(name)
    if window is not None:
        return f"temporal@{window}"
    raise ZodriveError(f"unknown defense {name!r} (known: {', '.join(DEFENSE_NAMES)})")


def keeps_state(name: str) -> bool:
    """Whether the defense tracks an episode (then it wraps the environment, one filter per episode
    row); a stateless one folds into the policy."""
    return parse_defense(name).partition("@")[0] in ("kinematic", "temporal")


def defense_version(name: str) -> int | None:
    """The version of the defense's behaviour, recorded in result keys and adversaries, so that
    a folder or an adversary made against an earlier one is not taken for this one (None:
    unversioned, unchanged since it was built)."""
    from zodrive.defense import randomized, shield, temporal

    base = parse_defense(name).partition("@")[0]
    return {"shield": shield.VERSION, "close-shield": shield.VERSION, "smooth": randomized.VERSION,
            "temporal": temporal.VERSION}.get(base)


def make_defense(name: str, preset: dict[str, Any]) -> EpisodeFilter | Guard:
    """A defense by name (one name per idea; `DEFENSE_NAMES`), for the preset's observations."""
    from zodrive.defense.randomized import Smoothing, parse_smooth
    from zodrive.defense.shield import Shield, parse_shield
    from zodrive.defense.temporal import TemporalMedian, parse_temporal

    canonical = parse_defense(name)
    shield = parse_shield(canonical)
    if shield is not None:
        return Shield(preset, shield[1], shield[0])
    sigma = parse_smooth(canonical)
    if sigma is not None:
        return Smoothing(preset, sigma)
    window = parse_temporal(canonical)
    if window is not None:
        return TemporalMedian(preset, window)
    from zodrive.defense.kinematic import KinematicFilter

    return KinematicFilter(preset)
