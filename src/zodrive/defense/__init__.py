"""Defenses by name (`--defense NAME`): what stands between the sensor and the policy.

`kinematic`: an observation filter (physics between two decisions). `shield[@EPS]`: a certified
safety shield that vetoes the policy's action when the pessimistic rules at budget EPS do not
find it safe (default EPS 0.02; `zodrive.defense.shield`)."""

from __future__ import annotations

DEFENSES = ("kinematic", "shield")
DEFENSE_NAMES = ("kinematic", "shield", "shield@EPS")  # as the user may write them


def parse_defense(name: str) -> str:
    """The canonical name of a defense (`shield` -> `shield@0.02`), or a one-line error: a
    result is keyed on this name, so one system has one key."""
    from zodrive.defense.shield import canonical_shield, parse_shield
    from zodrive.errors import ZodriveError

    if name == "kinematic":
        return name
    if parse_shield(name) is not None:
        return canonical_shield(name)
    raise ZodriveError(f"unknown defense {name!r} (known: {', '.join(DEFENSE_NAMES)})")
