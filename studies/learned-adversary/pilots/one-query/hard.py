"""A probe (issue 23, item 1; not a product command): a picker for the hard states. Vertex check's misses on
dqn-close come where the held vertex fails its check and the picker's best fresh vertex, fed unasked, fails
too (it works on about two of three such steps, `results/learned-adversary/pilots/one-query/unasked-dqn-close.txt`). The committed picker saw few such
states: they are the last steps before a crash, a few per training episode. This collects many of them and
fine-tunes a copy of the committed picker on them alone, to be used only where a check failed.

  collect  drive the product's `vertex-check:PICKER` on --episodes episodes from --seed0 (not tuning or evaluation
           seeds); at each step whose held vertex would fail its check, query --probes random vertices and keep
           them with their labels (every query counted and printed); writes an .npz
  judge    fine-tune a copy of the picker on the .npz files (BCE, --epochs, 5 % of states held out), then drive
           the product's vertex check on tuning seeds 900000+ and, where the held vertex fails its check, rank
           the same 64 random vertices with both pickers: print how often each one's best works. Nothing written.
  drive    fine-tune as judge does, then drive the product's vertex check on tuning seeds 900000+ with the fine-tuned
           copy choosing only the vertex fed unasked where a check failed (the committed picker everything else);
           print the return and the victim's action shares, to set beside the product's on the same seeds.

    python studies/learned-adversary/pilots/one-query/hard.py collect MODEL EPS PICKER_DIR --seed0 700000 \
        --episodes 150 --out runs/hard/a.npz
    python studies/learned-adversary/pilots/one-query/hard.py judge MODEL EPS PICKER_DIR runs/hard/a.npz ...
"""

from __future__ import annotations

import argparse
import copy

import numpy as np
import torch

from common import FASTER, Vertices, drive_attack, drive_counting, percent, vertex_check


def collect(a: argparse.Namespace) -> None:
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    v, rng = Vertices(threat, env.observation_space.shape), np.random.default_rng(a.seed0)
    points, labels, steps, queries = [], [], [0], [0]

    def at_state(x: np.ndarray, held: np.ndarray | None) -> None:
        steps[0] += 1
        if held is None or np.isnan(held).any():
            return
        queries[0] += 1
        if v.takes(victim, x, held)[0]:
            return
        pool = v.fed(x, v.random(rng, a.probes))
        queries[0] += len(pool)
        points.append(pool.reshape(len(pool), -1).astype(np.float32))
        labels.append(victim.query(pool).argmax(axis=1) == FASTER)

    drive_attack(env, victim, attack, objective, oracle, a.seed0, a.episodes, at_state)
    x, y = np.stack(points), np.stack(labels)
    np.savez_compressed(a.out, x=x, y=y)
    print(f"  seeds {a.seed0}-{a.seed0 + a.episodes - 1}: {steps[0]} steps, {len(x)} hard states (the held vertex would "
          f"fail its check), {a.probes} vertices each, {y.mean() * 100:.1f} % of them work; {queries[0]} probe queries "
          f"+ {oracle.total_queries} by the attack")


def fine_tune(a: argparse.Namespace, attack) -> torch.nn.Module:
    """A copy of the attack's picker network fitted further on the hard states of the .npz files."""
    data = [np.load(f) for f in a.data]
    x = np.concatenate([d["x"] for d in data])
    y = np.concatenate([d["y"] for d in data]).astype(np.float32)
    held_out = np.random.default_rng(0).random(len(x)) < 0.05  # whole states held out
    torch.manual_seed(0)
    net = copy.deepcopy(attack.picker.net).train()
    opt = torch.optim.Adam(net.parameters(), a.lr)
    tx, ty = torch.from_numpy(x[~held_out].reshape(-1, x.shape[-1])), torch.from_numpy(y[~held_out].reshape(-1))
    vx, vy = x[held_out], y[held_out]

    def top1(model: torch.nn.Module) -> float:
        with torch.no_grad():
            s = model(torch.from_numpy(vx.reshape(-1, vx.shape[-1]))).reshape(vy.shape)
        return float(vy[np.arange(len(vy)), s.argmax(dim=1).numpy()].mean())

    print(f"  fit data: {len(x)} hard states x {x.shape[1]} vertices ({y.mean() * 100:.1f} % work); held-out states "
          f"{int(held_out.sum())}: best-rated vertex works {top1(attack.picker.net) * 100:.1f} % (committed picker)")
    for epoch in range(a.epochs):
        for batch in torch.randperm(len(tx)).split(4096):
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net(tx[batch]).squeeze(1), ty[batch])
            opt.zero_grad()
            loss.backward()
            opt.step()
        print(f"    epoch {epoch}: held-out best-rated works {top1(net.eval()) * 100:.1f} %")
        net.train()
    return net.eval()


