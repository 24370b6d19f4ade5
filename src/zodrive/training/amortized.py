"""A learned adversary's start: an amortized transfer attack, fitted before PPO (`attack-train --pretrain-rounds`).

Why: SA-RL's adversary learns from the victim's return alone, and 100 000 steps did not make the DQN
driver crash (`results/learned-adversary`), while per-step searches that push the victim toward one
harmful action (FASTER) crash it in nearly every episode. Each round the victim drives under the current
adversary; the points it is queried on train a surrogate (Papernot et al., AsiaCCS 2017), and the
adversary's mean action is fitted through the surrogate so that it takes the target by a margin (Baluja &
Fischer, AAAI 2018). Every victim query is counted. Details: docs/attacks.md ("A fitted start").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from zodrive.attacks.learned import apply_action
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError
from zodrive.evaluation.rollout import to_action


@dataclass(frozen=True)
class Pretrain:
    """How the adversary's start is fitted (see the module docstring)."""

    rounds: int = 3       # drive, query, fit; each round on the states the current adversary leads to
    episodes: int = 10    # episodes driven per round
    probes: int = 4       # random points queried per visited state, uniform in the eps-ball, for the surrogate
    epochs: int = 20      # passes over all data so far, per fit
    hidden: int = 256     # the surrogate's two hidden layers (fitted by MSE on the victim's outputs)
    margin: float | None = None  # discrete: the target must win on the surrogate by this many of the
    #                              victim's median decision gaps (None: 1); continuous victims have no margin

    def __post_init__(self) -> None:
        for name in ("rounds", "episodes", "epochs", "hidden"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ZodriveError(f"pretrain {name} must be an integer >= 1, not {value}")
        if self.margin is not None and not (isinstance(self.margin, (int, float)) and self.margin >= 0):
            raise ZodriveError(f"pretrain margin must be a number >= 0, not {self.margin}")
        if not (isinstance(self.probes, int) and self.probes >= 0):
            raise ZodriveError(f"pretrain probes must be an integer >= 0, not {self.probes}")


def check(settings: Pretrain, kind: str, objective: Objective) -> None:
    """One-line errors for a start that cannot be fitted as asked (before anything is written)."""
    if not objective.targeted:
        raise ZodriveError("--pretrain-rounds fits the adversary to a target action (FASTER, or [1, 0.5] for a "
                           "continuous victim); an untargeted objective has none")
    if kind != "discrete" and settings.margin is not None:
        raise ZodriveError("--pretrain-margin is a margin between a discrete victim's action scores; this victim "
                           "is continuous")


def _mean(policy: Any, x: torch.Tensor) -> torch.Tensor:
    """The PPO policy's Gaussian mean: the adversary's deterministic action (what the attack uses)."""
    features = policy.extract_features(x, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))


def adam_epochs(params: list[torch.nn.Parameter], loss_of, n: int, epochs: int, gen: torch.Generator | None,
                lr: float = 1e-3, batch: int = 256) -> float:
    """Adam on `params` over shuffled mini-batches of `batch` of `n` rows (shuffled by `gen`, None:
    torch's global generator); `loss_of(index)` is a batch's mean loss. Returns the last epoch's mean loss."""
    opt = torch.optim.Adam(params, lr=lr)
    last = float("nan")
    for _ in range(epochs):
        total, batches = 0.0, 0
        for index in torch.randperm(n, generator=gen).split(batch):
            loss = loss_of(index)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total, batches = total + loss.item(), batches + 1
        last = total / batches
    return last


