"""Reinforcement learning that starts from a cloned driver (issue 22, item 2).

A behaviour-cloned network (`models/dqn-imitation`) outputs *logits*: their argmax drives well,
their values mean nothing to a TD target. So the clone goes into the online and target Q-networks
(`init_from_model`), drives into the replay buffer (`collect`), and its values are fitted to its own
returns by LSTD-Q (`calibrate`; Lagoudakis & Parr, JMLR 2003) in a family that a positive scale and a
per-state shift keep argmax-preserving at *every* state, folded into the last Linear layer: the greedy
policy stays exactly the clone's, and RL changes it only where the TD errors show a better action
(cf. DQfD's pre-training, Hester et al., AAAI 2018, from demonstrations instead of a trained policy).
`evaluate_td` (recipe `calibrate.td_steps`) optionally continues that policy evaluation with TD updates
of the whole network (the linear fit on frozen features leaves large TD errors, whose gradients would
reshape the hidden layers once RL starts) and DQfD's large-margin loss on the clone's actions.

A cloned DDPG / TD3 actor (`models/ddpg-imitation`) keeps its outputs as they are: it goes into the
actor and target actor (`init_actor_from_model`), drives into the buffer with the recipe's exploration
noise (`collect`), and the fresh critics are fitted to its returns by critic-only TD updates
(`evaluate_critic`) before the first actor update (then `GuidedTD3`, TD3+BC).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from torch.nn import functional as F

from zodrive.errors import ZodriveError
from zodrive.runinfo import sha256

Q_PREFIX = "q_net.q_net."  # SB3 DQN: the online Q-network's MLP in policy.pth
ACTOR_PREFIX = "actor.mu."  # SB3 DDPG / TD3: the actor's MLP in policy.pth
ACTOR_KIND = "DDPG or TD3 (no actor weights)"
EVALUATION_TAU = 0.05  # Polyak rate of the target critics during `evaluate_critic`


def init_from_model(model: Any, path: str | Path) -> dict[str, Any]:
    """Copy the Q-network weights of the DQN zip at `path` (file or model folder) into `model`'s
    online and target networks. Nothing is unpickled; a missing, non-DQN or differently shaped
    model is a one-line ZodriveError. Returns the file and its SHA-256."""
    file = _load_network(model.q_net, path, Q_PREFIX, "q_net.", "DQN (no Q-network weights)")
    model.q_net_target.load_state_dict(model.q_net.state_dict())
    return {"model": str(file), "sha256": sha256(file)}


def init_actor_from_model(model: Any, path: str | Path) -> dict[str, Any]:
    """Copy the actor of the DDPG / TD3 zip at `path` (file or model folder) into `model`'s actor
    and target actor; the critics stay freshly initialized (`evaluate_critic` fits them). Read
    without unpickling; a missing, non-DDPG/TD3 or differently shaped model is a one-line error."""
    file = _load_network(model.actor, path, ACTOR_PREFIX, "actor.", ACTOR_KIND)
    model.actor_target.load_state_dict(model.actor.state_dict())
    return {"model": str(file), "sha256": sha256(file), "part": "actor"}


def frozen_actor(model: Any, path: str | Path) -> Any:
    """The actor of the DDPG / TD3 zip at `path` as a frozen function (B, ...) observations -> (B, dims)
    actions: a copy of `model`'s actor with those weights (read without unpickling). A guide that keeps
    the learner near the policy it started from (a behaviour-regularized objective), the same on resume."""
    actor = copy.deepcopy(model.actor).requires_grad_(False)
    _load_network(actor, path, ACTOR_PREFIX, "actor.", ACTOR_KIND)

    def act(observations: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return actor(th.as_tensor(observations, dtype=th.float32)).numpy()

    return act


def _load_network(network: Any, path: str | Path, prefix: str, strip: str, kind: str) -> Path:
    """Load into `network` the weights under `prefix` in the zip at `path` (file or model folder),
    keys without `strip`, read without unpickling; returns the zip's path. A missing file, a zip
    without them or layers of other names or shapes are one-line ZodriveErrors."""
    from zodrive.policies.loading import model_file
    from zodrive.policies.safe_load import read_plain

    file = model_file(path)
    _, weights = read_plain(file)
    theirs = {k[len(strip):]: v for k, v in weights.items() if k.startswith(prefix)}
    if not theirs:
        raise ZodriveError(f"init model {file} is not a {kind}; init needs one")
    ours = network.state_dict()
    if set(theirs) != set(ours):
        raise ZodriveError(f"init model {file} has layers {sorted(theirs)}; the recipe's network has {sorted(ours)}")
    for key, value in ours.items():
        if tuple(theirs[key].shape) != tuple(value.shape):
            raise ZodriveError(f"init model {file}: {key} has shape {tuple(theirs[key].shape)}, the recipe's "
                               f"network {tuple(value.shape)} (policy_kwargs.net_arch and the preset must match)")
    network.load_state_dict({k: v.to(dtype=ours[k].dtype) for k, v in theirs.items()})
    return file


def drive_into_buffer(buffer: Any, env: Any, episodes: int, seed: int, choose: Any) -> list[float]:
    """Drive `episodes` episodes of `env` (seeds `seed`, `seed` + 1, ...) acting with `choose(obs)`
    and add every transition to the replay `buffer`; returns the episodes' returns."""
    returns = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        total, done = 0.0, False
        while not done:
            action = choose(obs)
            next_obs, reward, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
            buffer.add(obs[None], next_obs[None], np.reshape(action, (1, -1)), np.array([reward]), np.array([done]),
                       [{"TimeLimit.truncated": truncated and not terminated}])
            obs, total = next_obs, total + float(reward)
        returns.append(total)
    return returns


