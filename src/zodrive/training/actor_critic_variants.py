"""SB3's TD3 / DDPG with a behaviour-cloning term in the actor's loss, for RL from a cloned driver.

`GuidedTD3` is TD3+BC (Fujimoto & Gu, "A Minimalist Approach to Offline Reinforcement Learning",
NeurIPS 2021) used online: the actor maximizes

    Q1(s, pi(s)) / mean_batch |Q1(s, pi(s))|  -  imitation * mean_dims (pi(s) - a_G(s))^2,

with a_G(s) the guide's action on every sampled state: the actor the run started from, kept frozen
(recipe `guide.name: init`, a behaviour-regularized objective), or `baseline:rules` on the continuous
preset (`rules`, TD3+BC with an online teacher). The Q term is normalized as in TD3+BC so that
`imitation` means the same whatever the return scale (TD3+BC's alpha = 2.5 is `imitation` = 0.4).
With `error` "absolute" the guide's term is mean_dims |pi(s) - a_G(s)| instead, the loss the
continuous clone was fitted with. The guide's term keeps the driver where the critic does not show
it something better, the way DQfD's margin loss was meant to for the DQN (removed, issue 45:
results/finetune/README.md); from a clone of the rules, the clone is the guide that works (the
rules' high-gain steering, which the clone smooths, undid its lane keeping:
results/finetune-continuous/README.md). With `train_actor` False, `train` updates the critics only
(target actions from the frozen actor): policy evaluation of the initial driver before RL starts;
a recipe with `init` therefore trains a GuidedTD3 even without a guide.
Critic updates, target smoothing, delayed actor updates and Polyak averaging are SB3's TD3 unchanged;
`GuidedDDPG` is the same on SB3's DDPG (one critic, no smoothing, no delay). The saved zip is an
ordinary SB3 TD3 / DDPG zip; the guide is not part of the policy.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.utils import polyak_update
from torch.nn import functional as F

IMITATION_ERRORS = ("squared", "absolute")


class GuidedTD3(TD3):
    guide: Any = None        # (B, ...) observations -> (B, action dims) actions in [-1, 1]
    imitation: float = 0.0   # weight of the guide's error in the actor's loss
    error: str = "squared"   # squared (TD3+BC) | absolute
    train_actor: bool = True  # False: critic-only updates (policy evaluation of the frozen actor)

    def configure_guide(self, guide: Any, imitation: float, error: str = "squared") -> None:
        if error not in IMITATION_ERRORS:
            raise ValueError(f"error must be one of {IMITATION_ERRORS}, not {error!r}")
        self.guide, self.imitation, self.error = guide, float(imitation), error

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "guide"]

    def actor_loss(self, observations: th.Tensor) -> tuple[th.Tensor, float | None]:
        """TD3+BC's actor loss; returns it and the imitation term (None without a guide: then TD3's own
        loss, -Q, so that a GuidedTD3 without a guide learns as SB3's TD3)."""
        actions = self.actor(observations)
        q = self.critic.q1_forward(observations, actions)
        if self.guide is None or self.imitation <= 0:
            return -q.mean(), None
        loss = -q.mean() / q.abs().mean().detach().clamp_min(1e-6)
        labels = th.as_tensor(np.asarray(self.guide(observations.detach().cpu().numpy())), dtype=actions.dtype)
        bc = F.mse_loss(actions, labels) if self.error == "squared" else F.l1_loss(actions, labels)
        return loss + self.imitation * bc, bc.item()

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate([self.actor.optimizer, self.critic.optimizer])
        actor_losses, critic_losses, imitation_losses = [], [], []
        for _ in range(gradient_steps):
            self._n_updates += 1
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = data.discounts if data.discounts is not None else self.gamma
            with th.no_grad():
                noise = data.actions.clone().normal_(0, self.target_policy_noise).clamp(
                    -self.target_noise_clip, self.target_noise_clip)
                next_actions = (self.actor_target(data.next_observations) + noise).clamp(-1, 1)
                next_q = th.cat(self.critic_target(data.next_observations, next_actions),
                                dim=1).min(dim=1, keepdim=True)[0]
                target = data.rewards + (1 - data.dones) * discounts * next_q
            critic_loss = sum(F.mse_loss(q, target) for q in self.critic(data.observations, data.actions))
            assert isinstance(critic_loss, th.Tensor)
            critic_losses.append(critic_loss.item())
            self.critic.optimizer.zero_grad()
            critic_loss.backward()
            self.critic.optimizer.step()
            if self._n_updates % self.policy_delay == 0:
                if self.train_actor:
                    actor_loss, bc = self.actor_loss(data.observations)
                    actor_losses.append(actor_loss.item())
                    if bc is not None:
                        imitation_losses.append(bc)
                    self.actor.optimizer.zero_grad()
                    actor_loss.backward()
                    self.actor.optimizer.step()
                    polyak_update(self.actor.parameters(), self.actor_target.parameters(), self.tau)
                polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/critic_loss", np.mean(critic_losses))
        if actor_losses:
            self.logger.record("train/actor_loss", np.mean(actor_losses))
        if imitation_losses:
            self.logger.record("train/imitation_loss", np.mean(imitation_losses))


class GuidedDDPG(GuidedTD3, DDPG):
    """`GuidedTD3`'s loss on SB3's DDPG (one critic, policy_delay 1, no target smoothing)."""
