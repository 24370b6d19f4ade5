"""The must-show table of results/certify-exact/README.md, printed from the certify.json files there.

    python studies/exact-sandwich/table.py [results/certify-exact]

One row per model and radius: CROWN-certified, exactly robust / attackable / unknown (counts of the
same clean states), each attack's success, the miss rate (exactly attackable states the attack did
not win) of each black-box attack and of their union (missed by every one), PGD's (white-box), and
the exact check's seconds per state. Then the smallest radius that changes each state's action.
Nothing here is computed but shares of the counts certify wrote.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

ORDER = ("dqn-driver", "dqn-close", "dqn-imitation", "dqn-robust", "dqn-sa",
         "zoo-highway-fast-dqn-seed-0", "zoo-highway-fast-dqn-seed-1", "zoo-highway-fast-dqn-seed-2")


def _miss(gap: dict[str, Any]) -> str:
    if gap["miss_rate"] is None:
        return "– (0/0)"
    return f"{gap['miss_rate']:.1%} ({gap['missed']}/{gap['attackable']})".replace("%", " %")


def _pct(x: float) -> str:
    return f"{x:.1%}".replace("%", " %")


def _eps(v: float | None, top: float) -> str:
    return f"> {top:g}" if v is None else f"{v:.4f}"


def main(folder: Path) -> int:
    found = {p.parent.name: json.loads(p.read_text()) for p in sorted(folder.glob("*/certify.json"))}
    names = [n for n in ORDER if n in found] + sorted(set(found) - set(ORDER))
    print("| Model (states) | ε | CROWN certified | exact robust | exact attackable | unknown | random search "
          "success | ZO-SignSGD success | PGD (white-box) success | miss: random search | miss: ZO-SignSGD | "
          "miss: both black-box | miss: PGD (white-box) | exact s/state median, max |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    contradictions = 0
    for name in names:
        result = found[name]
        for k, row in enumerate(result["rows"]):
            ex, sides = row["exact"], {s["attack"]: s for s in row["attacks"]}
            n = row["states"]
            label = (f"`{result['model']}` ({n} states, {result['episodes']} ep., {ex['time_limit']:g} s/check)"
                     if k == 0 else "")
            contradictions += ex["contradictions"] + sum(s["vs_exact"]["won_robust"] for s in sides.values())
            print(f"| {label} | {row['eps']:g} | {ex['crown_certified']} | {ex['robust']} | {ex['attackable']} | "
                  f"{ex['unknown']} | {_pct(sides['random-search']['success_share'])} | "
                  f"{_pct(sides['zo-signsgd']['success_share'])} | {_pct(sides['pgd']['success_share'])} | "
                  f"{_miss(sides['random-search']['vs_exact'])} | {_miss(sides['zo-signsgd']['vs_exact'])} | "
                  f"{_miss(ex['black_box_ensemble'])} | {_miss(sides['pgd']['vs_exact'])} | "
                  f"{ex['seconds_median']:.3f}, {ex['seconds_max']:.2f} |")
    print(f"\ncontradictions (CROWN-certified or attack-won where exact says robust), all rows: {contradictions}")
    print("\n| Model | smallest ε changing the action, exact (bisection): q25 | median | q75 | no counterexample up "
          "to the largest ε (unknown there) | bisections stopped by an unknown | on the grid, q25 / median: exact | "
          "random search | ZO-SignSGD | PGD |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        m = found[name].get("min_eps")
        if m is None:
            continue
        top = max(m["grid"])
        q = [f"[{_eps(a, top)}, {_eps(b, top)}]" for a, b in zip(m["quartiles_lower"], m["quartiles_upper"])]
        grid = [f"{_eps(m['on_grid'][k][0], top)} / {_eps(m['on_grid'][k][1], top)}"
                for k in ("exact", "random-search", "zo-signsgd", "pgd")]
        print(f"| `{found[name]['model']}` | {' | '.join(q)} | {m['beyond_grid']} ({m['unknown_at_max']}) | "
              f"{m['stopped']} | {' | '.join(grid)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/certify-exact")))