def collect(model: Any, env: Any, episodes: int, seed: int, epsilon: float = 0.0) -> dict[str, Any]:
    """Drive `episodes` episodes of `env` (seeds `seed`, `seed` + 1, ...) with the model's own
    action and add every transition to its replay buffer. A DQN acts greedily, a uniform random
    action with probability `epsilon` (numpy generator seeded by `seed`); a DDPG / TD3 takes its
    deterministic action plus its recipe's exploration noise (`model.action_noise`), clipped to
    [-1, 1] (the noise is drawn from numpy's global generator, which SB3 seeds with the run's seed).
    Returns counts and the mean return."""
    rng = np.random.default_rng(seed)
    discrete = hasattr(model.action_space, "n")
    random_actions = 0

    def choose(obs: np.ndarray) -> Any:
        nonlocal random_actions
        if not discrete:  # the actor's [-1, 1] space is the preset's (checked by the recipe)
            with th.no_grad():
                action = model.actor(th.as_tensor(obs[None], dtype=th.float32))[0].numpy()
            return action if model.action_noise is None else np.clip(action + model.action_noise(), -1.0, 1.0)
        if rng.random() < epsilon:
            random_actions += 1
            return int(rng.integers(model.action_space.n))
        with th.no_grad():
            return int(model.q_net(th.as_tensor(obs[None], dtype=th.float32)).argmax(dim=1)[0])

    returns = drive_into_buffer(model.replay_buffer, env, episodes, seed, choose)
    return {"episodes": episodes, "seeds_from": seed,
            **({"epsilon": epsilon, "random_actions": random_actions} if discrete else {}),
            "transitions": int(model.replay_buffer.size()), "mean_return": round(float(np.mean(returns)), 3)}


