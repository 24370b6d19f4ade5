"""Metrics that mean what they say: on-road share per step, path length, n/a instead of nan, and
wording that fits untargeted attacks."""

from __future__ import annotations

import zodrive
from zodrive.evaluation.report import format_summary


def test_path_length_and_on_road_share_are_recorded() -> None:
    result = zodrive.evaluate("baseline:slower", "highway-fast", episodes=1, seed=100000)
    record = result.episodes[0]
    assert record["on_road_share"] == 1.0  # a constant brake stays on the road
    assert record["path_length"] >= record["distance"] > 0  # the path is at least the x-displacement
    assert abs(record["path_length"] - record["mean_speed"] * record["length"]) < 0.25 * record["path_length"]
    text = format_summary(result.summary)
    assert "on road: 100.0% of steps" in text and " path: " in text


def _summary(**attack) -> dict:
    base = {"episodes": 2, "seed": 0, "mean_return": 1.0, "ci95": [0.5, 1.5], "mean_speed": float("nan"),
            "mean_length": 3.0, "attack": "random-search", "norm": "linf", "eps": 0.05, "queries_per_step": 10.0,
            "max_linf": 0.05, "attack_config": {}}
    return {**base, **attack}


def test_a_full_base_rate_says_n_a_and_untargeted_runs_say_what_they_measure() -> None:
    full = format_summary(_summary(target="FASTER", attack_success_rate=float("nan"), target_base_rate=1.0))
    assert "nan" not in full and "n/a (no step left to attack: the clean policy already took the target" in full
    untargeted = format_summary(_summary(target="none", attack_success_rate=0.25, target_base_rate=0.0))
    assert "25.0% of steps changed the policy's action" in untargeted and "missed the target" not in untargeted
