"""Committed evaluations still match the key today's code builds for the same job, after attack
options were removed (`zodrive.attacks.schema.REMOVED`): a key that records a removed option at
the behaviour left resumes; one that records another value is refused in one line. The removed dqn
recipe options (`zodrive.training.recipes.REMOVED`) are refused in one line too."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any

import pytest

from zodrive.attacks.base import ENGINE_VERSION
from zodrive.attacks.schema import REMOVED
from zodrive.attacks.spec import AttackSpec
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.evaluate import check_same_evaluation, same_evaluation

ROOT = Path(__file__).resolve().parents[1]
EVALUATIONS = [*store.walk(ROOT / "results"), *store.walk(ROOT / "models")]  # in their folders or packed
REFUSED = {
    "results/on-failure/eps0.05-clean": "on_failure",
    "results/on-failure/eps0.1-clean": "on_failure",
    "results/vertex-hold/cells/check-dqn-close-eps0.02": "vertex-check without a picker",
    "results/vertex-hold/cells/check-dqn-close-eps0.05": "vertex-check without a picker",
    "results/vertex-hold/cells/check-dqn-driver-eps0.2": "vertex-check without a picker",
}
"""The committed folders whose attack zodrive can no longer run, and the setting that says so."""


def _attack_key(recorded: dict[str, Any]) -> dict[str, Any]:
    """The attack part of the key today's code writes for the attack `recorded` describes."""
    spec = AttackSpec.from_mapping({k: v for k, v in recorded.items() if k != "engine"}, "recorded attack")
    return {**spec.to_dict(), "engine": ENGINE_VERSION}


def test_every_committed_attack_key_matches_its_attack_today_or_is_refused() -> None:
    attacked = [(p, store.read(p).key or {}) for p in EVALUATIONS]
    attacked = [(p, key) for p, key in attacked if isinstance(key.get("attack"), dict)]
    assert len(attacked) > 400  # the committed attacked cells (491 when the first options were removed)
    refused = {}
    for path, key in attacked:
        if key["attack"].get("engine") != ENGINE_VERSION:
            continue  # made by another attack engine: never resumed
        try:
            wanted = {**key, "attack": _attack_key(key["attack"])}
        except ZodriveError as exc:
            assert "\n" not in str(exc) and "removed from zodrive" in str(exc), exc
            refused[str(path.relative_to(ROOT))] = str(exc)
            continue
        assert same_evaluation(key, wanted), path
    assert {folder: _why(message) for folder, message in refused.items()} == REFUSED


def _why(message: str) -> str:
    """The removed option a refusal names."""
    if "vertex-check needs a picker" in message:
        return "vertex-check without a picker"
    return next(name for name in REMOVED if f"{name}=" in message)


CELLS = [  # (folder, its summary's `zodrive evaluate` command rebuilt with today's parser): one of each kind
    "results/close-rules/attacked/random-search-eps0.02",
    "results/close-rules/attacked/pgd-eps0.02",
    "results/close-rules/attacked/amortized-eps0.02",  # learned:DIR
    "studies/defended-highway-fast/unseen/v6-random-search",  # behind a defense (the shield's current version)
    "results/robustness-100/dqn-driver-random-search-smooth-eps0.05",  # patience, warm start, max_change
    "results/default-vs-saving/ddpg-driver-warm-patience",  # a continuous victim
    "results/learned-adversary/cells/dqn-driver-uniform-noise-eps0.02",
    "results/vertex-hold/cells/ddpg-driver-eps0.05",  # vertex hold
    "results/vertex-hold/picker/cells/check-below0.998-dqn-close-rank-eps0.02-seed1",  # vertex-check:DIR, check_below
]


def _key_today(folder: Path) -> dict[str, Any]:
    """The key of the job that the `zodrive evaluate` command in `folder`'s summary builds with today's parser
    (as JSON reads it back); run from the repository root, since the commands name repository paths."""
    from zodrive.cli import build_parser
    from zodrive.cli.attack import attack_spec_from_args
    from zodrive.cli.common import preset_of
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob
    from zodrive.policies.policy import resolve

    args = build_parser().parse_args(shlex.split(store.summary(folder)["command"])[1:])
    job = EvalJob(model=resolve(args.model).ref, preset=preset_of(args), attack=attack_spec_from_args(args).to_dict(),
                  seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, defense=args.defense)
    return json.loads(json.dumps(job.key()))