def judge(a: argparse.Namespace) -> None:
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    net = fine_tune(a, attack)
    v, rng = Vertices(threat, env.observation_space.shape), np.random.default_rng(0)
    hits, failed = {"committed picker": 0, "fine-tuned on hard states": 0, "any of the 64": 0}, [0]

    def at_state(x0: np.ndarray, held: np.ndarray | None) -> None:
        if held is None or np.isnan(held).any():
            return
        if v.takes(victim, x0, held)[0]:
            return
        failed[0] += 1
        pool = v.fed(x0, v.random(rng, 64))
        works = victim.query(pool).argmax(axis=1) == FASTER
        hits["committed picker"] += bool(works[int(attack.picker.scores(pool).argmax())])
        with torch.no_grad():
            hits["fine-tuned on hard states"] += bool(works[int(net(torch.from_numpy(pool.reshape(64, -1))).argmax())])
        hits["any of the 64"] += bool(works.any())

    drive_attack(env, victim, attack, objective, oracle, 900000, a.episodes, at_state)
    print(f"  tuning seeds 900000-{900000 + a.episodes - 1}: the held vertex failed its check on {failed[0]} steps; "
          "there the best-rated of 64 random vertices worked:")
    for name, n in hits.items():
        print(f"    {name}: {n / max(failed[0], 1) * 100:.1f} %")


def drive(a: argparse.Namespace) -> None:
    from zodrive.attacks.picker import Picker

    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    committed = attack.picker
    hard = Picker(fine_tune(a, attack), committed.candidates, committed.switch)
    ask, fresh = attack.ask, attack.fresh
    asked = [False]

    def ask_then_mark(*args, **kwargs):  # the product's check; a fresh vertex drawn after it is fed unasked
        asked[0] = True
        return ask(*args, **kwargs)

    def fresh_by_case(*args, **kwargs):
        attack.picker = hard if asked[0] else committed
        try:
            return fresh(*args, **kwargs)
        finally:
            attack.picker = committed

    def begin(x: np.ndarray, held: np.ndarray | None) -> None:
        asked[0] = False

    attack.ask, attack.fresh = ask_then_mark, fresh_by_case
    returns, actions = drive_counting(env, victim, attack, objective, oracle, a.episodes, begin)
    share = percent(actions)
    print(f"  vertex check, the fine-tuned copy choosing the vertices fed unasked: return {np.mean(returns):.2f} over "
          f"seeds 900000-{900000 + a.episodes - 1}, action share % (LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER) "
          f"{share}, {oracle.total_queries / actions.sum():.2f} queries/step")


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=["collect", "judge", "drive"])
    p.add_argument("model")
    p.add_argument("eps", type=float)
    p.add_argument("picker")
    p.add_argument("data", nargs="*")
    p.add_argument("--seed0", type=int, default=700000)
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--probes", type=int, default=512)
    p.add_argument("--out")
    p.add_argument("--epochs", type=int, default=5)
    p.add_argument("--lr", type=float, default=3e-4)
    a = p.parse_args()
    {"collect": collect, "judge": judge, "drive": drive}[a.mode](a)


if __name__ == "__main__":
    main()
