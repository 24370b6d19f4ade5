"""Where does a fine-tuned actor move away from the clone it started from? (issue 22, item 2)

Drives 5 tuning episodes (seeds 50000-50004) with each given actor checkpoint and, on the states it
visits, prints its mean action, the clone's (`models/ddpg-imitation`) and the continuous rules', the
mean absolute differences per dimension [acceleration, steering], and the steering's spread.
Actors are read without unpickling (plain weights of SB3's DDPG/TD3 actor, ReLU MLP, tanh output).
Usage: python studies/finetune-continuous/drift.py CHECKPOINT.zip [...]
"""
import sys
from pathlib import Path

import numpy as np
import torch as th

from zodrive.drivers.rules import ContinuousRules
from zodrive.policies.safe_load import read_plain
from zodrive.envs import load_preset, make_env


def actor(path: str):
    _, w = read_plain(Path(path))
    layers = [(w[f"actor.mu.{i}.weight"], w[f"actor.mu.{i}.bias"]) for i in (0, 2, 4)]

    def act(x: np.ndarray) -> np.ndarray:
        h = th.as_tensor(x, dtype=th.float32).reshape(len(x), -1)
        for k, (weight, bias) in enumerate(layers):
            h = h @ weight.T + bias
            h = th.relu(h) if k < len(layers) - 1 else th.tanh(h)
        return h.numpy()

    return act


preset = load_preset("continuous")
rules, clone = ContinuousRules(preset), actor("models/ddpg-imitation/model.zip")
for path in sys.argv[1:]:
    policy, env, states = actor(path), make_env(preset), []
    for seed in range(50000, 50005):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            states.append(obs)
            obs, _, terminated, truncated, _ = env.step(policy(obs[None])[0])
            done = terminated or truncated
    x = np.stack(states)
    a, c, t = policy(x), clone(x), rules.controls(x)
    print(path, f"{len(x)} states")
    print("  mean action", a.mean(0).round(3), "clone", c.mean(0).round(3), "rules", t.mean(0).round(3))
    print("  |a-rules|", np.abs(a - t).mean(0).round(3), "|clone-rules|", np.abs(c - t).mean(0).round(3),
          "|a-clone|", np.abs(a - c).mean(0).round(3))
    print("  steering std", a[:, 1].std().round(3), "clone", c[:, 1].std().round(3), "rules", t[:, 1].std().round(3))
