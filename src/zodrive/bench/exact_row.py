"""`zodrive certify MODEL --row FOLDER`: a bench row's exact check, `exact.json` beside its `row.json`.

The states: the first `STATES` clean observations of the row's attacked episodes (its protocol's seeds,
driven by the policy itself). At each ε of the row's grid, each state's complete verdict (`evaluation.exact`:
robust, attackable or unknown at `TIME_LIMIT` seconds), and each black-box attack of the row's ensemble at
the protocol's settings, its per-step query cap included, untargeted and each state on its own (as
`certify --attack` runs them). The ensemble misses an exactly attackable state that none of its attacks
changed; white-box PGD is no part of it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from zodrive.bench.bench import BLACK_BOX
from zodrive.bench.exact_board import EXACT_FILE
from zodrive.bench.row import read_row
from zodrive.errors import ZodriveError
from zodrive.runinfo import command_line, write_json

STATES = 100
TIME_LIMIT = 10.0
GAP = ("success", "attackable", "found", "missed", "miss_rate", "won_unknown", "won_robust")
COUNTS = ("crown_certified", "robust", "attackable", "unknown", "timed_out", "contradictions", "seconds_median",
          "seconds_max")


def certify_row(model: str, folder: Path, *, state_count: int = STATES, time_limit: float = TIME_LIMIT,
                force: bool = False) -> dict[str, Any]:
    """Write and return `folder/exact.json` for the bench row in `folder`, whose policy `model` is (its
    content key must be the row's)."""
    from zodrive.evaluation.verify import certify_model
    from zodrive.policies.policy import resolve
    from zodrive.policies.resolve import resolve_scenario

    row = read_row(folder / "row.json")
    path = folder / EXACT_FILE
    if path.exists() and not force:
        raise ZodriveError(f"{path} exists: pass --force to replace it")
    if row.get("defense"):
        raise ZodriveError(f"{folder} is a defended row ({row['defense']}): the exact check decides the network "
                           "alone, not the network behind its defense")
    if row.get("track"):
        raise ZodriveError(f"{folder} is a row of the {row['track']} track: the exact check decides the dense threat "
                           "model (every row, every step) against the dense ensemble; check the policy's dense row")
    policy = resolve(model)
    if policy.kind != "model":
        raise ZodriveError(f"{model}: the exact check reads an SB3 zip's network (the row's own policy)")
    if policy.key() != row.get("key"):
        raise ZodriveError(f"{model} is not the policy of {folder}: its content key is not the row's "
                           f"({row.get('key')}); give the model that row benched")
    preset, _ = resolve_scenario(policy.ref, row["scenario"])
    black_box = BLACK_BOX  # every version's ensemble (an undefended row does not record it)
    budget, seed = row.get("query_budget"), int(row["seeds"][0])
    eps = [float(p["eps"]) for p in row["attacked"]]
    result = certify_model(policy.ref, preset, eps, episodes=int(row["episodes"]), seed=seed, attacks=black_box,
                           exact_limit=time_limit, state_count=state_count, query_budget=budget)
    exact = {
        "protocol": row["protocol"], "policy": row["policy"], "key": row["key"], "model": model,
        "states": result["rows"][0]["states"], "episodes": result["episodes"],
        "seeds": [seed, seed + result["episodes"] - 1], "time_limit": time_limit,
        "black_box": list(black_box), "query_budget": budget,
        "attacks_run": "untargeted, each state on its own (no warm start), the protocol's per-step query cap",
        "method": result["exact_method"],
        "rows": [{"eps": r["eps"], **{k: r["exact"][k] for k in COUNTS},
                  "ensemble": {k: r["exact"]["black_box_ensemble"][k] for k in GAP},
                  "attacks": {side["attack"]: {**{k: side["vs_exact"][k] for k in GAP},
                                               "queries_per_state": side["queries_per_state"]}
                              for side in r["attacks"]},
                  "per_state": r["per_state"]} for r in result["rows"]],
        "command": command_line(),
    }
    write_json(path, exact)
    return exact
