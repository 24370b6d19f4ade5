"""Attack any SB3 model in any gymnasium environment with zodrive, in your own loop.

Here: a DQN on CartPole (no highway-env involved). The attack sees only the model's query
function; the wrapper feeds the policy the attacked observation and counts every query.
Run: python examples/own_sb3_loop.py
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from stable_baselines3 import DQN

import zodrive


def main(train_steps: int = 20_000, episodes: int = 5) -> dict[str, float]:
    """Train, attack, and return the mean clean and attacked returns, the share of attacked
    steps whose decision flipped and the queries spent."""
    model = DQN("MlpPolicy", gym.make("CartPole-v1"), learning_starts=1000, exploration_fraction=0.2,
                seed=0).learn(train_steps)
    # the attacker queries the model (observations in, Q-values out) and nothing else; the wrapper reads
    # the threat model from the env: CartPole has no FASTER, so the attack is untargeted; L-inf 0.1
    attacked = zodrive.AttackWrapper(gym.make("CartPole-v1"), model, attack="random-search", eps=0.1)
    oracle = attacked.oracle
    returns = {}
    for name, env in (("clean", gym.make("CartPole-v1")), ("attacked", attacked)):
        totals = []
        flips = []
        for seed in range(episodes):
            obs, info = env.reset(seed=seed)
            done, total = False, 0.0
            while not done:
                action = int(model.predict(obs, deterministic=True)[0])
                if "clean_obs" in info:  # what the policy would have done on the true observation
                    flips.append(action != int(model.predict(info["clean_obs"], deterministic=True)[0]))
                obs, reward, terminated, truncated, info = env.step(action)
                total, done = total + float(reward), terminated or truncated
            totals.append(total)
        returns[name] = float(np.mean(totals))
    returns["flipped"] = float(np.mean(flips))  # share of attacked steps where the policy acted otherwise
    returns["queries"] = float(oracle.total_queries)
    print(f"clean return {returns['clean']:.1f}, attacked {returns['attacked']:.1f}, decisions changed on "
          f"{returns['flipped']:.0%} of attacked steps, {oracle.total_queries} queries to the policy")
    return returns


if __name__ == "__main__":
    main()
