"""A probe, not a product command: does a perturbation that makes the victim take FASTER at one step
still do it at the next? (issue 23 item 1: why the fitted start does not transfer to models/dqn-close)

The victim drives clean episodes on tuning seeds 900000.. (or, with --under DIR, under a learned adversary:
the states it leads to); at every step it is also queried on K random vertices of the eps-ball (drawn
afresh each step) and on the previous step's vertices that worked. Printed, over the steps whose clean
action is not FASTER: the share where the adversary's own perturbation makes it take FASTER (--under), the share of vertices that make it take FASTER (what one
blind guess achieves), the share of steps where at least one of the K does (what a search finds), and,
for the vertices that worked at step t, the share that still work at step t + 1 (whether a perturbation
found at one state carries to the next, 1 s later and nearly the same state: what an adversary that
maps states to perturbations with no query needs). 0 queries are spent on any attack; nothing is written.

    python studies/learned-adversary/pilots/decision-focused/vertex_persistence.py MODEL EPS [--episodes 10] [--k 64]
        [--under ADVERSARY_DIR]
"""

from __future__ import annotations

import argparse

import numpy as np

from zodrive.policies.resolve import load_victim
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates
from zodrive.attacks.spec import load_attack
from zodrive.envs import attack_context, load_preset, make_env


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("model")
    p.add_argument("eps", type=float)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--k", type=int, default=64)
    p.add_argument("--under", help="a learned adversary's folder (attack-train): drive under it")
    a = p.parse_args()
    preset = load_preset("discrete")
    ctx = attack_context(preset)
    victim = load_victim(a.model, preset)
    env = make_env(preset)
    spec = load_attack("random-search", [f"eps={a.eps}"])
    attack, _, _ = spec.build(victim, ctx["features"], ctx["bounds"], ctx["n_actions"], ctx["action_names"])
    threat, faster = attack.threat, ctx["action_names"].index("FASTER")
    adversary = LearnedAdversary(threat, adversary=a.under) if a.under else None
    rng = np.random.default_rng(0)
    blind, found, own, kept, worked = [], [], [], 0, 0
    for e in range(a.episodes):
        obs, _ = env.reset(seed=900000 + e)
        done, previous = False, None  # the previous step's vertices that made it take FASTER
        while not done:
            x = np.asarray(obs, np.float32)[None]
            mask = threat.mask(x.shape[1:])
            signs = rng.choice(np.array([-1.0, 1.0], np.float32), size=(a.k, *x.shape[1:])) * mask
            vertices = threat.project(x + a.eps * signs, np.repeat(x, a.k, axis=0))
            fed = x if adversary is None else apply_action(
                threat, x, adversary.actions(x.reshape(1, -1)), free_coordinates(threat, x.shape[1:]))
            out = victim.query(np.concatenate([x, fed, vertices]))
            clean, taken = int(out[0].argmax()), int(out[1].argmax())
            hit = out[2:].argmax(1) == faster
            if clean != faster:
                own.append(taken == faster)
                blind.append(hit.mean())
                found.append(hit.any())
                if previous is not None and len(previous):
                    again = victim.query(threat.project(x + previous, np.repeat(x, len(previous), axis=0)))
                    kept += int((again.argmax(1) == faster).sum())
                    worked += len(previous)
            previous = (a.eps * signs[hit]) if clean != faster else None
            obs, _, terminated, truncated, _ = env.step(taken)
            done = terminated or truncated
    print(f"{a.model} eps {a.eps}, driving {'under ' + a.under if a.under else 'clean'}: {len(blind)} steps with a "
          f"clean action other than FASTER, {a.k} random vertices each")
    if a.under:
        print(f"  the adversary's own perturbation makes it take FASTER: {np.mean(own):.1%}")
    print(f"  vertices that make it take FASTER: {np.mean(blind):.1%}; steps where at least one of {a.k} does: "
          f"{np.mean(found):.1%}")
    print(f"  of the {worked} vertices that did at step t, still doing it at step t + 1: "
          f"{kept / max(worked, 1):.1%}")


if __name__ == "__main__":
    main()
