"""Shared by the probes of this folder (not product code): the victim, its threat model, and a driving loop
in which an attacker picks each step's fed observation from the clean one and from whether the victim took
the target action at the last step (the one answer a one-query attacker gets)."""

from __future__ import annotations

import argparse
from typing import Any, Callable

import numpy as np

from zodrive.policies.resolve import load_victim
from zodrive.attacks.spec import load_attack
from zodrive.attacks.threat import ThreatModel
from zodrive.attacks.victim import Victim
from zodrive.envs import attack_context, load_preset, make_env

FASTER = 3
Chooser = Callable[[np.ndarray, dict[str, Any]], np.ndarray]
"""(clean observation (1, *obs), per-episode memory) -> the observation fed to the victim; the memory
holds "missed" (the victim did not take the target at the last step), "action" (the action it took)
and whatever the chooser keeps."""


def arguments(episodes: int = 30, folder: str | None = None) -> argparse.ArgumentParser:
    """The arguments every probe here takes: the victim MODEL, its L-inf EPS, the trained `folder` it reads
    if any (e.g. "picker", "adversary") and --episodes; a probe adds its own."""
    p = argparse.ArgumentParser()
    p.add_argument("model")
    p.add_argument("eps", type=float)
    if folder is not None:
        p.add_argument(folder)
    p.add_argument("--episodes", type=int, default=episodes)
    return p


def setup(model: str, eps: float) -> tuple[dict[str, Any], Victim, Any, ThreatModel]:
    """The discrete preset, the victim, one environment and the L-inf threat model every attack uses."""
    preset = load_preset("discrete")
    ctx = attack_context(preset)
    victim = load_victim(model, preset)
    spec = load_attack("random-search", [f"eps={eps}"])  # only for its threat model
    attack, _, _ = spec.build(victim, ctx["features"], ctx["bounds"], ctx["n_actions"], ctx["action_names"])
    return preset, victim, make_env(preset), attack.threat


def vertex_check(model: str, eps: float, picker: str) -> tuple[Victim, Any, ThreatModel, Any, Any, Any]:
    """The victim, one environment, the threat model, and the product's `--attack vertex-check:PICKER` at `eps`
    built for them: (victim, env, threat, attack, objective, oracle)."""
    from zodrive.envs import attack_context as context

    preset, victim, env, threat = setup(model, eps)
    ctx = context(preset)
    attack, objective, oracle = load_attack(f"vertex-check:{picker}", [f"eps={eps}"]).build(
        victim, ctx["features"], ctx["bounds"], ctx["n_actions"], ctx["action_names"])
    return victim, env, threat, attack, objective, oracle


def on_vertices(threat: ThreatModel, shape: tuple[int, ...]) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """fed(x, deltas): the observations (k, *obs) fed at clean observation x (1, *obs) for flat vertices
    `deltas` (k, dim), projected into the threat model."""
    dim = int(np.prod(shape))

    def fed(x: np.ndarray, deltas: np.ndarray) -> np.ndarray:
        base = np.repeat(x.reshape(1, dim), len(deltas), axis=0)
        return threat.project((base + deltas).reshape(-1, *shape), base.reshape(-1, *shape))
    return fed


class Vertices:
    """The L-inf ball's vertices for the probes: `random(rng, k)` draws k flat vertices (every free coordinate
    at +-eps, from `rng`), `fed(x, deltas)` is what is fed for them at clean observation x (1, *obs), projected,
    and `takes(victim, x, deltas)` whether the victim takes FASTER on each (uncounted: analysis only)."""

    def __init__(self, threat: ThreatModel, shape: tuple[int, ...]) -> None:
        self.mask = threat.mask(shape).reshape(-1)
        self.eps, self.dim = np.float32(threat.eps), self.mask.size
        self.fed = on_vertices(threat, shape)

    def random(self, rng: np.random.Generator, k: int) -> np.ndarray:
        return self.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=(k, self.dim)) * self.mask

    def takes(self, victim: Victim, x: np.ndarray, deltas: np.ndarray) -> np.ndarray:
        return victim.query(self.fed(x, deltas)).argmax(axis=1) == FASTER


