"""The bench's tracks: threat models of attackers with less than the dense one (issue 65), each benched as a
protocol of its own (`zodrive bench MODEL --scenario S --track NAME`; docs/bench.md, "Tracks").

The dense track is the bench as it was: every feature of every vehicle may move by ε at every step, and
the attacker reads the policy's scores. A track changes the threat model and nothing else: seeds, episodes,
ε grid and per-step query cap are those of the scenario's protocol, so a track's table is read beside the
dense one. Each track is the threat-model fields every attack of the row runs with (`attack_set`, options
of the one attack schema) and, where the dense ensemble cannot run under them, its own ensemble.

This module imports nothing heavy: the command line reads the track names from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

DENSE = "dense"
"""The default track: the threat model of the paper, a ceiling (every row, every step, score access)."""
TRACKS_FOLDER = "tracks"
"""A track's rows live in BOARD/SCENARIO/tracks/TRACK/NAME: never beside the dense rows (BOARD/SCENARIO/NAME),
whose folder names the leaderboard reads as rows; the scenario's brake (BOARD/SCENARIO/brake) serves both."""
RESERVED = ("brake", TRACKS_FOLDER)
"""Folder names in a scenario's folder that are not rows: no row may take them."""


@dataclass(frozen=True)
class Track:
    """What a track changes in its scenario's protocol."""

    attack_set: tuple[str, ...]
    """The threat-model fields of every attack of the row (`KEY=VALUE`, options of the attack schema)."""
    threat: str
    """The threat model in words (docs/bench.md and the leaderboard's heading of the track's table)."""
    black_box: tuple[str, ...] | None = None
    """The track's black-box ensemble (None: the dense protocol's)."""
    white_box: bool = True
    """Whether the row has the white-box PGD column (under the same threat-model fields)."""


TRACKS = {
    "decision": Track(
        ("access=decision",),
        "decision access: every query returns the action the policy takes and nothing else (one-hot), every feature "
        "of every vehicle at every step; ensemble hsja + random-search (the attacks that run on decisions); no "
        "white-box PGD (its column is –: a decision-only attacker reads no gradient)",
        black_box=("hsja", "random-search"), white_box=False),
    "one-object": Track(
        ("vehicles=1",),
        "one object: at most one vehicle row (the ego's counts) moved per step, the other rows exactly as sensed; "
        "score access, every step"),
    "sparse": Track(
        ("attack_share=0.1", "when=every"),
        "10 % of steps: at most a tenth of an episode's steps attacked, every 10th decision (the 10th, 20th, "
        "30th); the others feed the clean observation and make no query; every feature of every vehicle, score "
        "access"),
}
"""Every track but the dense one, by name (`--track NAME`)."""
TRACK_SCENARIOS = ("highway-fast", "merge")
"""The scenarios with tracks: those of the issue's studies (item 5), where the zoo's rows are run on every track."""


def is_dense(track: str | None) -> bool:
    return track in (None, DENSE)


def share_clean(policy: str, preset: str, seed: int, dense: Path, out: Path, counts: tuple[int, int],
                trust: bool = False) -> list[Path]:
    """Start a track row's clean cells (in `out`: the grid's own and `clean/`) from the same policy's dense row
    (`dense`), whose clean cells are the same evaluation: the same model, preset, seeds and episodes, and no
    attack. Copied only where the dense row is finished with the same episode `counts` (attacked, clean) and
    each cell's key is this evaluation's, and only into a cell the track row does not have yet; the evaluation
    then finds its episodes done. Returns the cells copied."""
    import json

    from zodrive.errors import ZodriveError
    from zodrive.evaluation import store
    from zodrive.evaluation.evaluate import EvalJob, same_evaluation
    from zodrive.experiments.compare import clean_cell
    from zodrive.policies.policy import resolve
    from zodrive.policies.resolve import resolve_scenario

    try:
        row = json.loads((dense / "row.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    resolved = resolve(policy)
    if not isinstance(row, dict) or row.get("defense") or row.get("key") != resolved.key() \
            or (row.get("episodes"), row.get("clean_episodes", row.get("episodes"))) != counts:
        return []
    model_preset, _ = resolve_scenario(policy, preset)
    wanted = EvalJob(model=resolved.ref, preset=model_preset, seed=seed, trust=trust).key()
    cell = clean_cell(resolved)  # the same cell in both rows' grids: each a grid of this policy alone
    copied = []
    for sub in ("", "clean") if counts[1] > counts[0] else ("",):
        source, target = cell.folder(dense / sub), cell.folder(out / sub)
        try:
            found = store.read(source)
        except ZodriveError:  # no such cell, or a damaged one: the track row runs its own
            continue
        if found.summary is None or found.key is None or store.exists(target) \
                or not same_evaluation(found.key, json.loads(json.dumps(wanted))):
            continue
        store.copy_for_resume(source, target)  # the summary is made again from the episodes
        copied.append(target)
    return copied


def threat_fields(attack_set: tuple[str, ...]) -> dict[str, Any]:
    """A track's threat-model fields (`Track.attack_set`) as a row records them (`{"vehicles": 1}`)."""
    from zodrive.config import parse_override

    fields: dict[str, Any] = {}
    for text in attack_set:
        fields.update(parse_override(text))
    return fields
