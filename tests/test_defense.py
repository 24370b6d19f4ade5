"""Adversarial training: attacked observations go into the replay buffer, crafted against
the network being trained; the control run trains the same way without the attack."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3 import DQN
from stable_baselines3.common.vec_env import DummyVecEnv

from zodrive.policies.victims import sb3_victim
from zodrive.attacks import AttackSpec
from zodrive.envs import load_preset, make_env
from zodrive.system import make_attacked_env

PRESET = load_preset("discrete", ["max_episode_steps=30"])


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A briefly trained DQN run that the defenses continue from (read only)."""
    from zodrive.cli import main

    out = tmp_path_factory.mktemp("base") / "base"
    assert main(["train", "--algo", "dqn", "--steps", "200", "--out", str(out), "--no-progress",
                 "--set", "hyperparameters.learning_starts=100", "--env-set", "max_episode_steps=30"]) == 0
    return out


def test_replay_buffer_holds_attacked_observations_against_the_live_network() -> None:
    model = DQN("MlpPolicy", make_env(PRESET), learning_starts=0, buffer_size=1000, train_freq=1, seed=0,
                policy_kwargs={"net_arch": [16]})
    victim = sb3_victim(model)
    attacked = make_attacked_env(PRESET, victim, AttackSpec(steps=5, n_directions=4, eps=0.2, target="none"))
    pairs: list[tuple[np.ndarray, np.ndarray]] = []
    observe = attacked.observation

    def spy(obs: np.ndarray) -> np.ndarray:
        adv = observe(obs)
        pairs.append((obs.copy(), adv.copy()))
        return adv

    attacked.observation = spy  # type: ignore[method-assign]
    model.set_env(DummyVecEnv([lambda: attacked]))
    probe = np.stack([make_env(PRESET).reset(seed=s)[0] for s in range(3)])
    before = victim.query(probe)
    model.learn(40)
    clean, adv = (np.stack(x) for x in zip(*pairs))
    stored = model.replay_buffer.observations[:40, 0]
    assert np.abs(adv - clean).max() > 0  # the attack did change what the agent saw
    assert all(any(np.array_equal(s, a) for a in adv) for s in stored)  # ... and that is what it learned from
    after = victim.query(probe)
    assert not np.allclose(before, after)  # the attacker queries the network being updated
    with torch.no_grad():
        np.testing.assert_allclose(after, model.q_net(torch.from_numpy(probe)).numpy(), atol=1e-6)


def test_control_run_is_the_same_training_without_the_attack(base: Path, tmp_path: Path, monkeypatch) -> None:
    from zodrive.cli import main
    from zodrive.system import AttackWrapper

    control = tmp_path / "control"
    assert main(["adv-train", str(base), "--no-attack", "--steps", "60", "--warmup", "40", "--out", str(control), "--no-progress",
                 "--trust-model", "--env-set", "max_episode_steps=30"]) == 0
    train = json.loads((control / "train.json").read_text())
    assert train["kind"] == "control (no attack)" and train["attack_queries"] == 0
    # the attacked run with its attack neutralized: the attack runs (queries, random stream) but the
    # clean observation is fed, so all that is left to differ from the control is the training itself
    attack_and_feed = AttackWrapper.observation

    def feed_clean(self: AttackWrapper, obs: np.ndarray) -> np.ndarray:
        attack_and_feed(self, obs)
        return obs

    monkeypatch.setattr(AttackWrapper, "observation", feed_clean)
    attacked = tmp_path / "attacked"
    assert main(["adv-train", str(base), "--attack", "uniform-noise", "--steps", "60", "--warmup", "40", "--out", str(attacked),
                 "--no-progress", "--trust-model", "--env-set", "max_episode_steps=30"]) == 0
    monkeypatch.undo()
    assert json.loads((attacked / "train.json").read_text())["attack_queries"] > 0  # the attack did run
    import yaml

    runs = [yaml.safe_load((folder / "config.yaml").read_text()) for folder in (control, attacked)]
    differs = {k for k in set(runs[0]) | set(runs[1]) if runs[0].get(k) != runs[1].get(k)}
    assert differs == {"attack"}  # source, preset, steps, warmup, noise, method: the same training but the attack
    assert runs[0]["attack"] is None and runs[1]["attack"]["attack"] == "uniform-noise"
    seeds = [json.loads((folder / "run.json").read_text())["seed"] for folder in (control, attacked)]
    assert seeds[0] == seeds[1]
    from zodrive.policies.safe_load import read_plain

    # same settings, same seed, same warm-up, exploration and updates: the very same network, bit for bit
    first, second = read_plain(control / "model.zip")[1], read_plain(attacked / "model.zip")[1]
    assert first.keys() == second.keys() and all(torch.equal(first[k], second[k]) for k in first)
    start = read_plain(base / "model.zip")[1]
    assert not all(torch.equal(first[k], start[k]) for k in first)  # ... and the training did change it


