"""Train one zoo policy with plain stable-baselines3 (no zodrive), as a researcher would.

The zoo is the first user of "bring your own model": each policy is an SB3 zip made here by SB3
alone, then benched by `zodrive bench`. DQN with highway-env's documented SB3 settings (two
256-unit layers, learning rate 5e-4, buffer 15,000, batch 32, gamma 0.8, target update every 50
steps) on one environment, so that a run fits on one core. Checkpoints every `--every` steps are
kept so that the one to ship is chosen on tuning seeds, never on the evaluation seeds.

`--start-from ZIP` continues a finished run instead: its weights and target network, a new replay
buffer that SB3's warm-up fills with 1,000 random-action steps before learning resumes, `--lr`,
and exploration held at the recipe's final 0.05; checkpoints are named by the total step count.

`--fast-env` trains on zodrive's copy of the scenario instead (its preset: highway-env's class and
defaults with the exact FastKinematics observer and closest-lane search): the same episodes and so the
same weights, from fewer CPU seconds (intersection, attention, 600 steps: the same SHA-256 of the
weights, 22.9 steps/s against 15.4). The script then needs zodrive; the SB3 zip it writes does not.

Run: python zoo/train.py --scenario highway-fast --seed 0 --out models/zoo/highway-fast-dqn/seed-0
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import highway_env  # noqa: F401  (registers the highway-env scenarios)
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.monitor import Monitor

#: zodrive preset -> the highway-env id a user trains on (same class, same defaults)
ENV_IDS = {"highway-fast": "highway-fast-v0", "merge": "merge-v1", "roundabout": "roundabout-v1",
           "intersection": "intersection-v2"}

DEFAULTS = {"steps": 20_000, "every": 2_000, "gamma": 0.8, "net": "mlp", "lr": 5e-4, "batch": 32, "target_update": 50,
            "n_steps": 1}
"""The recipe's settings a run may change (zoo/card.py writes the ones a run changed into its command)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=sorted(ENV_IDS), required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=DEFAULTS["steps"])
    parser.add_argument("--every", type=int, default=DEFAULTS["every"], help="checkpoint interval in steps")
    parser.add_argument("--gamma", type=float, default=DEFAULTS["gamma"],
                        help="discount (0.8: highway-env's documented setting, a horizon of about 5 decisions)")
    parser.add_argument("--net", choices=("mlp", "attention"), default=DEFAULTS["net"],
                        help="mlp: two 256-unit layers on the flattened table; attention: zoo/ego_attention.py "
                             "then two 64-unit layers (its zips load in zodrive with PYTHONPATH=zoo and --trust-model)")
    parser.add_argument("--lr", type=float, default=DEFAULTS["lr"], help="learning rate (default: %(default)s)")
    parser.add_argument("--batch", type=int, default=DEFAULTS["batch"], help="minibatch size (default: %(default)s)")
    parser.add_argument("--target-update", type=int, default=DEFAULTS["target_update"],
                        help="steps between target-network updates (default: %(default)s)")
    parser.add_argument("--n-steps", type=int, default=DEFAULTS["n_steps"],
                        help="decisions per bootstrapped return (SB3's n-step DQN; default: %(default)s)")
    parser.add_argument("--start-from", type=Path,
                        help="continue this finished run's zip for --steps more steps (exploration held at 0.05)")
    parser.add_argument("--fast-env", action="store_true",
                        help="train on zodrive's exact, faster copy of the scenario (same weights, fewer CPU seconds)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    done = [p for p in (args.out / "model.zip", args.out / "final.zip") if p.exists()]  # final.zip: a chosen run
    if done:
        print(f"{done[0]} exists: skipped")
        return
    args.out.mkdir(parents=True, exist_ok=True)
    if args.fast_env:
        from zodrive.envs import load_preset, make_env

        env = Monitor(make_env(load_preset(args.scenario)), str(args.out / "monitor"))
    else:
        env = Monitor(gym.make(ENV_IDS[args.scenario]), str(args.out / "monitor"))
    if args.net == "attention":
        from ego_attention import EgoAttention  # zoo/ is on sys.path when this script runs
        policy_kwargs = dict(features_extractor_class=EgoAttention, net_arch=[64, 64])
    else:
        policy_kwargs = dict(net_arch=[256, 256])
    if args.start_from is None:
        model = DQN("MlpPolicy", env, policy_kwargs=policy_kwargs, learning_rate=args.lr,
                    buffer_size=15_000, learning_starts=200, batch_size=args.batch, gamma=args.gamma, train_freq=1,
                    gradient_steps=1, n_steps=args.n_steps, target_update_interval=args.target_update,
                    exploration_fraction=0.7, seed=args.seed, device="cpu", verbose=0)
    else:  # the same recipe, continued: SB3 rebuilds the schedules from these values
        model = DQN.load(args.start_from, env=env, device="cpu", seed=args.seed, learning_rate=args.lr,
                         exploration_initial_eps=0.05, exploration_final_eps=0.05)
        recipe = {"gamma": (model.gamma, args.gamma), "batch": (model.batch_size, args.batch),
                  "target-update": (model.target_update_interval, args.target_update),
                  "n-steps": (model.n_steps, args.n_steps),
                  "net": (model.policy_kwargs.get("net_arch"), policy_kwargs["net_arch"])}
        differ = [name for name, (theirs, mine) in recipe.items() if theirs != mine]
        if differ:  # the zip's settings win in SB3's load, so a differing flag would be ignored silently
            raise SystemExit(f"{args.start_from} was not trained with these --{', --'.join(differ)}")
        model.learning_starts = model.num_timesteps + 1_000  # SB3's warm-up refills the new, empty buffer first
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, reset_num_timesteps=args.start_from is None,
                callback=CheckpointCallback(args.every, str(args.out / "checkpoints"), name_prefix="step"))
    model.save(args.out / "model")
    (args.out / "train.json").write_text(json.dumps(
        {"script": "zoo/train.py", "scenario": args.scenario, "env_id": ENV_IDS[args.scenario], "fast_env": args.fast_env,
         "algo": "dqn", "steps": args.steps, "every": args.every, "seed": args.seed, "gamma": args.gamma, "net": args.net,
         "lr": args.lr, "batch": args.batch, "target_update": args.target_update, "n_steps": args.n_steps,
         **({"start_from": str(args.start_from), "total_steps": model.num_timesteps} if args.start_from else {}),
         "wall_time_s": round(time.perf_counter() - start, 1)}, indent=2) + "\n")
    print(f"saved {args.out / 'model.zip'}")


if __name__ == "__main__":
    main()
