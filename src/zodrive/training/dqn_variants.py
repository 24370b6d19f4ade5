"""SB3's DQN with two opt-in changes to its loss, sharing one training loop.

- `DoubleDQN`: the Double-DQN target (van Hasselt, Guez & Silver, AAAI 2016): the online
  network picks the next action, the target network values it. Recipes opt in with
  `double_q: true`.
- `SADQN`: the state-adversarial regularizer of SA-DQN (Zhang, Chen, Xiao, Li, Boning,
  Hsieh, "Robustness of Deep Reinforcement Learning against Adversarial Perturbations on
  State Observations", NeurIPS 2020): for every state of the batch,
  R = max(max_{x' in B(x, eps)} [max_{a != a*} Q(x', a) - Q(x', a*)], -c), a* = argmax Q(x),
  the inner max found by `pgd_steps` signed-gradient steps inside the threat model (box,
  frozen presence), added to the TD loss with weight `kappa`; eps ramps up linearly over the
  first `eps_ramp` of training. Costs `pgd_steps` extra forward+backward passes per update.

Everything else (n-step replay, Huber loss, gradient clipping, target updates,
exploration) is SB3's DQN unchanged; the saved zip is an ordinary SB3 DQN zip.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from torch.nn import functional as F

from zodrive.training.state_adversarial import SAMixin
from zodrive.attacks.threat import worst_in_ball


class LossHookDQN(DQN):
    """SB3's DQN `train()` with two hooks: the TD target and an extra loss term."""

    def td_target(self, data: Any, discounts: Any) -> th.Tensor:
        with th.no_grad():
            next_q = self.q_net_target(data.next_observations).max(dim=1, keepdim=True)[0]
            return data.rewards + (1 - data.dones) * discounts * next_q

    def extra_loss(self, observations: th.Tensor) -> th.Tensor | None:
        return None

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses, extras = [], []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = data.discounts if data.discounts is not None else self.gamma  # n-step aware
            target = self.td_target(data, discounts)
            current = th.gather(self.q_net(data.observations), 1, data.actions.long())
            loss = F.smooth_l1_loss(current, target)
            losses.append(loss.item())
            extra = self.extra_loss(data.observations)
            if extra is not None:
                extras.append(extra.item())
                loss = loss + extra
            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))
        if extras:
            self.logger.record("train/regularizer", np.mean(extras))


class DoubleDQN(LossHookDQN):
    def td_target(self, data: Any, discounts: Any) -> th.Tensor:
        with th.no_grad():
            next_actions = self.q_net(data.next_observations).argmax(dim=1, keepdim=True)
            next_q = th.gather(self.q_net_target(data.next_observations), 1, next_actions)
            return data.rewards + (1 - data.dones) * discounts * next_q


class SADQN(SAMixin, LossHookDQN):
    """DQN + the SA-DQN regularizer; set `robust` (see `configure_robust`) before learning."""

    def extra_loss(self, observations: th.Tensor) -> th.Tensor | None:
        r = self.robust
        eps = self.current_eps()
        if eps <= 0:
            return None
        x0 = observations.detach()
        mask = self.ball_mask(x0)
        with th.no_grad():
            best = self.q_net(x0).argmax(dim=1, keepdim=True)
        assert isinstance(self.action_space, spaces.Discrete)  # DQN acts on Discrete actions only
        others = th.ones(x0.shape[0], self.action_space.n, dtype=th.bool).scatter_(1, best, False)

        def margin(x: th.Tensor) -> th.Tensor:  # > 0: some other action beats a* at x
            q = self.q_net(x)
            return q.masked_fill(~others, float("-inf")).amax(dim=1) - q.gather(1, best).squeeze(1)

        x = worst_in_ball(margin, x0, eps, r["pgd_steps"], mask, r["low"], r["high"])  # maximize the margin
        reg = th.clamp(margin(x), min=-r["hinge"]).mean()  # gradient flows into the network only
        return r["kappa"] * reg
