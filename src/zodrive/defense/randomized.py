"""Randomized smoothing (`--defense smooth@SIGMA`): the policy votes over noisy copies of what it observes.

Cohen, Rosenfeld & Kolter, "Certified Adversarial Robustness via Randomized Smoothing", ICML 2019;
for policies, Wu et al., "CROP: Certifying Robust Policies for Reinforcement Learning through
Functional Smoothing", ICLR 2022, and Sun, Zhang & Weng, "Breaking the Barrier: Enhanced Utility
and Robustness in Smoothed DRL Agents" (S-DQN), ICML 2024.

Each observation is copied `VOTES` times with Gaussian noise of standard deviation SIGMA
(normalized units) on every feature the attacker may move (not `presence`), clipped to the
observation box; the policy acts on each copy, and the system takes the action with the most
votes. What the attacker queries is the system: its outputs are the vote shares, so a
score-based attack reads how close the vote is.

The noise of an observation is drawn from a generator seeded by the observation's bytes
(derandomized smoothing): one observation, one decision, whatever else shares the batch, so
rows are reproducible and do not depend on `--envs` or `--workers`. An attacker that queries the
very point it feeds learns the decision the car will take there, so no expectation over the noise
(EOT) is needed to attack it: that is the attacker's best case, and a success counts as one.

Per state, `certified_radius` gives the L∞ radius within which the vote cannot change (Cohen et
al.'s L2 radius SIGMA·Φ⁻¹(p), p the one-sided Clopper-Pearson lower bound on the top vote share
at α = 0.001, divided by √d for the d free coordinates). It is an estimate from the same votes
that choose the action (Cohen et al. draw separate samples): reported, never relied on.

What it assumes: discrete actions (a vote), a policy whose decision on most states does not flip
under noise of SIGMA (else the clean cost is high: the table measures it). What it cannot stop:
a perturbation larger than a state's certified radius; a persistent offset that moves the whole
noise cloud across the policy's boundary; anything outside the observation.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from zodrive.attacks.oracle import stable_batch
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

VERSION = 2
"""The behaviour of `smooth@SIGMA`, recorded in every result key that names it: v1 drew each observation's
noise from a numpy generator of its own, v2 from counter-based SplitMix64 (`gaussians`), 60x cheaper."""
VOTES = 32
"""Noisy copies per observation: every query of the defended system costs the policy 32 rows, which
keeps a bench row within the protocol's time; vote shares move in steps of 1/32."""
ALPHA = 0.001
"""One-sided error of the certified radius' lower bound on the top vote share (Cohen et al.'s)."""
KEY = b"zodrive-smooth"
"""Keys the hash of every observation into its noise seed: a fixed part of the defense (one name, one system)."""


