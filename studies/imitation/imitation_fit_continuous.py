"""What limits behaviour cloning of `baseline:idm-mobil` into the DDPG driver's actor?

Fits on fixed data (the teacher's own states on the `continuous` preset: `--train` on seeds
1000+, `--heldout` on seeds `--heldout-seed`+ (26000), labelled as it drives) and prints, per variant, the RMSE of
acceleration and steering on the training and the held-out states, the same on the held-out
"calm" states (no label beyond +-0.2: no lane change, no hard braking) beside the labels' std
there (what a constant scores), and the share of held-out states where the student steers
beyond +-0.2 (and how often the teacher does), and how often the ego's speed feature is clipped. Variants: the source actor's weights or a
fresh initialization, the loss (`scaled_mse` or plain MSE), epochs, data, the input std floor,
the ego's row alone.
One torch thread, one process.

    python studies/imitation/imitation_fit_continuous.py > results/imitation-continuous/ablation.txt
    python studies/imitation/imitation_fit_continuous.py --train 40000 --heldout-seed 60000 > results/imitation-continuous/ablation-40000.txt
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from torch.nn import functional as F

from zodrive.policies.loading import load_network
from zodrive.system import make_policy_env
from zodrive.training.distill import action_error, fit, labelled_rollout, reinitialized, restandardize, scaled_mse, \
    standardized
from zodrive.envs import load_preset

NAMES = ("acceleration", "steering")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=int, default=10000, help="teacher's states on seeds 1000+")
    parser.add_argument("--heldout", type=int, default=3000, help="teacher's states on seeds --heldout-seed+")
    parser.add_argument("--heldout-seed", type=int, default=26000, help="after every training seed (1000 + --train)")
    parser.add_argument("--model", default="models/ddpg-driver", help="source of the actor")
    args = parser.parse_args()
    torch.set_num_threads(1)
    teacher, env = make_policy_env("baseline:idm-mobil", load_preset("continuous"))
    train = labelled_rollout(env, teacher, teacher, 1.0, 1000, args.train, np.random.default_rng(0))
    if args.heldout_seed < 1000 + args.train:
        parser.error("--heldout-seed must come after the training seeds (1000 + --train)")
    held = labelled_rollout(env, teacher, teacher, 1.0, args.heldout_seed, args.heldout, np.random.default_rng(0))
    x, y = (torch.as_tensor(a.reshape(len(a), -1), dtype=torch.float32) for a in (train[0], held[0]))
    ty, hy = (torch.as_tensor(a, dtype=torch.float32) for a in (train[1], held[1]))
    calm = hy.abs().max(dim=1).values < 0.2
    print(f"train {len(x)} states (seeds 1000+), held-out {len(y)} (seeds {args.heldout_seed}+), calm held-out {int(calm.sum())}; "
          f"teacher steers beyond 0.2 on {float((hy[:, 1].abs() > 0.2).float().mean()):.3f} of held-out states")
    for i, name in enumerate(NAMES):
        q = np.quantile(train[1][:, i], [0.0, 0.05, 0.5, 0.95, 1.0])
        print(f"teacher's {name} on the training states: min / 5 % / median / 95 % / max " + " / ".join(f"{v:.4f}" for v in q))
    ego_vx = train[0][:, 0, 3]  # the ego's speed feature: vx / 20 m/s, clipped to [-1, 1]
    print(f"the ego's vx feature is at its clip (1.0, i.e. >= 20 m/s) on {float((ego_vx >= 1.0).mean()):.3f} of the "
          f"training states: the speed IDM's acceleration depends on is not observed above 20 m/s")
    source = load_network(args.model).net
    variants = [("source weights, 50 epochs, 5000 states", dict(fresh=False, epochs=50, n=5000)),
                ("fresh, 50 epochs, 5000 states", dict(epochs=50, n=5000)),
                ("fresh, 50 epochs, plain MSE", dict(epochs=50, n=5000, plain=True)),
                ("fresh, 50 epochs", dict(epochs=50)),
                ("fresh, 50 epochs, input std floor 0", dict(epochs=50, floor=0.0)),
                ("fresh, 20 epochs", dict(epochs=20)),
                ("fresh, 10 epochs", dict(epochs=10)),
                ("fresh, 10 epochs, plain MSE", dict(epochs=10, plain=True)),
                ("fresh, 10 epochs, ego row only", dict(epochs=10, ego_only=True)),
                ("fresh, 50 epochs, ego row only", dict(epochs=50, ego_only=True))]
    for name, options in variants:
        run(name, source, x, ty, y, hy, calm, **options)


def run(name: str, source: torch.nn.Sequential, x: torch.Tensor, ty: torch.Tensor, hx: torch.Tensor,
        hy: torch.Tensor, calm: torch.Tensor, *, epochs: int, n: int | None = None, fresh: bool = True,
        plain: bool = False, floor: float = 0.05, ego_only: bool = False) -> None:
    """Fit one variant on the first `n` training states and print its errors; `ego_only`: the
    other vehicles' rows set to 0 (is the teacher's action a function of the ego's own row?)."""
    torch.manual_seed(0)
    x, ty = x[:n], ty[:n]
    if ego_only:
        x, hx = (torch.cat([a[:, :5], torch.zeros_like(a[:, 5:])], dim=1) for a in (x, hx))
    net = standardized(reinitialized(source) if fresh else source)
    restandardize(net, x, floor)
    start = time.perf_counter()
    fit(net, x, ty, epochs=epochs, lr=1e-3, batch=256, weight=None, gen=torch.Generator().manual_seed(0),
        criterion=F.mse_loss if plain else scaled_mse(ty.std(dim=0)))
    tr, he, ca = (action_error(net, a, b, NAMES)["per_dim"] for a, b in ((x, ty), (hx, hy), (hx[calm], hy[calm])))
    with torch.no_grad():
        steers = float((net(hx)[:, 1].abs() > 0.2).float().mean())
    print(f"{name:<40} ({len(x)} states) train a {tr['acceleration']['rmse']:.3f} s {tr['steering']['rmse']:.3f} | "
          f"held-out a {he['acceleration']['rmse']:.3f} s {he['steering']['rmse']:.3f} (std {he['acceleration']['label_std']:.3f} / "
          f"{he['steering']['label_std']:.3f}) | calm a {ca['acceleration']['rmse']:.3f} s {ca['steering']['rmse']:.3f} "
          f"(std {ca['acceleration']['label_std']:.3f} / {ca['steering']['label_std']:.3f}) | steers > 0.2: {steers:.3f} "
          f"| {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