def test_sa_dqn_regularizer_is_the_worst_case_margin_inside_the_ball() -> None:
    from zodrive.training.dqn_variants import SADQN

    model = SADQN("MlpPolicy", make_env(PRESET), seed=0, policy_kwargs={"net_arch": [16]})
    x = torch.from_numpy(np.stack([make_env(PRESET).reset(seed=s)[0] for s in range(8)])).float()
    mask = np.ones((5, 5), dtype=np.float32)
    mask[:, 0] = 0
    model.configure_robust(eps=0.2, kappa=1.0, pgd_steps=10, mask=mask, eps_ramp=0.0, hinge=1e9)
    model.num_timesteps = 0
    reg = model.extra_loss(x)
    with torch.no_grad():
        q = model.q_net(x)
        best = q.argmax(dim=1, keepdim=True)
        clean_margin = (q.scatter(1, best, float("-inf")).amax(dim=1) - q.gather(1, best).squeeze(1)).mean()
    assert reg is not None and reg.item() > clean_margin.item()  # PGD found worse points than the clean ones
    reg.backward()  # differentiable in the network's weights
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.q_net.parameters())
    model.configure_robust(eps=0.2, eps_ramp=0.5, total_steps=100)
    model.num_timesteps = 0
    assert model.current_eps() == 0.0  # the ramp starts at the first update
    model.num_timesteps = 25
    assert model.current_eps() == pytest.approx(0.1)


def test_robust_train_sa_runs_and_records_its_method(base: Path, tmp_path: Path) -> None:
    from zodrive.cli import main

    out = tmp_path / "sa"
    assert main(["robust-train", str(base), "--method", "sa", "--eps", "0.05", "--steps", "150", "--warmup", "30",
                 "--out", str(out), "--no-progress", "--trust-model", "--env-set", "max_episode_steps=30"]) == 0
    train = json.loads((out / "train.json").read_text())
    assert train["kind"] == "sa-dqn" and train["method"]["eps"] == 0.05
    progress = (out / "progress.csv").read_text()
    assert "train/regularizer" in progress


def test_robust_distillation_writes_a_model_every_command_reads(tmp_path: Path) -> None:
    """The student is an ordinary DQN zip (read without unpickling); its robustness term makes
    it harder to flip inside the ball than the teacher, on the teacher's own states."""
    import torch

    from zodrive.policies.loading import load_network
    from zodrive.attacks.threat import worst_in_ball
    from zodrive.training.distill import distill
    from zodrive.envs import load_preset

    preset = load_preset("discrete", ["max_episode_steps=60"])
    out = distill("models/dqn-driver", preset, 0.05, 300, tmp_path / "d", epochs=5)
    train = json.loads((tmp_path / "d" / "train.json").read_text())
    assert train["method"]["name"] == "robust-distillation" and 0 <= train["clean_agreement"] <= 1
    teacher = load_network("models/dqn-driver", preset)
    student = load_network(out, preset)  # the safe loader rebuilds it: nothing in the zip is unpickled
    assert student.n_outputs == 5 and not torch.equal(student.net[0].weight, teacher.net[0].weight)
    from zodrive.envs import make_env
    from zodrive.policies.victims import network_victim
    from zodrive.evaluation.rollout import clean_states

    x = torch.as_tensor(clean_states(make_env(preset), network_victim(teacher.net, "discrete", (5, 5)), 7, 60))
    mask = torch.ones(5, 5)
    mask[:, 0] = 0

    def flips(net: torch.nn.Module) -> float:
        y = net(x.reshape(len(x), -1)).argmax(dim=1)
        ce = lambda z: torch.nn.functional.cross_entropy(net(z.reshape(len(z), -1)), y, reduction="none")  # noqa: E731
        adv = worst_in_ball(ce, x, 0.05, 10, mask, -1.0, 1.0)
        return float((net(adv.reshape(len(x), -1)).argmax(dim=1) != y).float().mean())

    assert flips(student.net) < flips(teacher.net)


