"""A probe (issue 23, item 1; not a product command): where a picker misses on models/dqn-close, is the ranking
or the pool to blame? Each step the picker (`zodrive picker-train`) ranks --k random vertices of the eps-ball
and its best one is fed (no hold: every step a fresh pool). For analysis only (extra queries, not an attack)
the victim is also asked on every vertex of the pool, and on the steps where the fed vertex missed FASTER the
probe prints how often some vertex of the pool would have given it, and the pool's share that would.
Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/pool.py MODEL EPS PICKER_DIR [--k 64] [--episodes 10]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, arguments, drive, setup, show
from zodrive.attacks.picker import Picker


def main() -> None:
    p = arguments(10, "picker")
    p.add_argument("--k", type=int, default=64)
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    picker, _ = Picker.load(a.picker)
    shape = env.observation_space.shape
    mask = threat.mask(shape)
    rng = np.random.default_rng(0)
    rows: list[tuple[bool, bool, float, float]] = []  # (picked worked, any worked, pool share, picker's rating)

    def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
        pool = threat.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=(a.k, *shape)) * mask
        fed = threat.project(np.repeat(x, a.k, axis=0) + pool, np.repeat(x, a.k, axis=0))
        scores = picker.scores(fed)
        works = victim.query(fed).argmax(axis=1) == FASTER  # analysis only
        best = int(scores.argmax())
        rows.append((bool(works[best]), bool(works.any()), float(works.mean()), float(scores[best])))
        return fed[best:best + 1]

    show(f"picker's best of {a.k}, every step", drive(env, victim, 900000, a.episodes, choose))
    r = np.array(rows)
    miss = r[:, 0] == 0
    print(f"  {len(r)} steps; the fed vertex missed on {miss.mean() * 100:.1f} %")
    print(f"  on the missed steps: some vertex of the pool works on {r[miss, 1].mean() * 100:.1f} %, the pool's share "
          f"that works: mean {r[miss, 2].mean() * 100:.1f} %, median {np.median(r[miss, 2]) * 100:.1f} %; picker's "
          f"rating of its pick: mean {r[miss, 3].mean():.2f} (on the hit steps {r[~miss, 3].mean():.2f})")
    print(f"  on the hit steps: the pool's share that works: mean {r[~miss, 2].mean() * 100:.1f} %")


if __name__ == "__main__":
    main()