@pytest.mark.parametrize("cell", CELLS)
def test_a_committed_cell_matches_the_key_its_command_builds_today(cell: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """What `zodrive evaluate` checks before it resumes a folder: the key of the job its command builds."""
    monkeypatch.chdir(ROOT)  # the commands name repository paths
    folder = ROOT / cell
    on_disk = store.read(folder).key
    assert same_evaluation(on_disk, _key_today(folder))


def test_a_cell_of_an_earlier_defense_version_differs_from_todays_key_in_that_version_alone(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A cell made behind shield v5: its command today builds the same key but for the defense's version, so
    `zodrive evaluate` refuses to resume it with the current shield (never mixes two systems' episodes)."""
    from zodrive.defense import defense_version

    monkeypatch.chdir(ROOT)
    folder = ROOT / "results/close-rules/attacked/v5-shield@0.02-pgd-eps0.02"
    on_disk, today = store.read(folder).key, _key_today(folder)
    assert on_disk["defense_version"] == 5 and today["defense_version"] == defense_version("shield") != 5
    assert not same_evaluation(on_disk, today)
    assert same_evaluation({**on_disk, "defense_version": today["defense_version"]}, today)


def test_a_removed_option_at_the_behaviour_left_resumes_and_at_another_value_is_refused(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Checked on a stand-in removed option (the mechanism does not depend on which options are removed)."""
    from zodrive.attacks import schema

    monkeypatch.setitem(schema.REMOVED, "gone", ("kept", "results/somewhere/"))
    wanted = {"model": "m", "attack": {**AttackSpec(eps=0.05).to_dict(), "engine": ENGINE_VERSION}, "seed": 1}
    assert same_evaluation({**wanted, "attack": {**wanted["attack"], "gone": "kept"}}, wanted)
    stale = {**wanted, "attack": {**wanted["attack"], "gone": "other"}}
    assert not same_evaluation(stale, wanted)
    with pytest.raises(ZodriveError, match=r"gone=other \(its measurement: results/somewhere/\): removed from zodrive"):
        check_same_evaluation(stale, wanted, tmp_path)
    assert AttackSpec.from_mapping({"attack": "random-search", "gone": "kept"}) == AttackSpec(attack="random-search")
    with pytest.raises(ZodriveError, match="gone=other"):
        AttackSpec.from_mapping({"attack": "random-search", "gone": "other"})


def test_a_committed_adversary_that_records_victim_action_false_still_loads(tmp_path: Path) -> None:
    """`attack-train --victim-action` was removed: every committed adversary.json records it false (what is left)
    and is read; one that records true is refused in one line."""
    from zodrive.attacks.learned import META_FILE, read_meta

    folder = ROOT / "results" / "learned-adversary" / "amortized-dqn-close-eps0.02"
    meta = json.loads((folder / META_FILE).read_text())
    assert meta["victim_action"] is False and read_meta(folder)["eps"] == 0.02
    (tmp_path / META_FILE).write_text(json.dumps({**meta, "victim_action": True}))
    (tmp_path / "model.zip").write_bytes(b"")
    with pytest.raises(ZodriveError, match=r"clean action \(attack-train --victim-action\): removed from zodrive"):
        read_meta(tmp_path)


def test_a_dqn_recipe_that_names_a_removed_option_or_recipe_is_refused_in_one_line(tmp_path: Path, capsys) -> None:
    """Guided exploration, DQfD and fine-tuning the DQN from the clone were removed (issue 45): `guide`, `init`
    and `calibrate` on a dqn recipe (shipped, a file or `--set`) and the four recipes are one-line errors, exit 2;
    the continuous side keeps them (`td3-finetune` loads as it did)."""
    from zodrive.cli import main
    from zodrive.training.recipes import REMOVED_RECIPES, load_recipe, train

    def error(args: list[str]) -> str:
        assert main(["train", "--algo", "dqn", "--out", str(tmp_path / "run"), *args]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("zodrive: error:") and "\n" not in err and "Traceback" not in err
        return err

    for option in ("guide.name=rules", "guide.imitation=1.0", "init=models/dqn-imitation", "calibrate.episodes=30"):
        assert "removed from zodrive for dqn recipes" in error(["--set", option]), option
    recipe = tmp_path / "mine.yaml"
    recipe.write_text("base: dqn-driver\nguide: {name: rules, demonstrations: 60, pretrain_steps: 20000}\n")
    assert "guide (its measurement: results/driver-sweep/" in error(["--recipe", str(recipe)])
    for name in REMOVED_RECIPES:
        assert f"recipe {name!r} was removed from zodrive" in error(["--recipe", name])
    with pytest.raises(ZodriveError, match="removed from zodrive"):  # the Python door too, before any folder is made
        train({**load_recipe("dqn"), "init": "models/dqn-imitation"}, tmp_path / "run", progress_bar=False)
    assert not (tmp_path / "run").exists()
    assert {"init", "calibrate", "guide"} <= set(load_recipe("td3-finetune"))
