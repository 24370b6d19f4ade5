"""Train a learned optimal adversary (`zodrive attack-train`): SA-RL, Zhang et al., ICLR 2021.

An SB3 PPO agent in an environment of its own (`AdversaryEnv`) perturbs the fixed victim's
observation to lower its return; every victim call is counted. The folder it writes is read back by
`--attack learned:DIR` through the safe loader (nothing unpickled). The MDP, the rewards, the
exploration and the folder are described in docs/attacks.md ("The learned adversary").
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from zodrive.training.amortized import Pretrain, check, pretrain as fit_start, surrogate_fit
from zodrive.attacks.learned import FORMAT, META_FILE, apply_action, free_coordinates
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel
from zodrive.attacks.victim import Victim
from zodrive.compute import one_torch_thread
from zodrive.defense import defense_version
from zodrive.errors import ZodriveError
from zodrive.evaluation.rollout import to_action

log = logging.getLogger(__name__)

PPO_DEFAULTS: dict[str, Any] = {"n_steps": 1024, "batch_size": 64, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99,
                "gae_lambda": 0.95, "ent_coef": 0.0, "use_sde": True, "sde_sample_freq": 128}
"""SB3's PPO defaults but a shorter rollout (episodes are up to 450 decisions) and gSDE exploration
(Raffin et al., CoRL 2021) redrawn every 128 steps: a perturbation held for many steps is tried as a whole."""
REWARDS = ("minus", "horizon")
"""The adversary's reward (`AdversaryEnv._reward`): minus the victim's reward, or the same
objective over the fixed horizon with a crash credited at once."""
LOG_STD_INIT = -1.0
"""Initial log std of gSDE's noise weights (SB3's default 0); the samples still sit near the box's corners
(docs/attacks.md). `explore_std` replaces it by a plain Gaussian of a stated std."""


class AdversaryEnv(gym.Env):
    """The adversary's MDP around a fixed victim and the preset's environment.

    Observation: the flattened true observation. Action: a in [-1, 1]^d, d = perturbable coordinates.
    Step: the victim acts on `apply_action(threat, obs, a)` (one counted query), the
    environment steps, and the reward is minus the victim's reward (`info["victim_reward"]`).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, env: gym.Env, victim: Victim, threat: ThreatModel, *, reward: str = "minus",
                 horizon: int | None = None) -> None:
        if reward not in REWARDS:
            raise ZodriveError(f"reward must be one of {', '.join(REWARDS)}, not {reward!r}")
        if reward == "horizon" and not (isinstance(horizon, int) and horizon >= 1):
            raise ZodriveError("reward horizon needs the episode's horizon (a preset whose per-step reward is at most "
                               "1 and whose length is known); use reward minus")
        self.env, self.victim, self.threat = env, victim, threat
        self.reward, self.horizon = reward, horizon
        self.t = 0
        self.episode_return = 0.0
        self.victim_returns: list[float] = []  # the victim's return of every finished episode
        self.oracle = QueryOracle(victim)  # no budget: counts every victim call of training
        assert env.observation_space.shape is not None  # a Box (presets refuse others)
        shape = tuple(env.observation_space.shape)
        self.obs_shape = shape
        self.free = free_coordinates(threat, shape)
        if len(self.free) == 0:
            raise ZodriveError("the threat model leaves no coordinate to perturb")
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (int(np.prod(shape)),), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (len(self.free),), np.float32)
        self._obs: np.ndarray | None = None

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        self._obs = np.asarray(obs, dtype=np.float32)
        return self._obs.reshape(-1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, info = self.env.reset(seed=seed, options=options)
        self.oracle.begin_episode()
        self.t, self.episode_return = 0, 0.0
        return self._observe(obs), info

    def step(self, action: np.ndarray):
        if self._obs is None:
            raise ZodriveError("AdversaryEnv.step before reset")
        fed = apply_action(self.threat, self._obs[None], np.asarray(action, dtype=np.float32)[None], self.free)
        self.oracle.begin_step(1)
        chosen = to_action(self.victim, self.oracle(fed), self.env.action_space)
        obs, reward, terminated, truncated, info = self.env.step(chosen)
        info = dict(info)
        info["victim_reward"] = float(reward)
        info["linf"] = float(np.abs(fed[0] - self._obs).max())
        self.t += 1
        self.episode_return += float(reward)
        if terminated or truncated:
            self.victim_returns.append(self.episode_return)
        return self._observe(obs), self._reward(float(reward), terminated), terminated, truncated, info

    def _reward(self, reward: float, terminated: bool) -> float:
        """`minus`: -r. `horizon`: 1 - r, and when the episode ends before the horizon T (a crash),
        T - t at once: the T - t steps the victim no longer drives count as steps of reward 0.
        The episode's sum is then T - (the victim's return): the same objective, credited when
        the crash happens instead of only through the discounted absence of later rewards."""
        if self.reward == "minus":
            return -reward
        assert self.horizon is not None
        return 1.0 - reward + (max(self.horizon - self.t, 0) if terminated else 0.0)

    def close(self) -> None:
        self.env.close()


def _card(out: Path, meta: dict[str, Any], train: dict[str, Any]) -> str:
    """CARD.md of a trained adversary: what it attacks, how it was trained, what it cost."""
    first, last = train["victim_return_first10"], train["victim_return_last10"]
    return "\n".join([
        f"# Learned adversary: {meta['victim']} at L-inf eps {meta['eps']:g}", "",
        "SA-RL's learned optimal adversary (Zhang et al., ICLR 2021): an SB3 PPO policy whose action "
        "a in [-1, 1]^d is the perturbation eps * a on the perturbable features (presence frozen), "
        "projected like every zodrive attack. Reward: "
        + ("minus the victim's environment reward." if meta["reward"] == "minus" else
           f"1 - the victim's reward per step, and at a crash the {meta['horizon']} - t steps left at once "
           "(sum: horizon - the victim's return)."), "",
        f"- victim: `{meta['victim']}` (SHA-256 {meta['victim_sha256'][:16]}..)"
        + (f" behind defense `{meta['defense']}`" if meta["defense"] else ""),
        f"- preset: {meta['preset'].get('name')}; observes the true observation only (0 queries per step at "
        "attack time)",
        *_pretrain_lines(train.get("pretrain")),
        f"- PPO training: {train['total_timesteps']} steps, seed {train['seed']}, {train['episodes']} episodes, "
        f"{train['wall_time_s']} s; victim queries {train['victim_queries']}; exploration: {train['exploration']}"
        + (f"; the first {train['critic_warmup']} steps trained the critic only" if train.get("critic_warmup") else ""),
        f"- victim return per training episode: first 10 {first if first is None else round(first, 2)}, "
        f"last 10 {last if last is None else round(last, 2)} (exploring adversary: not an evaluation)",
        "", "Use: `zodrive evaluate " + meta["victim"] + f" --attack learned:{out} --eps {meta['eps']:g}`"
        + (f" --defense {meta['defense']}" if meta["defense"] else ""), "",
    ])


def _pretrain_lines(fitted: dict[str, Any] | None) -> list[str]:
    """The card's lines on the amortized start (`zodrive.training.amortized`), one per round."""
    if not fitted:
        return []
    by = "" if fitted["margin"] is None else f" by a margin of {fitted['margin']:.3g}"
    settings = fitted.get("settings") or {}
    lines = [f"- start fitted before PPO (`--pretrain-rounds`): a surrogate distilled from {fitted['queries']} counted "
             f"victim queries ({settings.get('probes', 4)} random points per visited state, uniform in the "
             f"ball), the mean action fitted to make it take the target action{by} "
             f"(target: {fitted.get('target', 'auto')}); {fitted['wall_time_s']} s. Per round (driving "
             "with the previous round's fit):"]
    for r in fitted["rounds"]:
        lines.append(f"  - round {r['round']}: {r['steps']} steps, victim return {r['victim_return']:.2f}, "
                     f"target action taken on {r['target_share']:.1%} of steps; {surrogate_fit(r)}")
    return lines


@one_torch_thread  # small MLPs: one thread is fastest and lets runs share cores
def attack_train(
    model: str,
    preset: dict[str, Any],
    eps: float,
    steps: int,
    out: Path,
    *,
    seed: int = 0,
    defense: str | None = None,
    reward: str = "minus",
    pretrain: Pretrain | None = None,
    target: str = "auto",
    explore_std: float | None = None,
    critic_warmup: int = 0,
    force: bool = False,
    progress_bar: bool = True,
) -> Path:
    """Train a learned adversary against `model` (behind `defense`) at L-inf `eps` for `steps`
    environment steps of PPO (0 allowed after `pretrain`: the fitted start alone), first fitting
    its mean action as an amortized transfer attack with `pretrain` (`zodrive.training.amortized`)
    towards `target` (as evaluate's --target; auto: the search attacks' default);
    `explore_std`: PPO explores with a Gaussian of that std per action dimension, redrawn every
    step, instead of gSDE (a fitted start's mean survives noise on that scale, not at the box's
    corners); `critic_warmup`: the first that many of the `steps` update PPO's value function
    only, the actor frozen (advantages from an untrained critic move a fitted mean at random);
    write the model folder `out` and return it."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    from zodrive.policies.policy import resolve
    from zodrive.system import load_policy
    from zodrive.training.recipes import check_run_folder
    from zodrive.attacks.spec import AttackSpec
    from zodrive.envs import attack_context, make_env
    from zodrive.runinfo import sha256, write_atomic, write_json, write_run_info

    if not (isinstance(steps, int) and steps >= (0 if pretrain else 1)):
        raise ZodriveError(f"steps must be an integer >= 1 (>= 0 with a pretrained start), not {steps}")
    if explore_std is not None and not (isinstance(explore_std, float) and 0 < explore_std <= 2):
        raise ZodriveError("explore_std must be a float in (0, 2] (units of eps per action dimension), "
                           f"not {explore_std}")
    if explore_std is not None and not steps:
        raise ZodriveError("--explore-std sets PPO's exploration; with --steps 0 no PPO step is taken")
    if not (isinstance(critic_warmup, int) and 0 <= critic_warmup < max(steps, 1)):
        raise ZodriveError(f"--critic-warmup {critic_warmup} must be below --steps {steps}: "
                           "PPO's actor would never train")
    if pretrain is None and target != "auto":
        raise ZodriveError(f"--target {target} is the per-step target of the fitted start; it applies with "
                           "--pretrain-rounds (PPO alone lowers the victim's return, with no per-step target)")
    if not (np.isfinite(eps) and eps > 0):
        raise ZodriveError(f"eps must be > 0, not {eps}")
    if resolve(model).kind != "model":
        raise ZodriveError("attack-train attacks a model file (SB3 zip or model folder): an adversary is tied "
                           "to the file it was trained against by its SHA-256")
    if defense is not None:
        from zodrive.defense import keeps_state

        if keeps_state(defense):
            raise ZodriveError(f"the {defense} defense keeps state over an episode; attack-train supports "
                               "stateless defenses (shield[@EPS], close-shield[@EPS], smooth@SIGMA)")
    check_run_folder(out, resume=False, force=force, resumable=False)
    victim = load_policy(model, preset, defense)  # safe loader; the defended system if a defense is named
    context = attack_context(preset)
    spec = AttackSpec(attack="learned", eps=float(eps))
    threat = spec.threat(context["features"], context["bounds"])
    objective = None
    if pretrain is not None:  # the per-step objective the start is fitted to: every search attack's default
        objective = AttackSpec(eps=float(eps), target=target).objective(
            victim.kind, context["n_actions"], context.get("action_names"), context.get("action_bounds"))
        check(pretrain, victim.kind, objective)
    file = Path(resolve(model).ref)
    ppo = dict(PPO_DEFAULTS)
    ppo["n_steps"] = min(ppo["n_steps"], max(steps, 8))  # a tiny run (tests) still completes its rollouts
    ppo["batch_size"] = min(ppo["batch_size"], ppo["n_steps"])
    log_std = LOG_STD_INIT
    if explore_std is not None:  # a plain Gaussian of the stated std (SB3: state-independent log std)
        ppo.update(use_sde=False)
        ppo.pop("sde_sample_freq")
        log_std = float(np.log(explore_std))
    horizon = None
    if reward == "horizon":
        from zodrive.envs import scenario

        max_return = scenario(preset).max_return  # known where every step earns at most 1 (normalized highway-env)
        if max_return is None:
            raise ZodriveError(f"--reward horizon needs a preset whose steps earn at most 1 and whose length is "
                               f"known; {preset.get('name')!r} is not one: use --reward minus")
        horizon = int(max_return)
    inner = AdversaryEnv(make_env(preset), victim, threat, reward=reward, horizon=horizon)
    assert inner.action_space.shape is not None  # a Box (`AdversaryEnv`)
    meta = {"format": FORMAT, "attack": "learned", "victim": str(model), "victim_sha256": sha256(file),
            "preset": preset, "defense": defense, "defense_version": defense and defense_version(defense),
            "eps": float(eps), "norm": threat.norm, "frozen": list(threat.frozen), "kind": victim.kind,
            "obs_shape": list(victim.obs_shape),
            "action_dim": int(inner.action_space.shape[0]), "reward": reward, "horizon": horizon}
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("model.zip", META_FILE, "train.json", "CARD.md", "monitor.monitor.csv"):
        (out / stale).unlink(missing_ok=True)  # --force: nothing of an older run is mistaken for this one's
    write_run_info(out, {"victim": str(model), "preset": preset, "defense": defense, "eps": float(eps),
                         "steps": steps, "reward": reward, "algo": "ppo", "ppo": ppo,
                         "log_std_init": log_std, "explore_std": explore_std, "critic_warmup": critic_warmup,
                         "pretrain": pretrain and pretrain.__dict__, "target": target}, seed)
    env = Monitor(inner, filename=str(out / "monitor"))
    venv = DummyVecEnv([lambda: env])
    venv.seed(seed)
    agent = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0,
                policy_kwargs={"log_std_init": log_std}, **ppo)
    fitted = None
    if pretrain is not None:
        start = time.perf_counter()
        with_env = make_env(preset)
        assert objective is not None  # set above with `pretrain`
        fitted = fit_start(agent.policy, with_env, victim, threat, objective, inner.free, pretrain, seed)
        with_env.close()
        fitted["wall_time_s"] = round(time.perf_counter() - start, 1)
        fitted["target"] = target
    start = time.perf_counter()
    if critic_warmup:  # the value function learns the fitted start's returns; the actor stays as fitted
        actor = [*agent.policy.mlp_extractor.policy_net.parameters(), *agent.policy.action_net.parameters(),
                 agent.policy.log_std]
        for param in actor:
            param.requires_grad_(False)  # no gradient: Adam leaves them alone
        agent.learn(total_timesteps=critic_warmup, progress_bar=progress_bar)
        for param in actor:
            param.requires_grad_(True)
    if steps - critic_warmup > 0:
        agent.learn(total_timesteps=steps - critic_warmup, progress_bar=progress_bar,
                    reset_num_timesteps=not critic_warmup)
    wall = time.perf_counter() - start
    agent.save(out / "model.zip")
    returns = list(inner.victim_returns)  # the victim's return per training episode
    done = int(agent.num_timesteps)
    train = {"algo": "ppo", "kind": "learned adversary (SA-RL, Zhang et al. ICLR 2021)", "victim": str(model),
             "defense": defense, "eps": float(eps), "total_timesteps": done, "requested_steps": steps, "seed": seed,
             "wall_time_s": round(wall, 1), "steps_per_s": round(done / wall, 1) if done else None,
             "victim_queries": int(inner.oracle.total_queries),
             "queries_per_step": inner.oracle.total_queries / done if done else None, "pretrain": fitted,
             "episodes": len(returns),
             "victim_return_first10": float(np.mean(returns[:10])) if returns else None,
             "victim_return_last10": float(np.mean(returns[-10:])) if returns else None,
             "reward": reward, "horizon": horizon,
             "exploration": f"Gaussian, std {explore_std}" if explore_std is not None else
             f"gSDE, log std {LOG_STD_INIT}, redrawn every {PPO_DEFAULTS['sde_sample_freq']} steps",
             "critic_warmup": critic_warmup}
    write_json(out / "train.json", train)
    write_atomic(out / META_FILE, json.dumps(meta, indent=2) + "\n")
    write_atomic(out / "CARD.md", _card(out, meta, train))
    venv.close()
    return out
