"""A probe (issue 23, item 1; not a product command): on the same states, where does random search with the
fallback target (`configs/attacks/random-search-fallback.yaml`, hundreds of queries per step) reach FASTER and
the fitted start (0 queries per step) not? The victim drives under random search; at every state the fitted
adversary's perturbation is also fed to the victim, for analysis only (not counted, not driven). Steps are
split by how far they are from the episode's end, since a crash ends it. Seeds --seed0.., nothing written.

    python studies/learned-adversary/pilots/one-query/critical.py MODEL EPS ADVERSARY_DIR [--episodes 20]
"""

from __future__ import annotations

import numpy as np

from common import FASTER, arguments, setup
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates
from zodrive.attacks.spec import load_attack
from zodrive.envs import attack_context

SLOWER = 4


def main() -> None:
    p = arguments(20, "adversary")
    p.add_argument("--seed0", type=int, default=900000)
    a = p.parse_args()
    preset, victim, env, threat = setup(a.model, a.eps)
    ctx = attack_context(preset)
    spec = load_attack("random-search-fallback", [f"eps={a.eps}"])
    attack, objective, oracle = spec.build(victim, ctx["features"], ctx["bounds"], ctx["n_actions"], ctx["action_names"])
    adversary = LearnedAdversary(threat, adversary=a.adversary)
    free = free_coordinates(threat, env.observation_space.shape)
    rows, returns = [], []  # (steps to the end, search's action, fitted's action, clean action)
    for e in range(a.episodes):
        seed = a.seed0 + e
        obs, _ = env.reset(seed=seed)
        attack.reseed(seed)
        oracle.begin_episode()
        done, total, episode = False, 0.0, []
        while not done:
            x = np.asarray(obs, np.float32)[None]
            act = int(np.argmax(attack.perturb(x, oracle, objective).adv_outputs[0]))
            fitted = int(victim.query(apply_action(threat, x, adversary.actions(x.reshape(1, -1)), free))[0].argmax())
            episode.append((act, fitted, int(victim.query(x)[0].argmax())))
            obs, reward, terminated, truncated, _ = env.step(act)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        rows += [(len(episode) - i, *r) for i, r in enumerate(episode)]
    r = np.array(rows)
    print(f"{a.model} eps {a.eps}, seeds {a.seed0}-{a.seed0 + a.episodes - 1}, driven by random search with the "
          f"fallback (return {np.mean(returns):.2f}); the fitted adversary {a.adversary} on the same states:")
    for label, sel in (("all steps", r[:, 0] > 0), ("the last 10 steps", r[:, 0] <= 10),
                       ("the last 3 steps", r[:, 0] <= 3), ("earlier steps", r[:, 0] > 10)):
        s = r[sel]
        both = ((s[:, 1] == FASTER) & (s[:, 2] == FASTER)).mean()
        print(f"  {label} ({len(s)}): FASTER from search {np.mean(s[:, 1] == FASTER):.1%}, from the fitted "
              f"{np.mean(s[:, 2] == FASTER):.1%}, from both {both:.1%}; SLOWER from search "
              f"{np.mean(s[:, 1] == SLOWER):.1%}, from the fitted {np.mean(s[:, 2] == SLOWER):.1%}, clean "
              f"{np.mean(s[:, 3] == SLOWER):.1%}")


if __name__ == "__main__":
    main()