def evaluate_critic(model: Any, steps: int, batch_size: int) -> dict[str, Any]:
    """`steps` critic-only TD3 / DDPG updates on the replay buffer (`GuidedTD3.train_actor` off, so
    the targets use the frozen actor's next actions): policy evaluation of the initial driver, so
    that the first actor updates follow a critic of *its* returns, not a random one. Returns the
    one-step TD loss on a fixed sample of the buffer before and after, and the critic's mean value.
    The target critics follow at `EVALUATION_TAU` (at TD3's 0.005 they would lag the values over
    some 400 updates each, and values of a 100-step horizon need many such lags to build up)."""
    data = model.replay_buffer.sample(min(4096, int(model.replay_buffer.size())))

    def td_loss() -> float:
        with th.no_grad():
            discounts = data.discounts if data.discounts is not None else model.gamma
            next_q = th.cat(model.critic_target(data.next_observations, model.actor_target(data.next_observations)),
                            dim=1).min(dim=1, keepdim=True)[0]
            target = data.rewards + (1 - data.dones) * discounts * next_q
            return float(F.mse_loss(model.critic.q1_forward(data.observations, data.actions), target))

    before = td_loss()
    model.train_actor, tau = False, model.tau
    model.tau = max(tau, EVALUATION_TAU)
    try:
        model.train(steps, batch_size)
    finally:
        model.train_actor, model.tau = True, tau
    with th.no_grad():
        value = model.critic.q1_forward(data.observations, model.actor(data.observations))
    return {"td_steps": steps, "td_loss_before": round(before, 4), "td_loss_after": round(td_loss(), 4),
            "mean_q": round(float(value.mean()), 4), "mean_reward": round(float(data.rewards.mean()), 4)}