def _splitmix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's output function (Steele, Lea & Flood, OOPSLA 2014), elementwise on uint64 (wrapping)."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def gaussians(seeds: np.ndarray, n: int) -> np.ndarray:
    """(B, n) standard normals (float32), row b a function of `seeds[b]` (uint64) alone: counter-based
    SplitMix64 uniforms through Box-Muller, all rows at once (one numpy generator per row costs ~100x more)."""
    counter = np.arange(2 * ((n + 1) // 2), dtype=np.uint64)
    with np.errstate(over="ignore"):
        bits = _splitmix(seeds[:, None] * np.uint64(0x9E3779B97F4A7C15) + counter)
    u = ((bits >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0 ** -53  # in (0, 1)
    u1, u2 = u[:, 0::2], u[:, 1::2]
    radius = np.sqrt(-2.0 * np.log(u1))
    z = np.concatenate([radius * np.cos(2 * np.pi * u2), radius * np.sin(2 * np.pi * u2)], axis=1)
    return z[:, :n].astype(np.float32)


def parse_smooth(name: str) -> float | None:
    """SIGMA of `smooth@SIGMA` (None if `name` is not this defense); one line for a bad SIGMA."""
    base, at, sigma = str(name).partition("@")
    if base != "smooth":
        return None
    try:
        value = float(sigma) if at else float("nan")
    except ValueError:
        value = float("nan")
    if not 0 < value <= 1:  # also rejects nan
        raise ZodriveError(f"{name}: smooth@SIGMA takes the noise's standard deviation SIGMA in (0, 1] in normalized "
                           "units, e.g. smooth@0.05")
    return value


class Smoothing:
    """`guard(victim)`: the voting system over `victim`. `noise(batch)`: the copies each observation
    is voted on (deterministic per observation)."""

    def __init__(self, preset: dict[str, Any], sigma: float, votes: int = VOTES) -> None:
        from zodrive.envs import scenario

        where = scenario(preset)
        if where.kind != "discrete":
            raise ZodriveError("randomized smoothing votes on an action: it defends discrete policies, "
                               "not continuous ones")
        self.sigma, self.votes = float(sigma), int(votes)
        low, high = where.bounds
        # numpy's isscalar guard also admits str and bytes; the bounds are numbers
        self.low = (np.asarray(low, dtype=np.float32).reshape(-1) if not np.isscalar(low)
                    else np.float32(low))  # type: ignore[arg-type]
        self.high = (np.asarray(high, dtype=np.float32).reshape(-1) if not np.isscalar(high)
                     else np.float32(high))  # type: ignore[arg-type]
        mask = np.ones(where.obs_shape, dtype=np.float32)
        if "presence" in where.features:
            index: list[Any] = [slice(None)] * len(where.obs_shape)
            index[where.feature_axis] = where.features.index("presence")
            mask[tuple(index)] = 0.0
        self.mask = mask.reshape(-1)
        self.dims = int(self.mask.sum())
        self.obs_shape = where.obs_shape

    def noise(self, batch: np.ndarray) -> np.ndarray:
        """(B, VOTES, *obs) noisy copies of `batch` (B, *obs): each observation's noise seeded by its bytes."""
        flat = np.ascontiguousarray(batch, dtype=np.float32).reshape(len(batch), -1)
        seeds = np.array([int.from_bytes(hashlib.blake2b(row.tobytes(), digest_size=8, key=KEY).digest(), "big")
                          for row in flat], dtype=np.uint64)
        z = gaussians(seeds, self.votes * flat.shape[1]).reshape(len(flat), self.votes, flat.shape[1])
        out = np.clip(flat[:, None] + self.sigma * z * self.mask, self.low, self.high)
        return out.reshape(len(batch), self.votes, *batch.shape[1:])

    def shares(self, victim: Victim, batch: np.ndarray, together: bool = False) -> np.ndarray:
        """(B, n_actions) vote shares of `victim` on each observation's copies (`votes_of`)."""
        return self.votes_of(victim, self.noise(np.asarray(batch)), together)

    def votes_of(self, victim: Victim, copies: np.ndarray, together: bool = False) -> np.ndarray:
        """(B, n_actions) vote shares of `victim` on copies (B, VOTES, *obs). A row's votes never depend on
        the batch it came in: each observation's VOTES copies go in a call of their own, or, `together`, all
        in one call where the network is known to give a row the same outputs in any batch of VOTES rows or
        more (`oracle.stable_batch`)."""
        if len(copies) == 0:
            return np.zeros((0, 0), dtype=np.float32)
        if together:
            scores = np.asarray(victim.query(copies.reshape(-1, *self.obs_shape)))
            votes = scores.argmax(axis=-1).reshape(len(copies), self.votes)
        else:
            outs = [np.asarray(victim.query(cloud)) for cloud in copies]
            scores, votes = outs[0], np.stack([o.argmax(axis=-1) for o in outs])
        k = scores.shape[-1]
        counts = (votes[:, :, None] == np.arange(k)).sum(axis=1)
        return (counts / self.votes).astype(np.float32)

    def guard(self, victim: Victim) -> Victim:
        """The defended system as the car and the attacker see it: vote shares (argmax: the vote's action).
        White-box access, where the policy has it, is the expectation over the noise (EOT; Athalye et al.,
        "Synthesizing Robust Adversarial Examples", ICML 2018): the value is the vote shares, the gradient
        that of the policy's scores averaged over the same noisy copies."""
        if victim.kind != "discrete":
            raise ZodriveError("randomized smoothing votes on an action: it defends discrete policies")
        together = victim.calibrate is not None and stable_batch(victim.calibrate, self.obs_shape)[0] <= self.votes

        def query(batch: np.ndarray) -> np.ndarray:
            batch = np.asarray(batch)
            lead = batch.shape[: batch.ndim - len(self.obs_shape)]
            shares = self.shares(victim, batch.reshape(-1, *self.obs_shape), together)
            return shares.reshape(*lead, shares.shape[-1])

        differentiable = None
        if victim.differentiable is not None:
            net = victim.differentiable

            def differentiable(x: Any) -> Any:
                flat = x.reshape(-1, *self.obs_shape)
                cloud = self.noise(flat.detach().cpu().numpy())
                offset = x.new_tensor(cloud) - flat.detach()[:, None]  # the copies, as offsets from x
                mean = (net((flat[:, None] + offset).reshape(-1, *self.obs_shape))
                        .reshape(len(flat), self.votes, -1).mean(1))
                value = mean.new_tensor(self.votes_of(victim, cloud, together))  # the same copies: noise drawn once
                return (mean + (value - mean).detach()).reshape(*x.shape[: x.ndim - len(self.obs_shape)], -1)

        return Victim(query=query, kind="discrete", obs_shape=victim.obs_shape, differentiable=differentiable,
                      reads=victim.reads)

    def certified_radius(self, shares: np.ndarray) -> np.ndarray:
        """Per state (B,), the L∞ radius within which the vote's action is estimated not to change (0: none)."""
        from scipy.stats import beta, norm

        top = np.rint(np.asarray(shares).max(axis=-1) * self.votes)
        lower = np.where(top > 0, beta.ppf(ALPHA, top, self.votes - top + 1), 0.0)
        lower = np.nan_to_num(lower, nan=0.0)
        radius = np.where(lower > 0.5, self.sigma * norm.ppf(np.clip(lower, 0.5, 1 - 1e-12)), 0.0)
        return radius / np.sqrt(max(self.dims, 1))