def test_sa_ddpg_shrinks_the_worst_action_change_inside_the_ball() -> None:
    """SA-DDPG's extra actor steps lower max ||pi(x') - pi(x)||^2 over the ball on replayed states;
    the regular DDPG update is left as SB3 makes it."""
    from stable_baselines3.common.logger import configure

    from zodrive.training.state_adversarial import SADDPG
    from zodrive.attacks.threat import worst_in_ball
    from zodrive.envs import load_preset

    preset = load_preset("continuous", ["max_episode_steps=30"])
    model = SADDPG("MlpPolicy", make_env(preset), seed=0, device="cpu", learning_starts=10**9,
                   policy_kwargs={"net_arch": [32, 32]})
    model.learn(60)  # fills the buffer, no updates
    mask = np.ones((5, 5), dtype=np.float32)
    mask[:, 0] = 0
    model.configure_robust(eps=0.1, kappa=10.0, pgd_steps=5, mask=mask, eps_ramp=0.0)
    model.set_logger(configure(None, []))
    x0 = torch.as_tensor(model.replay_buffer.observations[:60, 0])
    torch.manual_seed(0)

    def worst() -> float:
        with torch.no_grad():
            a0 = model.actor(x0)
        x = worst_in_ball(lambda z: ((model.actor(z) - a0) ** 2).sum(dim=1), x0, 0.1, 10,
                          torch.as_tensor(mask), -1.0, 1.0)
        with torch.no_grad():
            return float(((model.actor(x) - a0) ** 2).sum(dim=1).mean())

    before = worst()
    model.learning_starts = 0
    model.train(gradient_steps=50, batch_size=32)
    assert worst() < 0.5 * before


def test_robust_train_sa_ddpg_and_a_teacher_distillation_run_from_the_cli(tmp_path: Path) -> None:
    from zodrive.policies.loading import load_network
    from zodrive.cli import main
    from zodrive.envs import load_preset

    out = tmp_path / "sa-ddpg"
    assert main(["robust-train", "models/ddpg-driver", "--method", "sa", "--eps", "0.05", "--steps", "60",
                 "--warmup", "20", "--out", str(out), "--no-progress", "--env-set", "max_episode_steps=30"]) == 0
    train = json.loads((out / "train.json").read_text())
    assert train["kind"] == "sa-ddpg" and train["algo"] == "ddpg" and "hinge" not in train["method"]
    assert load_network(out, load_preset("continuous")).algo == "ddpg"  # the safe loader reads it
    student = tmp_path / "student"
    assert main(["robust-train", "models/dqn-driver", "--method", "distill", "--teacher", "baseline:robust-rules@0.02",
                 "--eps", "0.02", "--steps", "120", "--out", str(student), "--env-set", "max_episode_steps=60"]) == 0
    method = json.loads((student / "train.json").read_text())["method"]
    assert method["teacher"] == "baseline:robust-rules@0.02" and method["eps"] == 0.02
    assert main(["robust-train", "models/dqn-driver", "--method", "sa", "--teacher", "baseline:rules",
                 "--eps", "0.02", "--steps", "10", "--out", str(tmp_path / "x")]) == 2


def test_a_robust_models_card_states_its_method_and_attacked_numbers(tmp_path: Path) -> None:
    from zodrive.experiments.card import write_card

    folder = tmp_path / "dqn-robust"
    (folder / "eval").mkdir(parents=True)
    (folder / "model.zip").write_bytes(b"zip")
    (folder / "run.json").write_text(json.dumps({"command": "zodrive robust-train ...", "seed": 1,
                                                 "versions": {"zodrive": "0"}}))
    method = {"name": "robust-distillation", "teacher": "baseline:rules", "eps": 0.02, "kappa": 0.5,
              "reference": "Rusu et al. 2016; Madry et al. 2018"}
    (folder / "train.json").write_text(json.dumps({"algo": "dqn", "kind": "distill", "method": method, "seed": 1,
                                                   "source_model": "models/dqn-driver/model.zip",
                                                   "total_timesteps": 30000, "wall_time_s": 600, "steps_per_s": 50}))
    (folder / "config.yaml").write_text("preset: {name: discrete}\nmethod: {eps: 0.02}\n")
    summary = {"mean_return": 340.0, "ci95": [330.0, 350.0], "pct_of_max": 75.6, "collision_rate": 0.02,
               "mean_speed": 23.0, "right_lane_share": 0.8, "episodes": 10, "seed": 100000, "command": "zodrive evaluate"}
    (folder / "eval" / "summary.json").write_text(json.dumps(summary))
    cell = tmp_path / "cell"
    cell.mkdir()
    (cell / "summary.json").write_text(json.dumps({**summary, "mean_return": 120.5, "attack": "random-search",
                                                   "eps": 0.05, "attack_config": {"max_change": 0.01},
                                                   "attack_success_rate": 0.4, "queries_per_step": 14.2}))
    text = write_card(folder, attacked=[cell]).read_text()
    assert text.startswith("# dqn-robust: robustly distilled DQN")
    assert "Method: robust-distillation" in text and "teacher baseline:rules" in text and "ε 0.02" in text
    assert "under **random-search** (ε 0.05, max_change 0.01" in text and "120.50" in text
    assert "--attacked " + str(cell) in text and "## Robust training" in text
