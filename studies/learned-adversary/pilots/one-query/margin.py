"""A probe (issue 23, item 1; not a product command): would a picker fitted to the victim's scores pick better
where vertex check's check fails? The committed pickers are fitted to "takes FASTER" (0/1). Here two MLPs of
the same shape are fitted on the same vertices, one to that label (binary cross-entropy) and one to the margin
Q[FASTER] - max of the other Q-values (Huber, scaled), which a score query also returns; then, at the steps
of 30 tuning episodes where the held vertex fails its check (the victim driving under the product's vertex
check with a committed picker), each ranks the same 64 random vertices and the probe prints how often its
best one works, beside the committed picker's. Data: --episodes-fit episodes from seed 900100 under the same
attack, --probes vertices per state (queries counted and printed). Nothing written.

    python studies/learned-adversary/pilots/one-query/margin.py MODEL EPS PICKER_DIR [--episodes-fit 15]
"""

from __future__ import annotations

import numpy as np
import torch

from common import FASTER, Vertices, arguments, drive_attack, vertex_check
from zodrive.attacks.picker import network


def fit(x: torch.Tensor, y: torch.Tensor, loss: str, epochs: int, seed: int) -> torch.nn.Module:
    torch.manual_seed(seed)
    net = network(x.shape[1], 256)
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    for _ in range(epochs):
        for batch in torch.randperm(len(x)).split(4096):
            out = net(x[batch]).squeeze(1)
            value = (torch.nn.functional.binary_cross_entropy_with_logits(out, (y[batch] > 0).float()) if loss == "bce"
                     else torch.nn.functional.huber_loss(out, y[batch]))
            opt.zero_grad()
            value.backward()
            opt.step()
    return net.eval()


def main() -> None:
    p = arguments(30, "picker")
    p.add_argument("--episodes-fit", type=int, default=15)
    p.add_argument("--probes", type=int, default=256)
    p.add_argument("--epochs", type=int, default=10)
    a = p.parse_args()
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    v, rng = Vertices(threat, env.observation_space.shape), np.random.default_rng(0)
    xs, margins = [], []

    def collect(x: np.ndarray, held: np.ndarray | None) -> None:
        points = v.fed(x, v.random(rng, a.probes))
        q = victim.query(points)
        others = np.delete(q, FASTER, axis=1).max(axis=1)
        xs.append(points.reshape(len(points), -1))
        margins.append(q[:, FASTER] - others)

    drive_attack(env, victim, attack, objective, oracle, 900100, a.episodes_fit, collect)
    x = torch.from_numpy(np.concatenate(xs))
    m = np.concatenate(margins)
    scale = float(np.std(m))
    y = torch.from_numpy((m / scale).astype(np.float32))
    print(f"  fit data: {len(x)} vertices at {len(xs)} states ({len(x)} victim queries), FASTER on "
          f"{(m > 0).mean() * 100:.1f} %")
    nets = {"fitted to 0/1 (BCE)": fit(x, y, "bce", a.epochs, 0), "fitted to the margin (Huber)": fit(x, y, "margin", a.epochs, 0)}
    hits = {"committed picker": 0, **{name: 0 for name in nets}}
    failed = 0

    def judge(x: np.ndarray, held: np.ndarray | None) -> None:
        nonlocal failed
        if held is None or np.isnan(held).any():
            return
        if v.takes(victim, x, held)[0]:
            return
        failed += 1
        pool = v.fed(x, v.random(rng, 64))
        works = victim.query(pool).argmax(axis=1) == FASTER
        hits["committed picker"] += bool(works[int(attack.picker.scores(pool).argmax())])
        with torch.no_grad():
            flat = torch.from_numpy(pool.reshape(64, -1))
            for name, net in nets.items():
                hits[name] += bool(works[int(net(flat).squeeze(1).argmax())])

    drive_attack(env, victim, attack, objective, oracle, 900000, a.episodes, judge)
    print(f"  tuning seeds 900000-{900000 + a.episodes - 1}: the held vertex failed its check on {failed} steps; "
          "there the best-rated of 64 random vertices worked:")
    for name, n in hits.items():
        print(f"    {name}: {n / max(failed, 1) * 100:.1f} %")


if __name__ == "__main__":
    main()
