"""Two states from results/certify-exact, shown on stable-baselines3's own network.

    python studies/exact-sandwich/examples.py [results/certify-exact]

1. CROWN silent, the exact check attackable, no attack (random search, ZO-SignSGD, PGD) won: the
   state is rebuilt (the same clean episodes), the attacks are re-run on it alone with the seed
   certify gave it, the exact check's counterexample is recomputed and replayed through
   `stable_baselines3.DQN.load(...).predict` and its Q-network.
2. CROWN silent, the exact check proved robust (if any such state exists in any certify.json):
   CROWN's margin bound beside the exact verdict, and SB3's action on the box's corners and random
   points (a consistency check, not a proof: the MILP is the proof).

The models are this repository's own zips: SB3's loader is used on them directly.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from zodrive.attacks.spec import AttackSpec
from zodrive.envs import scenario
from zodrive.evaluation.certify import certify, episode_states, sandwich, threat_box
from zodrive.evaluation.exact import exact
from zodrive.policies.loading import load_network
from zodrive.policies.resolve import resolve_scenario
from zodrive.policies.victims import network_victim

np.set_printoptions(precision=4, suppress=True, linewidth=120)
ORDER = ("dqn-driver", "dqn-close", "dqn-imitation", "dqn-robust", "dqn-sa",
         "zoo-highway-fast-dqn-seed-0", "zoo-highway-fast-dqn-seed-1", "zoo-highway-fast-dqn-seed-2")


def _first(found: dict[str, dict[str, Any]], want: str) -> tuple[str, int, int] | None:
    """(folder, row, state) of the first state with CROWN silent and exact verdict `want` ("a": no attack won it)."""
    for name in [n for n in ORDER if n in found]:
        for r, row in enumerate(found[name]["rows"]):
            per = row["per_state"]
            for i, (crown, verdict) in enumerate(zip(per["crown"], per["exact"])):
                if crown == "0" and verdict == want and (want != "a" or all(
                        per[s["attack"]][i] == "0" for s in row["attacks"])):
                    return name, r, i
    return None


def _setup(result: dict[str, Any]) -> tuple[Any, dict[str, Any], Any, np.ndarray, np.ndarray]:
    model = result["model"]
    preset, _ = resolve_scenario(model, None, [])
    network = load_network(model, preset)
    victim = network_victim(network.net, network.kind, network.obs_shape)
    states = episode_states(preset, victim, result["seed"], result["episodes"])
    env = scenario(preset)
    mask = AttackSpec(eps=0.01).threat(env.features, env.bounds).mask(states.shape[1:]).astype(np.float64)  # as box_of
    return network, preset, victim, states, mask


def _sb3(model: str) -> Any:
    from stable_baselines3 import DQN

    path = Path(model)
    return DQN.load(path / "model.zip" if path.is_dir() else path, device="cpu")


def _q(sb3: Any, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return sb3.q_net(torch.as_tensor(obs[None], dtype=torch.float32)).numpy()[0]


def attackable_missed(found: dict[str, dict[str, Any]]) -> None:
    hit = _first(found, "a")
    if hit is None:
        print("1. no state with CROWN silent, exact attackable and no attack winning in any certify.json")
        return
    name, r, i = hit
    result, row = found[name], found[name]["rows"][r]
    eps, seed = row["eps"], result["seed"]
    print(f"1. {result['model']} ({result['preset']}), eps {eps:g}, state {i} of {len(row['per_state']['exact'])} "
          f"(clean episodes from seed {seed}): CROWN silent, exact attackable, missed by "
          + ", ".join(s["attack"] for s in row["attacks"]))
    network, preset, victim, states, mask = _setup(result)
    env = scenario(preset)
    x = states[i:i + 1]
    cert = certify(network.net, network.kind, x, eps, mask, *env.bounds)
    print(f"   rebuilt: CROWN certified {bool(cert.certified[0])}, margin lower bound {cert.bound[0]:.4f}")
    for side in row["attacks"]:
        again, won = sandwich(x, cert.certified, side["attack"], eps, victim, preset, seed + i, 0.2)
        print(f"   {side['attack']} re-run on this state alone (seed {seed + i}): won {bool(won[0])}, "
              f"{again['queries_per_state']:.0f} queries")
    ex = exact(network.net, network.kind, x, eps, mask, *env.bounds, time_limit=60)
    print(f"   exact: {ex.verdict[0]} in {ex.seconds[0]:.3f} s")
    point = ex.counterexample[0].reshape(x.shape[1:]).astype(np.float32)
    lo, hi = threat_box(x.reshape(1, -1).astype(np.float64), eps, mask.reshape(-1), *env.bounds)
    inside = bool((point.reshape(-1) >= lo[0]).all() and (point.reshape(-1) <= hi[0]).all())
    delta = point - x[0]
    print(f"   counterexample inside the threat box: {inside}; max |delta| {np.abs(delta).max():.6f} (eps {eps:g}); "
          f"frozen features moved: {bool(np.abs(delta[mask == 0]).max(initial=0) > 0)}")
    sb3 = _sb3(result["model"])
    clean_action, _ = sb3.predict(x[0], deterministic=True)
    moved_action, _ = sb3.predict(point, deterministic=True)
    print(f"   stable_baselines3 DQN.load(...).predict: clean action {int(clean_action)}, at the counterexample "
          f"{int(moved_action)}")
    print(f"   SB3 Q-values clean:          {_q(sb3, x[0])}")
    print(f"   SB3 Q-values counterexample: {_q(sb3, point)}")
    print(f"   clean observation:\n{x[0]}\n   delta (counterexample - clean):\n{delta}")


def robust_where_crown_silent(found: dict[str, dict[str, Any]]) -> None:
    hit = _first(found, "r")
    if hit is None:
        print("2. no state with CROWN silent and exact robust in any certify.json")
        return
    name, r, i = hit
    result, row = found[name], found[name]["rows"][r]
    eps = row["eps"]
    total = sum(sum(c == "0" and v == "r" for c, v in zip(rw["per_state"]["crown"], rw["per_state"]["exact"]))
                for f in found.values() for rw in f["rows"])
    print(f"2. {result['model']} ({result['preset']}), eps {eps:g}, state {i}: CROWN silent, exact robust "
          f"({total} such (state, eps) pairs in all certify.json files)")
    network, preset, _, states, mask = _setup(result)
    env = scenario(preset)
    x = states[i:i + 1]
    cert = certify(network.net, network.kind, x, eps, mask, *env.bounds)
    ex = exact(network.net, network.kind, x, eps, mask, *env.bounds, time_limit=60)
    print(f"   CROWN margin lower bound {cert.bound[0]:.6f} (certified needs > 1e-4); exact: {ex.verdict[0]} in "
          f"{ex.seconds[0]:.3f} s")
    lo, hi = threat_box(x.reshape(1, -1).astype(np.float64), eps, mask.reshape(-1), *env.bounds)
    rng = np.random.default_rng(0)
    corners = np.where(rng.random((20000, lo.shape[1])) < 0.5, lo[0], hi[0])
    uniform = lo[0] + (hi[0] - lo[0]) * rng.random((20000, lo.shape[1]))
    points = np.concatenate([corners, uniform]).astype(np.float32).reshape(-1, *x.shape[1:])
    sb3 = _sb3(result["model"])
    clean_action, _ = sb3.predict(x[0], deterministic=True)
    actions, _ = sb3.predict(points, deterministic=True)
    print(f"   SB3 predict: clean action {int(clean_action)}; on 20000 random corners and 20000 uniform points of the "
          f"box: {int((actions != clean_action).sum())} change it")
    q = _q(sb3, x[0])
    print(f"   SB3 Q-values clean: {q} (gap to the runner-up {np.sort(q)[-1] - np.sort(q)[-2]:.4f})")


def main(folder: Path) -> int:
    found = {p.parent.name: json.loads(p.read_text()) for p in sorted(folder.glob("*/certify.json"))}
    attackable_missed(found)
    robust_where_crown_silent(found)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/certify-exact")))
