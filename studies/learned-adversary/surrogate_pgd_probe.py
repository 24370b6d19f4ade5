"""A probe, not a product command: how far is a black-box attack with 0 victim queries at attack time
from white-box PGD, once the amortization gap is removed? (issue 23 item 1, "What is left")

Black-box phase (counted): the victim drives ROUNDS x 10 training episodes (seeds 0..), round 0 clean,
later rounds under the attack below; at every state it is queried on the fed observation and on 4 random
points of the eps-ball (as `agents.amortized`), and a surrogate (25-256-256-5 MLP, MSE on the centred
scores) is fitted to every answer so far. Attack time: zodrive's own PGD (target FASTER, patience 10)
runs against the surrogate (`Victim` with the surrogate as query and gradient), and its perturbation is
fed to the victim: 0 victim queries per step. Evaluated on tuning seeds 900000.. (not the 100000 seeds).

    python studies/learned-adversary/surrogate_pgd_probe.py MODEL EPS [--rounds 3] [--episodes 30]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from zodrive.policies.resolve import load_victim
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.spec import load_attack
from zodrive.attacks.victim import Victim
from zodrive.envs import attack_context, load_preset, make_env


def drive(victim: Victim, env, seed: int, attack=None, record: list | None = None,
          rng: np.random.Generator | None = None, threat=None, eps: float = 0.0) -> tuple[float, bool]:
    """One episode; `attack(x) -> x_adv` or None (clean). With `record`, every fed observation and 4
    random eps-ball points are queried and kept (the surrogate's data)."""
    obs, _ = env.reset(seed=seed)
    total, done, info = 0.0, False, {}
    while not done:
        x = np.asarray(obs, np.float32)[None]
        fed = x if attack is None else attack(x)
        if record is not None:
            noise = rng.uniform(-1, 1, (4, *x.shape[1:])).astype(np.float32) * threat.mask(x.shape[1:])
            batch = np.concatenate([fed, threat.project(x + eps * noise, np.repeat(x, 4, axis=0))])
            out = victim.query(batch)
            record.append((batch, out))
            action = int(out[0].argmax())
        else:
            action = int(victim.query(fed)[0].argmax())
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        done = terminated or truncated
    return total, bool(info.get("crashed"))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("model")
    p.add_argument("eps", type=float)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--episodes", type=int, default=30)
    a = p.parse_args()
    torch.manual_seed(0)
    preset = load_preset("discrete")
    ctx = attack_context(preset)
    victim = load_victim(a.model, preset)
    env = make_env(preset)
    spec = load_attack("pgd", [f"eps={a.eps}", "patience=10"])  # as the committed white-box PGD cells
    surrogate = torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(25, 256), torch.nn.ReLU(),
                                    torch.nn.Linear(256, 256), torch.nn.ReLU(), torch.nn.Linear(256, 5))
    proxy = Victim(query=lambda b: surrogate(torch.as_tensor(b, dtype=torch.float32)).detach().numpy(),
                   kind="discrete", obs_shape=(5, 5), differentiable=lambda x: surrogate(x.float()))
    pgd, objective, _ = spec.build(proxy, ctx["features"], ctx["bounds"], ctx["n_actions"], ctx["action_names"])
    threat = pgd.threat

    def attack(x: np.ndarray) -> np.ndarray:
        return pgd.perturb(x, QueryOracle(proxy), objective).x_adv

    rng, data, queries = np.random.default_rng(0), [], 0
    for r in range(a.rounds):
        returns = [drive(victim, env, r * 10 + e, None if r == 0 else attack, data, rng, threat, a.eps)[0]
                   for e in range(10)]
        X = torch.as_tensor(np.concatenate([b for b, _ in data]).reshape(-1, 25))
        Y = torch.as_tensor(np.concatenate([o for _, o in data]))
        Y = Y - Y.mean(1, keepdim=True)
        queries = len(X)
        opt, scale = torch.optim.Adam(surrogate.parameters(), lr=1e-3), Y.std()
        for _ in range(20):
            for i in torch.randperm(len(X)).split(256):
                loss = (((surrogate(X[i]) - Y[i]) / scale) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
        with torch.no_grad():
            agree = float((surrogate(X).argmax(1) == Y.argmax(1)).float().mean())
        print(f"round {r}: victim return {np.mean(returns):.2f} over 10 training episodes, {queries} victim "
              f"queries so far, surrogate agreement {agree:.1%}", flush=True)
    results = [drive(victim, env, 900000 + e, attack) for e in range(a.episodes)]
    ret = np.array([r for r, _ in results])
    print(f"{a.model} eps {a.eps}, surrogate PGD (0 victim queries per step), seeds 900000-{900000 + a.episodes - 1}: "
          f"mean return {ret.mean():.2f}, collisions {np.mean([c for _, c in results]):.1%}")


if __name__ == "__main__":
    main()