def drive_attack(env: Any, victim: Victim, attack: Any, objective: Any, oracle: Any, seed0: int, episodes: int,
                 at_state: Callable[[np.ndarray, np.ndarray | None], None],
                 after: Callable[[Any], None] = lambda result: None) -> list[float]:
    """`episodes` episodes from seed `seed0` with a product attack feeding the victim (its own counted queries
    and random streams). `at_state(x, held)` sees each clean observation (1, *obs) and the vertex the attack
    holds (None at an episode's start) before the attack acts, `after(result)` each step's AttackResult.
    Returns the episodes' returns."""
    returns = []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed0 + e)
        attack.reseed(seed0 + e)
        oracle.begin_episode()
        attack.begin_episode()
        total, done = 0.0, False
        while not done:
            x = np.asarray(obs, np.float32)[None]
            at_state(x, attack.carried)
            result = attack.perturb(x, oracle, objective)
            after(result)
            obs, reward, terminated, truncated, _ = env.step(int(victim.query(result.x_adv)[0].argmax()))
            total += reward
            done = terminated or truncated
        returns.append(total)
    return returns


def drive_counting(env: Any, victim: Victim, attack: Any, objective: Any, oracle: Any, episodes: int,
                   at_state: Callable[[np.ndarray, np.ndarray | None], None] = lambda x, held: None,
                   after: Callable[[Any], None] = lambda result: None) -> tuple[list[float], np.ndarray]:
    """`drive_attack` on tuning seeds 900000+, also counting the action the victim takes at each step (it acts on
    the fed observation). Returns the episodes' returns and the counts (LANE_LEFT, IDLE, LANE_RIGHT, FASTER,
    SLOWER)."""
    actions = np.zeros(5, int)

    def count(result: Any) -> None:
        after(result)
        actions[int(victim.query(result.x_adv)[0].argmax())] += 1

    return drive_attack(env, victim, attack, objective, oracle, 900000, episodes, at_state, count), actions


def percent(actions: np.ndarray) -> list[float]:
    """Action counts as percentages of the steps, to two decimals."""
    return np.round(actions / actions.sum() * 100, 2).tolist()


def drive(env: Any, victim: Victim, seed0: int, episodes: int, choose: Chooser, *,
          target: Callable[[np.ndarray], int] = lambda x: FASTER,
          states: list[np.ndarray] | None = None) -> dict[str, Any]:
    """`episodes` episodes from seed `seed0`; the victim acts on what `choose` feeds it (its one query).
    `target(x)` is the action wanted at clean observation x. Returns the mean return, the crashes, and per
    target action how often it was wanted and taken. `states` collects the clean observations."""
    returns, crashes, wanted, taken, actions = [], 0, {}, {}, np.zeros(5, int)
    for e in range(episodes):
        obs, _ = env.reset(seed=seed0 + e)
        done, total, memory = False, 0.0, {"missed": False}
        while not done:
            x = np.asarray(obs, np.float32)[None]
            if states is not None:
                states.append(x[0])
            t = target(x)
            memory["target"] = t
            act = int(victim.query(choose(x, memory))[0].argmax())
            memory["missed"], memory["action"] = act != t, act
            wanted[t] = wanted.get(t, 0) + 1
            taken[t] = taken.get(t, 0) + int(act == t)
            actions[act] += 1
            obs, reward, terminated, truncated, info = env.step(act)
            total += reward
            done = terminated or truncated
        returns.append(total)
        crashes += bool(info.get("crashed"))
    return {"return": float(np.mean(returns)), "crashes": crashes, "episodes": episodes, "returns": returns,
            "taken": {t: f"{taken[t]}/{wanted[t]}" for t in sorted(wanted)},
            "action_share": np.round(actions / actions.sum(), 3).tolist()}


def show(label: str, r: dict[str, Any]) -> None:
    print(f"  {label}: return {r['return']:.2f}, crashed {r['crashes']}/{r['episodes']}, target taken "
          f"{r['taken']} (action: taken/wanted), action share {r['action_share']}")


def vertex_hold(threat: ThreatModel, shape: tuple[int, ...], rng: np.random.Generator) -> Chooser:
    """`--attack vertex-hold`'s rule: keep the vertex while the victim takes the target (and the target
    stays the same), else a fresh random vertex of the L-inf ball, projected."""
    mask = threat.mask(shape)

    def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
        if memory.get("held") is None or memory["missed"] or memory.get("held_for") != memory["target"]:
            memory["held"] = threat.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=shape) * mask
            memory["held_for"] = memory["target"]
        return threat.project(x + memory["held"], x)
    return choose
