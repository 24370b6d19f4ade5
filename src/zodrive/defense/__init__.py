"""Defenses by name (`--defense NAME`): what stands between the sensor and the policy.

`kinematic`: an observation filter (physics between two decisions); it tracks an episode, so it
wraps the environment. `shield[@EPS]`: a certified safety shield that vetoes the policy's action
when the pessimistic rules at budget EPS do not find it safe (default EPS 0.02;
`zodrive.defense.shield`); `close-shield[@EPS]` the same with `baseline:close-rules`' shorter gap; it keeps no state, so the shielded policy is itself a policy."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from zodrive.errors import ZodriveError

if TYPE_CHECKING:
    from zodrive.defense.kinematic import KinematicFilter
    from zodrive.defense.shield import Shield

DEFENSE_NAMES = ("kinematic", "shield", "shield@EPS", "close-shield", "close-shield@EPS")  # as the user may write them


def parse_defense(name: str) -> str:
    """The canonical name of a defense (`shield` -> `shield@0.02`, `shield@.050` -> `shield@0.05`),
    or a one-line error: a result is keyed on this name, so one system has one key."""
    from zodrive.defense.shield import parse_shield

    if name == "kinematic":
        return name
    shield = parse_shield(name)
    if shield is None:
        raise ZodriveError(f"unknown defense {name!r} (known: {', '.join(DEFENSE_NAMES)})")
    return f"{shield[0]}@{shield[1]:g}"


def keeps_state(name: str) -> bool:
    """Whether the defense tracks an episode (then it wraps the environment and episodes run one
    at a time); a stateless one folds into the policy."""
    return parse_defense(name) == "kinematic"


def defense_version(name: str) -> int | None:
    """The version of the defense's behaviour, recorded in result keys and adversaries, so that
    a folder or an adversary made against an earlier shield is not taken for this one (None:
    unversioned, unchanged since it was built)."""
    from zodrive.defense.shield import VERSION, parse_shield

    return VERSION if parse_shield(parse_defense(name)) is not None else None


def make_defense(name: str, preset: dict[str, Any]) -> KinematicFilter | Shield:
    """A defense by name (one name per idea: `--defense kinematic`, `--defense shield[@EPS]`,
    `--defense close-shield[@EPS]`)."""
    from zodrive.defense.shield import Shield, parse_shield

    shield = parse_shield(name)
    if shield is not None:
        return Shield(preset, shield[1], shield[0])
    if name != "kinematic":
        raise ZodriveError(f"unknown defense {name!r} (known: {', '.join(DEFENSE_NAMES)})")
    from zodrive.defense.kinematic import KinematicFilter

    return KinematicFilter(preset)