def pretrain(policy: Any, env: gym.Env, victim: Victim, threat: ThreatModel, objective: Objective,
             free: np.ndarray, settings: Pretrain, seed: int) -> dict[str, Any]:
    """Fit `policy`'s mean action (an SB3 PPO policy over flattened observations) as above;
    returns what it cost and did, per round: states visited, the victim's return, the share of
    steps where the victim took the target action under the adversary (measured by the
    decision queries themselves: the objective's success), queries so far, the surrogate's and
    the adversary's fit, and the share of visited states where the fitted adversary makes the
    surrogate take the target (what it should do to the victim next round, if it transfers).
    Round r drives with the adversary as round r - 1 left it (round 0: PPO's initial mean,
    near zero: nearly clean)."""
    check(settings, victim.kind, objective)
    discrete = victim.kind == "discrete"
    rng = np.random.default_rng(seed)
    gen = torch.Generator().manual_seed(seed)
    assert env.observation_space.shape is not None  # a Box (presets refuse others)
    shape = tuple(env.observation_space.shape)
    dim = int(np.prod(shape))
    oracle = QueryOracle(victim)
    mask = threat.mask(shape).reshape(-1)
    eps = np.float32(threat.eps)
    width = kappa = None
    surrogate: torch.nn.Module | None = None
    inputs: list[np.ndarray] = []   # every queried point (flattened) ...
    outputs: list[np.ndarray] = []  # ... and the victim's outputs there
    states: list[np.ndarray] = []   # every visited clean observation (flattened)
    rounds = []
    for r in range(settings.rounds):
        returns, hits, steps = [], 0, 0
        for e in range(settings.episodes):
            obs, _ = env.reset(seed=int(seed * 1000 + r * settings.episodes + e))
            done, total = False, 0.0
            while not done:
                x = np.asarray(obs, dtype=np.float32)[None]
                with torch.no_grad():
                    action = _mean(policy, torch.from_numpy(x.reshape(1, -1))).numpy()
                fed = apply_action(threat, x, action, free)
                noise = rng.uniform(-1.0, 1.0, size=(settings.probes, *shape)).astype(np.float32) * mask.reshape(shape)
                probes = threat.project(x + eps * noise, np.repeat(x, settings.probes, axis=0))
                batch = np.concatenate([fed, probes])
                oracle.begin_step(1)
                out = oracle(batch, np.zeros(len(batch), dtype=np.int64))
                first = torch.from_numpy(np.asarray(out[:1], dtype=np.float32))
                hits += bool(objective.success(first[:, None], first)[0, 0])
                chosen = to_action(victim, out[:1], env.action_space)
                inputs.append(batch.reshape(len(batch), dim))
                outputs.append(np.asarray(out, dtype=np.float32))
                states.append(x.reshape(1, dim))
                obs, reward, terminated, truncated, _ = env.step(chosen)
                total += float(reward)
                steps += 1
                done = terminated or truncated
            returns.append(total)
        X = torch.from_numpy(np.concatenate(inputs))
        Y = torch.from_numpy(np.concatenate(outputs))
        if discrete:
            Y = Y - Y.mean(dim=1, keepdim=True)  # what decides is the scores' differences, not their common level
        S = torch.from_numpy(np.concatenate(states))
        if surrogate is None:
            surrogate = torch.nn.Sequential(torch.nn.Linear(dim, settings.hidden), torch.nn.ReLU(),
                                            torch.nn.Linear(settings.hidden, settings.hidden), torch.nn.ReLU(),
                                            torch.nn.Linear(settings.hidden, Y.shape[1]))
            if discrete:
                top2 = np.sort(Y.numpy(), axis=1)[:, -2:]
                width = float(np.median(top2[:, 1] - top2[:, 0]))  # the victim's typical decision gap
        scale = Y.std().clamp(min=1e-6)

        def surrogate_loss(i: torch.Tensor) -> torch.Tensor:
            return (((surrogate(X[i]) - Y[i]) / scale) ** 2).mean()

        mse = adam_epochs(list(surrogate.parameters()), surrogate_loss, len(X), settings.epochs, gen)
        with torch.no_grad():  # discrete: the share of points where it picks the victim's action; continuous: RMSE
            agree = (float((surrogate(X).argmax(1) == Y.argmax(1)).float().mean()) if discrete
                     else float(((surrogate(X) - Y) ** 2).mean().sqrt()))
        surrogate.requires_grad_(False)  # fitting the adversary through it: no gradient for its weights
        # discrete: win by the victim's typical gap, so that the attack survives the surrogate's error
        kappa = None if width is None else (1.0 if settings.margin is None else settings.margin) * width
        # (a width only for a discrete victim, whose objectives all have a kappa)
        margin = objective if kappa is None else replace(objective, kappa=kappa)  # type: ignore[call-arg]
        # only these are fitted
        actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
        low = torch.minimum(torch.tensor(threat.low), S)
        high = torch.maximum(torch.tensor(threat.high), S)
        free_t = torch.from_numpy(free)

        def fed_to_surrogate(i: torch.Tensor | slice, a: torch.Tensor) -> torch.Tensor:
            """`apply_action` in torch (an L-inf ball: eps * a is inside it) for the states S[i]."""
            delta = torch.zeros_like(S[i])
            delta[:, free_t] = float(eps) * a
            return surrogate(torch.maximum(torch.minimum(S[i] + delta, high[i]), low[i]))

        def adversary_loss(i: torch.Tensor) -> torch.Tensor:
            mean = _mean(policy, S[i])
            # the attack's clip; gradients pass
            out = fed_to_surrogate(i, mean - (mean - mean.clamp(-1.0, 1.0)).detach())
            outside = torch.relu(mean.abs() - 1.0)  # ... and a penalty keeps the mean near [-1, 1]
            return margin.loss(out[:, None], out.detach())[:, 0].mean() + (outside ** 2).sum(1).mean()

        fit = adam_epochs(actor, adversary_loss, len(S), settings.epochs, gen)
        with torch.no_grad():  # on the surrogate, the share of visited states the fitted adversary wins
            fed_out = fed_to_surrogate(slice(None), _mean(policy, S).clamp(-1.0, 1.0))
            won = float(objective.success(fed_out[:, None], fed_out)[:, 0].float().mean())
        surrogate.requires_grad_(True)
        rounds.append({"round": r, "episodes": settings.episodes, "steps": steps,
                       "victim_return": float(np.mean(returns)), "target_share": hits / max(steps, 1),
                       "queries": int(oracle.total_queries),
                       "surrogate_mse": round(mse, 4),
                       ("surrogate_agreement" if discrete else "surrogate_rmse"): round(agree, 4),
                       "adversary_loss": round(fit, 4), "surrogate_target_share": round(won, 4)})
    return {"rounds": rounds, "queries": int(oracle.total_queries), "margin": kappa, "settings": settings.__dict__}


def surrogate_fit(round_: dict[str, Any]) -> str:
    """How well a round's surrogate matched the victim, in words (for the card and the CLI)."""
    if "surrogate_agreement" in round_:
        return f"surrogate takes the victim's action on {round_['surrogate_agreement']:.1%} of queried points"
    return f"surrogate action RMSE {round_['surrogate_rmse']:.3f}"
