"""The learned adversary (SA-RL): its environment, its folder and `--attack learned:DIR`.

No highway-env training: a toy environment for the adversary's MDP, CartPole and tiny
models for the command line."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from toys import FEATURES, linear_victim, observations
from zodrive.training.adversary import AdversaryEnv
from zodrive.attacks import AttackSpec, ThreatModel
from zodrive.attacks.learned import apply_action, free_coordinates
from zodrive.errors import ZodriveError
from zodrive.cli import main


class ToyRoad(gym.Env):
    """(5, 5) observations in [-1, 1] (presence first), 5 actions; the reward depends on the
    action the victim takes, so the adversary's reward tells whether it is the victim's."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (5, 5), np.float32)
    action_space = gym.spaces.Discrete(5)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def _obs(self) -> np.ndarray:
        return observations(1, seed=int(self.np_random.integers(1 << 30)))[0]

    def step(self, action):
        self.t += 1
        return self._obs(), 0.1 * (int(action) + 1), self.t >= 10, False, {"action": int(action)}


def _threat(eps: float = 0.05) -> ThreatModel:
    return AttackSpec(attack="learned", eps=eps).threat(FEATURES, (-1.0, 1.0))


def test_the_perturbation_stays_in_the_ball_the_mask_and_the_box() -> None:
    threat = _threat(0.05)
    x0 = observations(64)
    x0[:3, 1:, 1] = 0.99  # near the box's edge
    free = free_coordinates(threat, x0.shape[1:])
    assert len(free) == 20  # presence (one column of five rows) is frozen
    rng = np.random.default_rng(0)
    for scale in (0.5, 1.0, 10.0):  # actions beyond [-1, 1] are clipped, never amplified
        x = apply_action(threat, x0, scale * rng.standard_normal((64, len(free))), free)
        assert np.abs(x - x0).max() <= 0.05 + 1e-7
        assert np.array_equal(x[:, :, 0], x0[:, :, 0])  # presence untouched
        assert x.max() <= 1.0 and x.min() >= -1.0


def test_adversary_env_reward_is_minus_the_victims_and_queries_are_counted() -> None:
    victim = linear_victim()
    env = AdversaryEnv(ToyRoad(), victim, _threat())
    obs, _ = env.reset(seed=3)
    assert obs.shape == (25,) and env.action_space.shape == (20,)
    steps = 0
    done = False
    rng = np.random.default_rng(1)
    while not done:
        before = env._obs.copy()
        action = rng.uniform(-1, 1, 20).astype(np.float32)
        fed = apply_action(env.threat, before[None], action[None], env.free)
        expected = int(victim.query(fed).argmax())  # what the victim does on the perturbed observation
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        assert info["action"] == expected and reward == -info["victim_reward"] == pytest.approx(-0.1 * (expected + 1))
        assert info["linf"] <= 0.05 + 1e-7
        done = terminated or truncated
    assert env.oracle.total_queries == steps  # one query per step: the victim's decision


def _victim(tmp_path: Path, seed: int = 0) -> Path:
    from stable_baselines3 import DQN

    model = DQN("MlpPolicy", gym.make("CartPole-v1"), seed=seed, device="cpu", buffer_size=1000,
                learning_starts=50).learn(100)
    path = tmp_path / f"victim{seed}.zip"
    model.save(path)
    return path


CART = ["--env-id", "CartPole-v1", "--obs-bounds=-0.4,0.4"]  # inside the declared box (x: 4.8, angle: 0.42)


