"""The learned adversary against the strongest per-step attack on the same 100 seeds (100000-100099):
mean of (learned - per-step) return per seed with its bootstrap 95 % CI (`zodrive.evaluation.stats.
paired_difference_ci`). Both start every episode from the same traffic, so the pairs are correlated and
the difference is measured more precisely than the two CIs side by side show. Positive: the learned
adversary left the victim more return (it is weaker). Usage: python studies/learned-adversary/paired.py"""

from pathlib import Path

from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci

C, R = Path("results/learned-adversary/cells"), Path("results/robustness-100")
K = Path("results/close-rules/attacked")
SEEDS = ("", "-seed1", "-seed2")  # a cell's suffix for training (or attack) seeds 0, 1, 2
PAIRS = [  # (learned cell, per-step cell)
    (C / "dqn-driver-amortized-eps0.05-100", C / "dqn-driver-pgd-eps0.05-100"),
    (C / "dqn-driver-amortized-eps0.2-100", C / "dqn-driver-random-search-eps0.2-100"),
    (C / "dqn-robust-amortized-eps0.02-100", R / "dqn-robust-pgd-eps0.02"),
    (C / "dqn-driver-amortized-eps0.02-100", R / "dqn-driver-pgd-eps0.02"),
    (C / "ppo-dqn-driver-eps0.02-std0.2-w10k-100", R / "dqn-driver-pgd-eps0.02"),
    (C / "dqn-robust-amortized-eps0.05-100", R / "dqn-robust-random-search-eps0.05"),
    (C / "ppo-dqn-robust-eps0.05-std0.2-w10k-100", R / "dqn-robust-random-search-eps0.05"),
    *[(C / f"ppo-ddpg-driver-eps0.2{s}-100", C / "ddpg-driver-random-search-eps0.2-100") for s in ("", "-seed1", "-seed2")],
    *[(C / f"ppo-ddpg-driver-eps0.05{s}-100", C / "ddpg-driver-random-search-eps0.05-100") for s in ("", "-seed1", "-seed2")],
    (C / "ppo-ddpg-robust-eps0.05-100", C / "ddpg-robust-random-search-eps0.05-100"),
    (C / "ppo-td3-finetuned-eps0.2-100", C / "td3-finetuned-random-search-eps0.2-100"),
    *[(K / f"amortized-eps{e}", K / f"random-search-eps{e}") for e in ("0.02", "0.05")],  # models/dqn-close
    # training seeds 1 and 2 of the fitted start on dqn-robust (run-seeds-robust.sh), and random search's
    # attack seeds 1 and 2 at eps 0.05 (run-rs-seeds-robust.sh), each against the other side's seed 0
    *[(C / f"dqn-robust-amortized-eps0.02-seed{s}-100", R / "dqn-robust-pgd-eps0.02") for s in (1, 2)],
    *[(C / f"dqn-robust-amortized-eps0.05-seed{s}-100", R / "dqn-robust-random-search-eps0.05") for s in (1, 2)],
    *[(C / "dqn-robust-amortized-eps0.05-100", C / f"dqn-robust-random-search-eps0.05-seed{s}-100") for s in (1, 2)],
    # the fallback target FASTER,not:SLOWER (run-fallback.sh, run-fallback-fitted.sh): each per-step attack with it
    # against itself without it; then the one-query attacks against the strongest per-step attack
    *[(C / f"dqn-robust-random-search-fallback-eps0.05{t}-100", R / "dqn-robust-random-search-eps0.05") for t in SEEDS],
    (C / "dqn-robust-pgd-fallback-eps0.02-100", R / "dqn-robust-pgd-eps0.02"),
    (C / "dqn-driver-pgd-fallback-eps0.02-100", R / "dqn-driver-pgd-eps0.02"),
    (C / "dqn-driver-pgd-fallback-eps0.05-100", C / "dqn-driver-pgd-eps0.05-100"),
    *[(C / f"dqn-robust-amortized-fallback-eps{e}{t}-100", C / f"dqn-robust-amortized-eps{e}{t}-100")
      for e in ("0.02", "0.05") for t in SEEDS],
    (C / "dqn-driver-amortized-fallback-eps0.02-100", C / "dqn-driver-amortized-eps0.02-100"),
    *[(C / f"dqn-robust-amortized-fallback-eps0.05{t}-100", C / "dqn-robust-random-search-fallback-eps0.05-100")
      for t in SEEDS],
    *[(C / "dqn-robust-amortized-fallback-eps0.05-100", C / f"dqn-robust-random-search-fallback-eps0.05{t}-100")
      for t in SEEDS[1:]],
    *[(C / f"dqn-robust-amortized{f}-eps0.02{t}-100", C / "dqn-robust-pgd-fallback-eps0.02-100")
      for f in ("", "-fallback") for t in SEEDS],
    *[(C / f"dqn-driver-amortized-fallback-eps0.02{t}-100", C / "dqn-driver-pgd-fallback-eps0.02-100") for t in SEEDS],
    (C / "dqn-driver-amortized-eps0.02-100", C / "dqn-driver-pgd-fallback-eps0.02-100"),
    # random search on the DQN driver at eps 0.02, 100 episodes, with and without the fallback, against PGD with it
    *[(C / f"dqn-driver-random-search{f}-eps0.02-100", C / "dqn-driver-pgd-fallback-eps0.02-100") for f in ("", "-fallback")],
    (C / "dqn-driver-random-search-fallback-eps0.02-100", C / "dqn-driver-random-search-eps0.02-100"),
    (C / "dqn-close-random-search-fallback-eps0.02-100", K / "random-search-eps0.02"),  # the fallback on dqn-close
    # PPO from the fitted start for 1 M steps (run-ppo.sh ... std0.2-w10k-1m ... --steps 1000000)
    *[(C / "ppo-dqn-robust-eps0.05-std0.2-w10k-1m-100", other) for other in (
        C / "dqn-robust-amortized-eps0.05-100", R / "dqn-robust-random-search-eps0.05",
        C / "dqn-robust-random-search-fallback-eps0.05-100")],
    # white-box PGD (patience 10) on dqn-robust at eps 0.05, the literature's per-step baseline, against the fitted
    # start's training seeds without and with the fallback
    *[(C / f"dqn-robust-amortized{f}-eps0.05{t}-100", C / "dqn-robust-pgd-eps0.05-100")
      for f in ("", "-fallback") for t in SEEDS],
    # PPO from the fitted start against white-box PGD on the continuous victims (PGD's cells have 30 episodes:
    # the first 30 seeds are paired)
    *[(C / f"ppo-ddpg-driver-eps0.2{t}-100", Path("results/attacks-drivers/cells/ddpg-driver-pgd-eps0.2")) for t in SEEDS],
    *[(C / f"ppo-ddpg-driver-eps0.05{t}-100", C / "ddpg-driver-pgd-eps0.05") for t in SEEDS],
    (C / "ppo-ddpg-robust-eps0.05-100", C / "ddpg-robust-pgd-eps0.05"),
    (C / "ppo-td3-finetuned-eps0.2-100", Path("results/attacks-td3-finetuned/cells/td3-finetuned-pgd-eps0.2")),
    # for the summary table: the fitted start's training seeds 1 and 2 on the DQN driver at eps 0.05 against PGD, and
    # with the fallback on dqn-robust at eps 0.02 against plain PGD
    *[(C / f"dqn-driver-amortized-eps0.05{t}-100", C / "dqn-driver-pgd-eps0.05-100") for t in SEEDS[1:]],
    *[(C / f"dqn-robust-amortized-fallback-eps0.02{t}-100", R / "dqn-robust-pgd-eps0.02") for t in SEEDS],
]


def returns(cell: Path) -> dict[int, float]:
    return {row["seed"]: row["return"] for row in store.episodes(cell)}  # its folder, or its line in a pack


def label(cell: Path) -> str:
    return f"dqn-close-{cell.name}" if cell.parent == K else cell.name


for learned, per_step in PAIRS:
    a, b = returns(learned), returns(per_step)
    seeds = sorted(set(a) & set(b))
    diff, low, high = paired_difference_ci([a[s] for s in seeds], [b[s] for s in seeds])
    print(f"{label(learned)} - {label(per_step)}: {diff:+.2f} [{low:+.2f}, {high:+.2f}] over {len(seeds)} seeds")
