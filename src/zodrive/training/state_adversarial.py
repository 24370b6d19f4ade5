"""State-adversarial (SA) regularization for SB3 agents (Zhang, Chen, Xiao, Li, Boning, Hsieh,
"Robustness of Deep Reinforcement Learning against Adversarial Perturbations on State
Observations", NeurIPS 2020): the training loss plus a penalty on how much the policy's
decision can change inside the eps-ball around each replayed state, the worst point found by
PGD inside the same threat model as the attacks (box, frozen presence). eps ramps up linearly
over the first `eps_ramp` of training.

- `SAMixin`: the settings and the eps schedule, shared by SA-DQN (`dqn_variants.SADQN`) and SA-DDPG.
- `SADDPG`: R = max_{x' in B(x, eps)} ||pi(x') - pi(x)||^2 (the paper's SA-DDPG regularizer,
  here with PGD for the inner max instead of convex relaxation), weight `kappa`. SB3's DDPG
  update is unchanged; after it, each gradient step takes one actor step on kappa * R
  (alternating, so SB3's train() is reused rather than copied). Costs `pgd_steps` + 1 extra
  actor forward/backward passes per update. The saved zip is an ordinary SB3 DDPG zip.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import DDPG

from zodrive.attacks.threat import worst_in_ball


class SAMixin:
    """The SA settings of an SB3 agent; call `configure_robust` before learning."""

    robust: dict[str, Any] = {}
    num_timesteps: int

    def configure_robust(self, *, eps: float, kappa: float = 0.5, pgd_steps: int = 5, hinge: float = 1.0,
                         eps_ramp: float = 0.3, mask: np.ndarray | None = None, low: float = -1.0,
                         high: float = 1.0, total_steps: int = 1) -> None:
        self.robust = {"eps": eps, "kappa": kappa, "pgd_steps": pgd_steps, "hinge": hinge, "eps_ramp": eps_ramp,
                       "mask": None if mask is None else th.as_tensor(mask, dtype=th.float32), "low": low,
                       "high": high, "total_steps": max(total_steps, 1), "start": None}

    def current_eps(self) -> float:
        r = self.robust
        if not r:
            return 0.0
        if r["start"] is None:  # the ramp starts with the first update
            r["start"] = self.num_timesteps
        done = (self.num_timesteps - r["start"]) / r["total_steps"]
        return r["eps"] * min(1.0, done / r["eps_ramp"]) if r["eps_ramp"] > 0 else r["eps"]

    def ball_mask(self, x0: th.Tensor) -> th.Tensor:
        mask = self.robust["mask"]
        return th.ones_like(x0[0]) if mask is None else mask.reshape(x0.shape[1:])


class SADDPG(SAMixin, DDPG):
    """SB3's DDPG + the SA-DDPG regularizer on the actor."""

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        super().train(gradient_steps, batch_size)
        eps = self.current_eps()
        if eps <= 0:
            return
        r, regs = self.robust, []
        for _ in range(gradient_steps):
            x0 = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env).observations.detach()  # type: ignore[union-attr]
            with th.no_grad():
                a0 = self.actor(x0)

            def change(x: th.Tensor) -> th.Tensor:  # squared L2 change of the action, per state
                return ((self.actor(x) - a0) ** 2).sum(dim=1)

            x = worst_in_ball(change, x0, eps, r["pgd_steps"], self.ball_mask(x0), r["low"], r["high"])
            reg = r["kappa"] * change(x).mean()
            self.actor.optimizer.zero_grad()
            reg.backward()
            self.actor.optimizer.step()
            regs.append(reg.item())
        self.logger.record("train/regularizer", float(np.mean(regs)))
