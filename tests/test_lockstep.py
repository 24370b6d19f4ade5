"""Episodes run side by side (`--envs`) give, record for record and step for step, what the
same episodes give one at a time, for every attack (each row its own random stream, budgets
and carried perturbation; no row's queries batched where that would change their outputs),
including an environment that starts a waiting episode and one that is dropped."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zodrive.attacks.spec import load_attack
from zodrive.config import available, models_dir
from zodrive.envs import load_preset
from zodrive.evaluation.evaluate import EvalJob, evaluate

STEPS = 12  # per episode: short episodes, every per-step path


def _records(job: EvalJob, envs: int, out: Path) -> tuple[list[dict], list[dict]]:
    evaluate(job, 3, out, envs=envs, progress=False)  # 3 episodes on 2 environments: one is refilled, one dropped
    read = lambda name: sorted((json.loads(line) for line in (out / name).read_text().splitlines()),  # noqa: E731
                               key=lambda r: (r["episode"], r.get("step", 0)))
    steps = [{k: v for k, v in s.items() if k != "wall_time"} for s in read("steps.jsonl")]
    return read("episodes.jsonl"), steps


def _job(model: str, preset: str, attack: str, *overrides: str) -> EvalJob:
    defense = next((o.split("=", 1)[1] for o in overrides if o.startswith("defense=")), None)
    spec = load_attack(attack, [o for o in overrides if not o.startswith("defense=")])
    return EvalJob(model=str(models_dir() / model / "model.zip"), preset={**load_preset(preset), "max_episode_steps": STEPS},
                   attack=spec.to_dict(), defense=defense)


CASES = [("dqn-driver", "discrete", name) for name in available("attacks")] + [
    ("dqn-driver", "discrete", "zo-signsgd", "warm_start=true", "patience=3"),
    ("dqn-driver", "discrete", "random-search", "query_budget=30"),
    ("ddpg-driver", "continuous", "zo-signsgd"),
    ("ddpg-driver", "continuous", "random-search-smooth"),
    ("ddpg-driver", "continuous", "pgd", "norm=l2", "eps=0.3"),
    ("dqn-driver", "discrete", "random-search", "eps=0.05", "defense=shield@0.05"),  # a stateless defense
    ("dqn-driver", "discrete", "pgd", "defense=shield@0.02"),
    # stateful defenses: one filter per row, each row's queries through its own (RowFilters)
    ("zoo/highway-fast-dqn/seed-0", "highway-fast", "random-search-smooth", "eps=0.05", "defense=temporal@3"),
    ("dqn-driver", "discrete", "zo-signsgd", "warm_start=true", "defense=kinematic"),
    ("dqn-driver", "discrete", "pgd", "defense=temporal@3"),  # BPDA through the front
    ("ddpg-driver", "continuous", "random-search", "defense=kinematic"),
]


@pytest.mark.integration
@pytest.mark.parametrize("case", CASES, ids=["-".join(c[::2] + c[3:]) for c in CASES])
def test_lockstep_equals_one_episode_at_a_time(case: tuple[str, ...], tmp_path: Path) -> None:
    model, preset, attack, *overrides = case
    job = _job(model, preset, attack, *overrides)
    alone = _records(job, 1, tmp_path / "one")
    together = _records(job, 2, tmp_path / "two")
    assert together == alone
    assert sum(r["queries"] for r in alone[0]) > 0  # the attack ran
