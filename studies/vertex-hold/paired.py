"""Vertex hold (1 query per step) against the strongest per-step attack and the learned adversary on the
same 100 seeds (100000-100099): mean of (vertex hold - other) return per seed with its bootstrap 95 % CI
(`zodrive.evaluation.stats.paired_difference_ci`); positive: vertex hold left the victim more return (it
is weaker). The other cells are the ones studies/learned-adversary/paired.py compares (the shielded
rows: results/shield). Usage: python studies/vertex-hold/paired.py > results/vertex-hold/paired.txt"""

from pathlib import Path

from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci

H = Path("results/vertex-hold/cells")
C, R = Path("results/learned-adversary/cells"), Path("results/robustness-100")
K, S = Path("results/close-rules/attacked"), Path("results/shield/cells-v5")
PAIRS = [  # (vertex-hold cell, other cell)
    ("dqn-driver-eps0.02", R / "dqn-driver-pgd-eps0.02"), ("dqn-driver-eps0.02", C / "dqn-driver-amortized-eps0.02-100"),
    ("dqn-driver-eps0.05", C / "dqn-driver-pgd-eps0.05-100"), ("dqn-driver-eps0.05", C / "dqn-driver-amortized-eps0.05-100"),
    ("dqn-driver-eps0.2", C / "dqn-driver-random-search-eps0.2-100"),
    ("dqn-driver-eps0.2", C / "dqn-driver-amortized-eps0.2-100"),
    ("dqn-robust-eps0.02", R / "dqn-robust-pgd-eps0.02"), ("dqn-robust-eps0.02", C / "dqn-robust-amortized-eps0.02-100"),
    ("dqn-robust-eps0.05", R / "dqn-robust-random-search-eps0.05"),
    ("dqn-robust-eps0.05", C / "dqn-robust-amortized-eps0.05-100"),
    ("dqn-close-eps0.02", K / "random-search-eps0.02"), ("dqn-close-eps0.02", K / "amortized-eps0.02"),
    ("dqn-close-eps0.05", K / "random-search-eps0.05"), ("dqn-close-eps0.05", K / "amortized-eps0.05"),
    ("ddpg-driver-eps0.2", C / "ddpg-driver-random-search-eps0.2-100"), ("ddpg-driver-eps0.2", C / "ppo-ddpg-driver-eps0.2-100"),
    ("ddpg-driver-eps0.05", C / "ddpg-driver-random-search-eps0.05-100"),
    ("ddpg-driver-eps0.05", C / "ppo-ddpg-driver-eps0.05-seed1-100"),
    ("ddpg-robust-eps0.05", C / "ddpg-robust-random-search-eps0.05-100"),
    ("ddpg-robust-eps0.05", C / "ppo-ddpg-robust-eps0.05-100"),
    ("td3-finetuned-eps0.2", C / "td3-finetuned-random-search-eps0.2-100"),
    ("td3-finetuned-eps0.2", C / "ppo-td3-finetuned-eps0.2-100"),
    # attack seeds 1 and 2 (run-seeds.sh) where vertex hold matters
    *[(f"{cell}-seed{s}", other) for s in (1, 2) for cell, other in (
        ("dqn-close-eps0.02", K / "random-search-eps0.02"), ("dqn-close-eps0.05", K / "random-search-eps0.05"),
        ("dqn-driver-eps0.2", C / "dqn-driver-random-search-eps0.2-100"),
        ("dqn-driver-eps0.02", R / "dqn-driver-pgd-eps0.02"))],
    # with a picker (picker/run.sh; fit seeds 0, 1 and 2 where run): against random search and vertex hold blind
    *[(Path("../picker/cells") / f"dqn-close-eps0.02-seed{s}", other) for s in (0, 1, 2)
      if store.exists(H / "../picker/cells" / f"dqn-close-eps0.02-seed{s}")
      for other in (K / "random-search-eps0.02", H / "dqn-close-eps0.02")],
    *[(Path(f"../picker/cells/dqn-driver-eps0.02-seed{s}"), other) for s in (0, 1, 2)
      if store.exists(H / f"../picker/cells/dqn-driver-eps0.02-seed{s}")
      for other in (R / "dqn-driver-pgd-eps0.02", H / "dqn-driver-eps0.02", C / "dqn-driver-pgd-fallback-eps0.02-100")],
    # pickers fitted with --loss rank (picker/run.sh dqn-close-rank ... --loss rank): against random search, and
    # against the picker of the same fit seed fitted with the default loss (bce)
    *[(Path(f"../picker/cells/dqn-close-rank-eps0.02-seed{s}"), other) for s in (0, 1, 2)
      if store.exists(H / f"../picker/cells/dqn-close-rank-eps0.02-seed{s}")
      for other in (K / "random-search-eps0.02", H / f"../picker/cells/dqn-close-eps0.02-seed{s}")],
    # vertex check (run-check.sh, picker/check.sh; cells check-*): against the strongest per-step attack and
    # against vertex hold, blind or with the same picker
    *[(Path(f"check-{cell}"), other) for cell, others in (
        ("dqn-close-eps0.02", (K / "random-search-eps0.02", H / "dqn-close-eps0.02")),
        ("dqn-close-eps0.05", (K / "random-search-eps0.05", H / "dqn-close-eps0.05")),
        ("dqn-driver-eps0.2", (C / "dqn-driver-random-search-eps0.2-100", H / "dqn-driver-eps0.2")))
      if store.exists(H / f"check-{cell}") for other in others],
    *[(Path(f"../picker/cells/check-{name}-seed{s}"), other) for name, strongest in (
        ("dqn-close-eps0.02", (K / "random-search-eps0.02",)), ("dqn-close-rank-eps0.02", (K / "random-search-eps0.02",)),
        ("dqn-driver-eps0.02", (R / "dqn-driver-pgd-eps0.02", C / "dqn-driver-pgd-fallback-eps0.02-100"))) for s in (0, 1, 2)
      if store.exists(H / f"../picker/cells/check-{name}-seed{s}")
      for other in (*strongest, H / f"../picker/cells/{name}-seed{s}")],
    # vertex check with --check-below 0.998 (at most 1 query per step on average): against random search and
    # against vertex check with the same picker at 1 query per step
    *[(Path(f"../picker/cells/check-below0.998-{name}-seed{s}"), other)
      for name in ("dqn-close-eps0.02", "dqn-close-rank-eps0.02") for s in (0, 1, 2)
      if store.exists(H / f"../picker/cells/check-below0.998-{name}-seed{s}")
      for other in (K / "random-search-eps0.02", H / f"../picker/cells/check-{name}-seed{s}")],
    # against PGD with the fallback target FASTER,not:SLOWER (studies/learned-adversary/run-fallback.sh)
    ("dqn-driver-eps0.02", C / "dqn-driver-pgd-fallback-eps0.02-100"),
    ("dqn-robust-eps0.02", C / "dqn-robust-pgd-fallback-eps0.02-100"),
    ("dqn-robust-eps0.05", C / "dqn-robust-random-search-fallback-eps0.05-100"),
    # vertex check on dqn-close at eps 0.02 against white-box PGD (patience 10), the literature's per-step baseline
    *[(Path(f"../picker/cells/check-{name}-seed{s}"), K / "pgd-eps0.02")
      for name in ("dqn-close-eps0.02", "dqn-close-rank-eps0.02") for s in (0, 1, 2)],
    # against white-box PGD where random search was the strongest per-step attack (the summary table of
    # results/learned-adversary/README.md)
    ("dqn-driver-eps0.2", C / "dqn-driver-pgd-eps0.2-100"),
    *[(f"dqn-close-eps0.05{t}", K / "pgd-eps0.05") for t in ("", "-seed1", "-seed2")],
    # behind the shield: against its strongest attack so far and the constant brake (its first 100 seeds)
    ("dqn-driver+shield@0.02-eps0.02", S / "dqn-driver+shield@0.02-pgd-eps0.02"),
    ("dqn-driver+shield@0.02-eps0.02", S / "baseline-slower-300"),
    ("dqn-driver+shield@0.05-eps0.05", S / "dqn-driver+shield@0.05-pgd-eps0.05-300"),
    ("dqn-driver+shield@0.05-eps0.05", S / "baseline-slower-300"),
    ("dqn-close+shield@0.02-eps0.02", K / "v5-shield@0.02-random-search-eps0.02"),
    ("dqn-close+shield@0.02-eps0.02", S / "baseline-slower-300"),
]


def returns(cell: Path) -> dict[int, float]:
    return {row["seed"]: row["return"] for row in store.episodes(cell)}  # its folder, or its line in a pack


for hold, other in PAIRS:
    a, b = returns(H / hold), returns(other)
    seeds = sorted(set(a) & set(b))
    diff, low, high = paired_difference_ci([a[s] for s in seeds], [b[s] for s in seeds])
    print(f"vertex-hold {hold} - {other.parent.name}/{other.name}: {diff:+.2f} [{low:+.2f}, {high:+.2f}] over {len(seeds)} seeds")