def _hidden_and_logits(q_net: Any, obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """The last hidden layer h(s) and the outputs of an SB3 QNetwork."""
    mlp = q_net.q_net
    hidden = mlp[:-1](q_net.extract_features(obs, q_net.features_extractor))
    return hidden, mlp[-1](hidden)


def _buffer_samples(model: Any) -> Any:
    """Every stored transition once (n-step returns as the buffer computes them for training)."""
    buffer = model.replay_buffer
    size = buffer.buffer_size if buffer.full else buffer.pos
    return buffer._get_samples(np.arange(size))


def calibrate(model: Any, ridge: float = 1e-3, min_scale: float = 0.1) -> dict[str, Any]:
    """Policy evaluation of the model's greedy policy on its replay buffer by LSTD-Q, in the
    argmax-preserving family Q = alpha * f(s, a) + u . h(s) + c (f: the current outputs); the
    solution is folded into the last layer of the online and target networks. `ridge` is
    Tikhonov regularization relative to the features' mean square; alpha below `min_scale` (the
    clone's ranking is not reflected in its returns) is raised to it and (u, c) refit. Returns
    the fit and the TD errors before and after, and the greedy agreement (1.0 by construction)."""
    q_net = model.q_net
    data = _buffer_samples(model)
    with th.no_grad():
        h, f = _hidden_and_logits(q_net, data.observations)
        h2, f2 = _hidden_and_logits(q_net, data.next_observations)
        greedy_before = f.argmax(dim=1)
        taken = f.gather(1, data.actions.long()).squeeze(1)
        nxt = f2.max(dim=1).values  # the clone's own next action (argmax), frozen
        discount = (data.discounts if data.discounts is not None else th.full_like(data.rewards, model.gamma))
        cont = (discount * (1 - data.dones)).squeeze(1).double()
        reward = data.rewards.squeeze(1).double()
        ones = th.ones(len(h), 1, dtype=th.float64)
        phi = th.cat([taken.double()[:, None], h.double(), ones], dim=1)
        phi2 = th.cat([nxt.double()[:, None], h2.double(), ones], dim=1)

        def td_errors(alpha: float, u: th.Tensor, c: float) -> th.Tensor:
            q, q2 = (alpha * p[:, 0] + p[:, 1:-1] @ u + c for p in (phi, phi2))
            return reward + cont * q2 - q

        before = float(td_errors(1.0, th.zeros(h.shape[1], dtype=th.float64), 0.0).abs().mean())
        n = len(phi)

        def lstd(a: th.Tensor, b: th.Tensor) -> th.Tensor:  # solve (A + ridge * scale * I) w = b
            scale = float((a.diagonal().abs().mean()))
            return th.linalg.solve(a + ridge * max(scale, 1e-12) * th.eye(len(a), dtype=a.dtype), b)

        matrix = phi.T @ (phi - cont[:, None] * phi2) / n
        w = lstd(matrix, phi.T @ reward / n)
        alpha_fit = float(w[0])
        if alpha_fit < min_scale:  # refit the value part with alpha fixed
            psi, psi2 = phi[:, 1:], phi2[:, 1:]
            target = reward + min_scale * (cont * phi2[:, 0] - phi[:, 0])
            w = th.cat([th.tensor([min_scale], dtype=th.float64),
                        lstd(psi.T @ (psi - cont[:, None] * psi2) / n, psi.T @ target / n)])
        alpha, u, c = float(w[0]), w[1:-1], float(w[-1])
        after = float(td_errors(alpha, u, c).abs().mean())
        last = q_net.q_net[-1]
        last.weight.copy_((alpha * last.weight.double() + u[None, :]).to(last.weight.dtype))
        last.bias.copy_((alpha * last.bias.double() + c).to(last.bias.dtype))
        model.q_net_target.load_state_dict(q_net.state_dict())
        _, f_new = _hidden_and_logits(q_net, data.observations)
        q_taken = f_new.gather(1, data.actions.long()).squeeze(1)
    return {"method": "LSTD-Q policy evaluation of the frozen greedy policy (Lagoudakis & Parr 2003), "
                      "Q = alpha * logit + u . h + c folded into the last layer",
            "transitions": n, "ridge": ridge, "alpha_fit": round(alpha_fit, 6), "alpha": round(alpha, 6),
            "offset": round(c, 4), "mean_q": round(float(q_taken.mean()), 4),
            "mean_n_step_return": round(float(reward.mean()), 4),
            "mean_abs_td_error_before": round(before, 4), "mean_abs_td_error_after": round(after, 4),
            "greedy_agreement": float((f_new.argmax(dim=1) == greedy_before).float().mean())}


def evaluate_td(model: Any, steps: int, batch_size: int, margin: float = 0.8, weight: float = 1.0,
                sync_every: int = 1000) -> dict[str, Any]:
    """`steps` TD updates of policy evaluation on the replay buffer: target r + gamma^n Q'(s', pi(s')),
    pi the argmax of a frozen copy of the current network (the calibrated clone), plus `weight` times
    the large-margin loss (Hester et al. 2018) on pi's actions; the target network copies the online
    one every `sync_every` updates and at the end. Uses the model's optimizer, learning rate and
    gradient clipping. Returns the losses and the greedy agreement with pi on the buffer's states."""
    frozen = copy.deepcopy(model.q_net).requires_grad_(False)
    model.policy.set_training_mode(True)
    td_losses, margins = [], []
    for step in range(steps):
        data = model.replay_buffer.sample(batch_size)
        discounts = data.discounts if data.discounts is not None else model.gamma
        with th.no_grad():
            nxt = frozen(data.next_observations).argmax(dim=1, keepdim=True)
            target = data.rewards + (1 - data.dones) * discounts * model.q_net_target(data.next_observations).gather(1, nxt)
            labels = frozen(data.observations).argmax(dim=1, keepdim=True)
        q = model.q_net(data.observations)
        td = F.smooth_l1_loss(q.gather(1, data.actions.long()), target)
        bonus = th.full_like(q, margin).scatter_(1, labels, 0.0)
        large_margin = ((q + bonus).amax(dim=1) - q.gather(1, labels).squeeze(1)).mean()
        loss = td + weight * large_margin
        model.policy.optimizer.zero_grad()
        loss.backward()
        th.nn.utils.clip_grad_norm_(model.policy.parameters(), model.max_grad_norm)
        model.policy.optimizer.step()
        td_losses.append(td.item())
        margins.append(large_margin.item())
        if (step + 1) % sync_every == 0:
            model.q_net_target.load_state_dict(model.q_net.state_dict())
    model.q_net_target.load_state_dict(model.q_net.state_dict())
    data = _buffer_samples(model)
    with th.no_grad():
        agreement = float((model.q_net(data.observations).argmax(dim=1)
                           == frozen(data.observations).argmax(dim=1)).float().mean())
    tail = max(1, steps // 10)
    return {"td_steps": steps, "td_loss_first": round(float(np.mean(td_losses[:tail])), 4),
            "td_loss_last": round(float(np.mean(td_losses[-tail:])), 4),
            "margin_loss_last": round(float(np.mean(margins[-tail:])), 4), "greedy_agreement": round(agreement, 4)}
