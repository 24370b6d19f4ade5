"""Trace one shielded episode step by step: what the driver proposed, what the shield let through,
and the room test on the observation the policy saw and on the true one (a diagnostic, not a
product command). Used to diagnose the crashes of shield v2 under the learned adversary
(results/shield/README.md, "From v2 to v4"):

    python studies/shield/trace_episode.py models/dqn-driver ATTACK EPS SEED shield@0.02 [--last N] [--every K]

ATTACK: `none`, a registry/config name, or `learned:DIR`; `--transfer` runs an adversary trained
against another shield version (the evaluation refuses it). Columns: own / left / right = the
lane's room beyond the safe gap [m] on the true / seen observation; safe = the shield's accepted
actions (L I R F S) on the seen / true observation; gap = the simulator's gap to the car ahead.
Both sides of every column are the shield's pessimistic test at EPS, so the true side is stricter
than the plain rules' test (eps 0) its guarantee is stated against.
"""

from __future__ import annotations

import argparse

import numpy as np

from zodrive.policies.resolve import load_victim
from zodrive.system import make_policy_env
from zodrive.attacks.spec import load_attack
from zodrive.defense import make_defense
from zodrive.envs import load_preset
from zodrive.evaluation.rollout import act, find_attack_wrapper

NAMES = ("LEFT", "IDLE", "RIGHT", "FASTER", "SLOWER")


def marks(safe: np.ndarray) -> str:
    return "".join(c if ok else "." for c, ok in zip("LIRFS", safe))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("model", "attack", "eps", "seed", "defense"):
        p.add_argument(name)
    p.add_argument("--last", type=int, default=40, help="print the last N steps")
    p.add_argument("--every", type=int, default=1, help="print every K-th step")
    p.add_argument("--show", type=int, nargs="*", default=[], help="print the true and the seen observation "
                   "(physical units) at these steps")
    p.add_argument("--transfer", action="store_true", help="run an adversary trained against another shield version")
    a = p.parse_args()
    if a.transfer:
        import zodrive.attacks.learned as learned

        learned.check_adversary = lambda *args, **kwargs: None
    preset = load_preset("discrete")
    spec = None if a.attack == "none" else load_attack(a.attack, [f"eps={a.eps}"])
    policy, env = make_policy_env(a.model, preset, spec, defense=a.defense)
    driver, shield = load_victim(a.model, preset), make_defense(a.defense, preset)
    wrapper = find_attack_wrapper(env)
    obs, _ = env.reset(seed=int(a.seed))
    rows, done, t = [], False, 0
    while not done:
        true = wrapper.clean_obs if wrapper is not None else obs
        action = int(act(policy, obs, env.action_space))
        proposed = int(np.argmax(driver.query(obs[None])[0]))
        ego = env.unwrapped.vehicle
        front, _ = ego.road.neighbour_vehicles(ego, ego.lane_index)
        gap = front.position[0] - ego.position[0] if front else np.inf
        rt, rs = shield.rules.rooms(true[None]), shield.rules.rooms(obs[None])
        if t in a.show:
            np.set_printoptions(precision=2, suppress=True)
            print(f"t={t} true:\n{true * shield.rules.scale}\nseen:\n{obs * shield.rules.scale}")
        if t % a.every == 0:
            rows.append(f"t={t:3d} v={ego.speed:5.1f} lane={ego.lane_index[2]}->{ego.target_lane_index[2]} "
                        f"vy={ego.velocity[1]:5.2f} gap={gap:6.1f} own={rt['own'][0]:6.1f}/{rs['own'][0]:6.1f} "
                        f"left={rt['left'][0]:6.1f}/{rs['left'][0]:6.1f} right={rt['right'][0]:6.1f}/{rs['right'][0]:6.1f} proposed={NAMES[proposed]:6s} "
                        f"action={NAMES[action]:6s} safe={marks(shield.safe(obs[None])[0])}/{marks(shield.safe(true[None])[0])}")
        obs, _, terminated, truncated, info = env.step(action)
        done, t = terminated or truncated, t + 1
    print("\n".join(rows[-a.last:]))
    print(f"end after {t} steps, crashed={bool(info.get('crashed'))}")


if __name__ == "__main__":
    main()