def _error(capsys, args: list[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, Path]:
    """A victim and an adversary trained against it."""
    tmp = tmp_path_factory.mktemp("learned")
    victim = _victim(tmp)
    assert main(["attack-train", str(victim), *CART, "--eps", "0.1", "--steps", "64", "--out", str(tmp / "adv"),
                 "--seed", "1", "--no-progress"]) == 0
    return victim, tmp / "adv"


def test_attack_train_writes_a_model_folder(trained) -> None:
    victim, adv = trained
    for name in ("model.zip", "adversary.json", "train.json", "config.yaml", "run.json", "CARD.md"):
        assert (adv / name).is_file(), name
    train = json.loads((adv / "train.json").read_text())
    meta = json.loads((adv / "adversary.json").read_text())
    assert train["victim_queries"] == train["total_timesteps"] >= 64 and train["queries_per_step"] == 1.0
    assert meta["eps"] == 0.1 and meta["action_dim"] == 4 and "victim_action" not in meta
    assert "--attack learned:" in (adv / "CARD.md").read_text()


def test_attack_learned_reads_it_in_the_ball_deterministic_and_lockstep_equal(trained, tmp_path: Path, capsys,
                                                                             monkeypatch) -> None:
    from stable_baselines3 import PPO

    victim, adv = trained
    monkeypatch.setattr(PPO, "load", lambda *a, **k: pytest.fail("the adversary must be read by the safe loader"))
    records = {}
    for adversary, envs in ((adv, 1), (adv, 3)):
        out = tmp_path / f"{adversary.name}-{envs}"
        assert main(["evaluate", str(victim), *CART, "--attack", f"learned:{adversary}", "--eps", "0.1",
                     "--episodes", "3", "--envs", str(envs), "--out", str(out), "--no-progress"]) == 0, \
            capsys.readouterr().err
        assert "n/a" in capsys.readouterr().out
        summary = json.loads((out / "summary.json").read_text())
        assert summary["max_linf"] <= 0.1 + 1e-6 and summary["attack_success_rate"] is None
        assert summary["queries_per_step"] == 0.0
        records[out.name] = [{k: v for k, v in json.loads(line).items()}
                             for line in (out / "episodes.jsonl").read_text().splitlines()]
        steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
        assert max(s["linf"] for s in steps) <= 0.1 + 1e-6
    for name in ("adv",):  # N episodes side by side = N one-episode runs, bit for bit
        one = sorted(records[f"{name}-1"], key=lambda r: r["episode"])
        three = sorted(records[f"{name}-3"], key=lambda r: r["episode"])
        assert one == three


def test_learned_adversary_mistakes_are_one_line_errors(trained, tmp_path: Path, capsys) -> None:
    victim, adv = trained
    base = ["evaluate", str(victim), *CART, "--episodes", "1", "--no-progress"]
    assert "trained at linf eps 0.1" in _error(capsys, [*base, "--attack", f"learned:{adv}", "--eps", "0.2"])
    assert "not found" in _error(capsys, [*base, "--attack", f"learned:{tmp_path / 'nope'}", "--eps", "0.1"])
    (tmp_path / "empty").mkdir()
    assert "not a trained adversary" in _error(capsys, [*base, "--attack", f"learned:{tmp_path / 'empty'}"])
    assert "needs a trained adversary" in _error(capsys, [*base, "--attack", "learned", "--eps", "0.1"])
    assert "has no effect" in _error(capsys, [*base, "--attack", f"learned:{adv}", "--eps", "0.1", "--target", "1"])
    assert "has no effect" in _error(capsys, [*base, "--attack", f"learned:{adv}", "--eps", "0.1", "--patience", "2"])
    assert "has no effect" in _error(capsys, [*base, "--attack", f"learned:{adv}", "--eps", "0.1", "--attack-seed", "3"])
    other = _victim(tmp_path, seed=5)
    assert "train one against this model" in _error(
        capsys, ["evaluate", str(other), *CART, "--episodes", "1", "--attack", f"learned:{adv}", "--eps", "0.1"])
    assert "adversary" in _error(  # trained on another preset and against a model file, not a baseline
        capsys, ["evaluate", "baseline:rules", "--preset", "discrete", "--episodes", "1", "--attack",
                 f"learned:{adv}", "--eps", "0.1"])
    assert "already holds a run" in _error(capsys, ["attack-train", str(victim), *CART, "--eps", "0.1", "--steps",
                                                    "8", "--out", str(adv)])
    assert "--reward horizon needs" in _error(capsys, ["attack-train", str(victim), *CART, "--eps", "0.1", "--steps",
                                                       "8", "--reward", "horizon", "--out", str(tmp_path / "h")])
    assert not (tmp_path / "h").exists()  # a refused run leaves no folder behind
    assert "attacks a model file" in _error(capsys, ["attack-train", "baseline:faster", "--eps", "0.1", "--steps",
                                                     "8", "--out", str(tmp_path / "b")])


def test_an_adversary_trained_against_another_shield_version_is_refused(trained, tmp_path: Path) -> None:
    import shutil

    from zodrive.attacks.learned import check_adversary
    from zodrive.defense.shield import VERSION

    victim, adv = trained
    meta = json.loads((adv / "adversary.json").read_text())
    assert meta["defense"] is None and meta["defense_version"] is None
    old = tmp_path / "old"
    shutil.copytree(adv, old)
    for version, refused in ((VERSION - 1, True), (None, True), (VERSION, False)):
        (old / "adversary.json").write_text(json.dumps({**meta, "defense": "shield@0.02", "defense_version": version}))
        if refused:
            with pytest.raises(ZodriveError, match=f"this zodrive's is version {VERSION}"):
                check_adversary(old, model_file=str(victim), preset=meta["preset"], defense="shield@0.02",
                                defense_version=VERSION)
        else:
            check_adversary(old, model_file=str(victim), preset=meta["preset"], defense="shield@0.02",
                                defense_version=VERSION)


@pytest.mark.parametrize("horizon", [10, 25])
def test_horizon_reward_sums_to_the_horizon_minus_the_victims_return(horizon: int) -> None:
    env = AdversaryEnv(ToyRoad(), linear_victim(), _threat(), reward="horizon", horizon=horizon)
    env.reset(seed=0)
    total, victim, done = 0.0, 0.0, False
    while not done:
        _, reward, terminated, truncated, info = env.step(np.zeros(20, dtype=np.float32))
        total, victim, done = total + reward, victim + info["victim_reward"], terminated or truncated
    # the toy ends after 10 steps: with horizon 25 the 15 steps it cut off count as steps of reward 0
    assert total == pytest.approx(horizon - victim) and env.victim_returns == [pytest.approx(victim)]


def test_horizon_reward_needs_a_known_horizon() -> None:
    with pytest.raises(ZodriveError, match="horizon"):
        AdversaryEnv(ToyRoad(), linear_victim(), _threat(), reward="horizon")


class ToyCar(ToyRoad):
    """`ToyRoad` with a continuous action in [-1, 1]^2."""

    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def step(self, action):
        self.t += 1
        return self._obs(), 0.1, self.t >= 10, False, {}


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_a_pretrained_start_makes_a_black_box_victim_take_the_target_action(kind: str) -> None:
    """The amortized start (`--pretrain-rounds`): from queries alone (the victim offers no
    gradients), the adversary's mean action comes to make the victim take the target (FASTER;
    [1, 0.5] within 0.2 for a continuous victim) on most states where it took it on few; every
    query is counted: one decision and `probes` ball points per step driven."""
    import torch
    from stable_baselines3 import PPO

    from zodrive.training.amortized import Pretrain, _mean, pretrain
    from zodrive.attacks.objectives import make_objective
    from zodrive.attacks.victim import Victim

    toy = linear_victim(hidden=16, kind=kind)
    victim = Victim(query=toy.query, kind=kind, obs_shape=(5, 5))  # no `differentiable`: black-box
    objective = make_objective(kind, "FASTER" if kind == "discrete" else "1,0.5")
    threat = _threat(0.3)
    road = ToyRoad() if kind == "discrete" else ToyCar()
    env = AdversaryEnv(road, victim, threat)
    agent = PPO("MlpPolicy", env, seed=0, device="cpu", n_steps=64, batch_size=64,
                policy_kwargs={"log_std_init": -1.0})
    free = env.free
    states = observations(400, seed=7)

    def target_share() -> float:
        with torch.no_grad():
            actions = _mean(agent.policy, torch.from_numpy(states.reshape(len(states), -1))).numpy()
        out = torch.from_numpy(victim.query(apply_action(threat, states, actions, free)))
        return float(objective.success(out[:, None], out)[:, 0].float().mean())

    before = target_share()
    settings = Pretrain(rounds=2, episodes=20, probes=4, epochs=20 if kind == "discrete" else 60, hidden=64)
    fitted = pretrain(agent.policy, type(road)(), victim, threat, objective, free, settings, 0)
    after = target_share()
    if kind == "discrete":
        assert after >= 0.8 > before + 0.3, (before, after)
    else:  # the toy's target is reached only within 0.2 on both outputs: the surrogate's error (RMSE ~0.14) shows
        assert after > 3 * before + 0.05 and fitted["rounds"][-1]["surrogate_rmse"] < 0.25, (before, after)
    steps = sum(r["steps"] for r in fitted["rounds"])
    assert fitted["queries"] == steps * (1 + settings.probes) == fitted["rounds"][-1]["queries"]


def test_pretraining_mistakes_are_one_line_errors(trained, tmp_path: Path, capsys) -> None:
    victim, _ = trained
    base = ["attack-train", str(victim), *CART, "--eps", "0.1", "--out", str(tmp_path / "a"), "--no-progress"]
    assert "--pretrain-episodes applies with --pretrain-rounds" in _error(capsys, [*base, "--steps", "8",
                                                                                   "--pretrain-episodes", "3"])
    assert "--steps 0 trains nothing" in _error(capsys, [*base, "--steps", "0"])
    assert "do not have" in _error(capsys, [*base, "--steps", "0", "--pretrain-rounds", "1"])  # CartPole: no FASTER
    assert "--pretrain-probes applies with --pretrain-rounds" in _error(capsys, [*base, "--steps", "8",
                                                                                  "--pretrain-probes", "8"])
    for removed in (["--victim-action"], ["--pretrain-loss", "decisions"]):  # removed (issue 45)
        assert "unrecognized arguments" in _error(capsys, [*base, "--steps", "8", *removed])
    # argparse reads --pretrain-probe as a prefix of --pretrain-probes, whose value is an integer
    assert "expected an integer" in _error(capsys, [*base, "--steps", "8", "--pretrain-probe", "vertices"])
    assert not (tmp_path / "a").exists()  # refused before anything is written


def test_attack_train_target_is_the_fitted_start_s_and_is_recorded(trained, tmp_path: Path, capsys) -> None:
    """`attack-train --target` sets the per-step target the start is fitted to (here CartPole's action 1, else not
    0), recorded in train.json, run.json and the card; without --pretrain-rounds it would do nothing: an error."""
    victim, _ = trained
    base = ["attack-train", str(victim), *CART, "--eps", "0.1", "--no-progress"]
    assert "--target 1 is the per-step target of the fitted start" in _error(capsys, [*base, "--steps", "8", "--target",
                                                                                    "1", "--out", str(tmp_path / "a")])
    assert "unknown target 'FLY'" in _error(capsys, [*base, "--steps", "0", "--pretrain-rounds", "1", "--target", "FLY",
                                                     "--out", str(tmp_path / "a")])
    assert not (tmp_path / "a").exists()
    out = tmp_path / "b"
    assert main([*base, "--steps", "0", "--pretrain-rounds", "1", "--pretrain-episodes", "1", "--target", "1,not:0",
                 "--out", str(out)]) == 0
    assert json.loads((out / "train.json").read_text())["pretrain"]["target"] == "1,not:0"
    assert "target: 1,not:0" in (out / "config.yaml").read_text()
    assert "(target: 1,not:0)" in (out / "CARD.md").read_text()


def test_the_card_describes_a_fitted_start_of_either_kind() -> None:
    from zodrive.training.adversary import _pretrain_lines

    rounds = [{"round": 0, "steps": 9, "victim_return": 1.5, "target_share": 0.25, "surrogate_agreement": 0.9}]
    discrete = _pretrain_lines({"queries": 45, "margin": 0.3, "wall_time_s": 1.0, "rounds": rounds})
    assert "4 random points per visited state, uniform in the ball" in discrete[0]
    assert "by a margin of 0.3" in discrete[0] and "on 25.0% of steps" in discrete[1] and "90.0%" in discrete[1]
    rounds = [{**rounds[0], "surrogate_rmse": 0.12}]
    del rounds[0]["surrogate_agreement"]
    continuous = _pretrain_lines({"queries": 45, "margin": None, "wall_time_s": 1.0, "rounds": rounds})
    assert "margin" not in continuous[0] and "RMSE 0.120" in continuous[1]
    assert _pretrain_lines(None) == []


def test_explore_std_trains_with_a_plain_gaussian_of_that_std(trained, tmp_path: Path, capsys) -> None:
    """`--explore-std S`: PPO explores with a state-independent Gaussian of std S (the default's
    gSDE noise is state-dependent); the record and the card say which; mistakes are one-line errors."""
    import torch
    from stable_baselines3 import PPO

    victim, adv = trained
    out = tmp_path / "g"
    assert main(["attack-train", str(victim), *CART, "--eps", "0.1", "--steps", "16", "--explore-std", "0.2",
                 "--out", str(out), "--seed", "1", "--no-progress"]) == 0
    model = PPO.load(out / "model.zip", device="cpu")  # our own file, written by this test
    assert not model.policy.use_sde
    obs = torch.zeros((3, *model.observation_space.shape))
    std = model.policy.get_distribution(obs).distribution.stddev
    assert torch.allclose(std, torch.full_like(std, 0.2), rtol=0.05)  # 16 steps barely move it from 0.2
    assert json.loads((out / "train.json").read_text())["exploration"] == "Gaussian, std 0.2"
    assert "exploration: Gaussian, std 0.2" in (out / "CARD.md").read_text()
    assert json.loads((adv / "train.json").read_text())["exploration"].startswith("gSDE")
    base = ["attack-train", str(victim), *CART, "--eps", "0.1", "--out", str(tmp_path / "b"), "--no-progress"]
    assert "no PPO step is taken" in _error(capsys, [*base, "--steps", "0", "--pretrain-rounds", "1",
                                                     "--explore-std", "0.2"])
    assert "a finite number > 0" in _error(capsys, [*base, "--steps", "8", "--explore-std", "0"])
    assert "in (0, 2]" in _error(capsys, [*base, "--steps", "8", "--explore-std", "3"])
    assert not (tmp_path / "b").exists()


def test_critic_warmup_trains_the_value_function_only_then_both(trained, tmp_path: Path, monkeypatch,
                                                                 capsys) -> None:
    """`--critic-warmup N`: PPO's first learn call (N steps) leaves the actor's weights exactly
    as they were and moves the critic's; the second moves the actor."""
    import torch
    from stable_baselines3 import PPO

    victim, _ = trained
    snapshots: list[tuple[list[torch.Tensor], list[torch.Tensor]]] = []
    original = PPO.learn

    def weights(agent: PPO) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        policy = agent.policy
        actor = [p.detach().clone() for p in [*policy.mlp_extractor.policy_net.parameters(),
                                               *policy.action_net.parameters(), policy.log_std]]
        critic = [p.detach().clone() for p in [*policy.mlp_extractor.value_net.parameters(),
                                                *policy.value_net.parameters()]]
        return actor, critic

    def learn(self: PPO, *args, **kwargs):
        snapshots.append(weights(self))
        out = original(self, *args, **kwargs)
        snapshots.append(weights(self))
        return out

    monkeypatch.setattr(PPO, "learn", learn)
    out = tmp_path / "w"
    assert main(["attack-train", str(victim), *CART, "--eps", "0.1", "--steps", "32", "--critic-warmup", "16",
                 "--explore-std", "0.3", "--out", str(out), "--seed", "1", "--no-progress"]) == 0
    assert len(snapshots) == 4  # before / after the warm-up, before / after PPO proper
    same = lambda a, b: all(torch.equal(x, y) for x, y in zip(a, b))  # noqa: E731
    assert same(snapshots[0][0], snapshots[1][0]) and not same(snapshots[0][1], snapshots[1][1])
    assert not same(snapshots[2][0], snapshots[3][0])
    assert json.loads((out / "train.json").read_text())["critic_warmup"] == 16
    assert "the first 16 steps trained the critic only" in (out / "CARD.md").read_text()
    base = ["attack-train", str(victim), *CART, "--eps", "0.1", "--out", str(tmp_path / "b"), "--no-progress"]
    assert "must be below --steps 8" in _error(capsys, [*base, "--steps", "8", "--critic-warmup", "8"])
    assert not (tmp_path / "b").exists()
