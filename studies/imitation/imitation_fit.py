"""What limits behaviour cloning of `baseline:rules` into the DQN's 25-256-256-5 MLP?

Fits on fixed data (the rules' own states: `--train` on seeds 20000+, `--heldout` on seeds
30000+) and prints train / held-out agreement per class (L LANE_LEFT, I IDLE, R LANE_RIGHT,
F FASTER, S SLOWER) for: the last session's plain fit (raw observation, Adam 1e-3 constant),
a cosine schedule, a standardized input layer (folded into the first Linear layer before
measuring, as it is saved), class weights, epochs, data amount, and `jitter` (noisy copies
of each batch labelled by the rules). Then where the plain fit's held-out SLOWER errors are:
per episode, and the gap and closing speed of the vehicle ahead (the rules' own terms).
One torch thread, one process.

    python studies/imitation/imitation_fit.py --train 40000 --heldout 10000 > results/imitation/ablation.txt
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from torch.nn import functional as F

from zodrive.policies.loading import load_network
from zodrive.policies.resolve import load_victim
from zodrive.training.distill import agreement, class_weights, fit, folded, jitter, standardized
from zodrive.envs import make_env
from zodrive.envs.presets import load_preset, scenario
from zodrive.evaluation.rollout import clean_states

SHORT = ("L", "I", "R", "F", "S")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=int, default=40000, help="rules' states on seeds 20000+")
    parser.add_argument("--heldout", type=int, default=10000, help="rules' states on seeds 30000+")
    parser.add_argument("--model", default="models/dqn", help="source of the network shape")
    parser.add_argument("--student", help="also: a student zip's confusion with the rules on its own states "
                                          "(seeds 90000+, --heldout states), and nothing else")
    parser.add_argument("--rounds", metavar="TRAIN_JSON", help="only print a DAgger run's agreement per round")
    args = parser.parse_args()
    if args.rounds:
        print_rounds(args.rounds)
        return
    torch.set_num_threads(1)
    preset = load_preset("discrete")
    rules = load_victim("baseline:rules", preset)
    env = make_env(preset)
    if args.student:
        confusion(args.student, env, rules, preset, args.heldout)
        return
    train_states = clean_states(env, rules, 20000, args.train)
    held_states = clean_states(env, rules, 30000, args.heldout)
    env.close()

    def flat(states: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(states.reshape(len(states), -1), dtype=torch.float32)

    def label(x: torch.Tensor) -> torch.Tensor:
        return torch.as_tensor(rules.query(x.numpy().reshape(len(x), *rules.obs_shape)).argmax(axis=1))

    x_tr, x_ho = flat(train_states), flat(held_states)
    y_tr, y_ho = label(x_tr), label(x_ho)
    print(f"{len(x_tr)} training states (seeds 20000+), {len(x_ho)} held-out (seeds 30000+); labels on the "
          "training states: " + ", ".join(f"{n} {float((y_tr == c).float().mean()):.2%}" for c, n in enumerate(SHORT)))
    source = load_network(args.model, preset).net

    def run(text: str, n: int, *, std: bool, power: float = 0.0, epochs: int = 60, constant_lr: bool = False,
            noise: float = 0.0) -> torch.nn.Sequential:
        torch.manual_seed(1)
        net = torch.nn.Sequential(*[torch.nn.Linear(m.in_features, m.out_features) if isinstance(m, torch.nn.Linear)
                                    else m for m in source])  # a fresh network of the DQN's shape
        x, y = x_tr[:n], y_tr[:n]
        if std:
            net = standardized(net, x)
        gen = torch.Generator().manual_seed(1)
        weight = class_weights(y, len(SHORT), power) if power else None
        start = time.perf_counter()
        if constant_lr:  # the last session's plain fit
            opt = torch.optim.Adam(net.parameters(), lr=1e-3)
            for _ in range(epochs):
                for idx in torch.randperm(len(x), generator=gen).split(256):
                    loss = F.cross_entropy(net(x[idx]), y[idx], weight=weight)
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
            net.eval()
        else:
            spread = x.std(dim=0)
            spread[0::5] = 0  # presence stays as observed
            augment = jitter(label, spread, noise, -1.0, 1.0, gen) if noise else None
            fit(net, x, y, epochs=epochs, lr=1e-3, batch=256, weight=weight, gen=gen, augment=augment)
        net = folded(net)
        parts = [f"{text:<52} {time.perf_counter() - start:4.0f}s"]
        for name, (xt, yt) in {"train": (x, y), "heldout": (x_ho, y_ho)}.items():
            a = agreement(net, xt, yt, SHORT)
            parts.append(f"| {name} {a['all']:.4f} (" + " ".join(f"{k} {v[0]:.3f}/{v[1]}" for k, v in
                                                                a["per_class"].items()) + ")")
        print(" ".join(parts), flush=True)
        return net

    n, quarter = len(x_tr), len(x_tr) // 4
    run(f"raw, Adam 1e-3 constant, 60 ep, {quarter} states", quarter, std=False, constant_lr=True)
    plain = run("raw, Adam 1e-3 constant, 60 ep", n, std=False, constant_lr=True)
    run("raw, cosine 1e-3, 60 ep", n, std=False)
    run(f"standardized, cosine, 60 ep, {quarter} states", quarter, std=True)
    run("standardized, cosine, 60 ep", n, std=True)
    run("standardized, cosine, 60 ep, class weights ^0.5", n, std=True, power=0.5)
    run("standardized, cosine, 150 ep", n, std=True, epochs=150)
    run("standardized, cosine, 60 ep, jitter 0.2", n, std=True, noise=0.2)
    run("standardized, cosine, 60 ep, jitter 0.5", n, std=True, noise=0.5)
    run("standardized, cosine, 60 ep, jitter 0.5, class weights ^0.5", n, std=True, noise=0.5, power=0.5)
    run("standardized, cosine, 150 ep, jitter 0.5", n, std=True, noise=0.5, epochs=150)

    # where the plain fit's held-out SLOWER errors are, in the rules' terms (physical units)
    with torch.no_grad():
        pred = plain(x_ho).argmax(dim=1).numpy()
    ranges = scenario(preset).feature_ranges
    scale = np.array([1.0, ranges["x"][1], ranges["y"][1], ranges["vx"][1], ranges["vy"][1]])
    others = held_states[:, 1:] * scale
    ahead = (np.abs(others[:, :, 2]) < 2.0) & (others[:, :, 1] > 0)  # own lane (4 m wide), ahead
    nearest = np.where(ahead, others[:, :, 1], np.inf).argmin(axis=1)
    gap, dvx = others[np.arange(len(others)), nearest, 1], others[np.arange(len(others)), nearest, 3]
    slower = y_ho.numpy() == 4
    episode = np.arange(len(held_states)) // 450  # 450-step episodes (a crash shifts this: approximate)
    print("plain fit, held-out SLOWER states per 450-step block:", np.bincount(episode[slower]).tolist())
    print("                       of them taken as another action:", np.bincount(episode[slower & (pred != 4)]).tolist())
    print("confusion of SLOWER: " + ", ".join(f"{SHORT[c]} {int((slower & (pred == c)).sum())}" for c in range(5)))
    for text, mask in (("right", slower & (pred == 4)), ("wrong", slower & (pred != 4))):
        q = lambda v: " ".join(f"{p:.1f}" for p in np.percentile(v[mask], [10, 50, 90]))  # noqa: E731
        print(f"held-out SLOWER, plain fit {text}: {int(mask.sum())} states; gap ahead [m] p10/50/90 {q(gap)}; "
              f"relative speed [m/s] {q(dvx)}")
    q = lambda v: " ".join(f"{p:.1f}" for p in np.percentile(v, [10, 50, 90]))  # noqa: E731
    train_slower = y_tr.numpy() == 4
    ot = train_states[:, 1:] * scale
    at = (np.abs(ot[:, :, 2]) < 2.0) & (ot[:, :, 1] > 0)
    nt = np.where(at, ot[:, :, 1], np.inf).argmin(axis=1)
    print(f"training SLOWER: {int(train_slower.sum())} states; gap ahead [m] p10/50/90 "
          f"{q(ot[np.arange(len(ot)), nt, 1][train_slower])}; relative speed [m/s] {q(ot[np.arange(len(ot)), nt, 3][train_slower])}")


def print_rounds(path: str) -> None:
    """The agreement table of a `--dagger` run's train.json, one block per round (a continuous
    student's: RMSE / MAE per action dimension beside the labels' std)."""
    import json

    t = json.loads(open(path).read())
    m = t["method"]
    print(f"{path}: {m['rounds']} rounds of {m['states']} states, {m['epochs']} epochs per refit, jitter {m['jitter']}, "
          f"kappa {m['kappa']}{', beta ' + str(m['beta']) if 'beta' in m else ''}; held-out seeds {t['heldout_seeds']}; {t['wall_time_s']} s")
    for r in t["rounds"]:
        print(f"round {r['round']} ({r['driver']} drives, seeds {r['seeds'][0]}-{r['seeds'][1]}), aggregate "
              f"{r['aggregate']}, loss {r['loss_per_epoch'][0]} -> {r['loss_per_epoch'][-1]}")
        for key in ("train", "heldout_teacher_states", "heldout_student_states"):
            a = r[key]
            if "per_dim" in a:
                print(f"   {key:<24} " + "  ".join(f"{n} rmse {v['rmse']:.4f} mae {v['mae']:.4f} (label std "
                                                     f"{v['label_std']:.4f})" for n, v in a["per_dim"].items()))
                continue
            print(f"   {key:<24} {a['all']:.4f}  " + " ".join(f"{SHORT[['LANE_LEFT', 'IDLE', 'LANE_RIGHT', 'FASTER', 'SLOWER'].index(n)]} "
                                                          f"{v[0]:.3f}/{v[1]}" for n, v in a["per_class"].items()))


def confusion(student: str, env: object, rules: object, preset: dict, count: int) -> None:
    """Rows: the rules' action, columns: the student's, on the states the student drives into."""
    from zodrive.policies.victims import network_victim

    net = load_network(student, preset).net
    states = clean_states(env, network_victim(net, "discrete", rules.obs_shape), 90000, count)
    with torch.no_grad():
        mine = net(torch.as_tensor(states.reshape(len(states), -1))).argmax(dim=1).numpy()
    theirs = rules.query(states).argmax(axis=1)
    print(f"{student}: {len(states)} states it drives into (seeds 90000+); rows rules, columns student")
    print("      " + " ".join(f"{n:>6}" for n in SHORT))
    for c, n in enumerate(SHORT):
        print(f"{n:>5} " + " ".join(f"{int(((theirs == c) & (mine == d)).sum()):>6}" for d in range(5)))


if __name__ == "__main__":
    main()
