"""Behaviour cloning with DAgger (`defense.distill`): the standardized input layer folds away
exactly, DAgger aggregates the states the student drives into labelled by the teacher, and
the held-out agreement it reports is measured on states no round trained on."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from zodrive.attacks.victim import Victim
from zodrive.training.distill import agreement, class_weights, dagger_rounds, fit, folded, standardized


class Walk(gym.Env):
    """A 1-d walk seen as a (5, 5) observation: x[0, 2] is the position, actions move it by
    -0.2, -0.1, 0, 0.1, 0.2; 20 steps per episode; the start depends on the seed."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (5, 5), np.float32)
    action_space = gym.spaces.Discrete(5)

    def _obs(self) -> np.ndarray:
        obs = np.zeros((5, 5), np.float32)
        obs[:, 0], obs[0, 2] = 1.0, self.pos
        return obs

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.pos, self.t = float(self.np_random.uniform(-0.05, 0.05)), 0
        return self._obs(), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.pos = float(np.clip(self.pos + 0.1 * (int(action) - 2), -1, 1))
        self.t += 1
        return self._obs(), 0.0, False, self.t >= 20, {}


def _teacher() -> Victim:
    """Steers back to 0: never leaves [-0.15, 0.15] from a start in [-0.05, 0.05]."""
    eye = np.eye(5, dtype=np.float32)
    return Victim(query=lambda x: eye[np.where(np.asarray(x)[:, 0, 2] > 0.05, 1, np.where(np.asarray(x)[:, 0, 2] < -0.05, 3, 2))],
                  kind="discrete", obs_shape=(5, 5))


def _net(seed: int = 0) -> torch.nn.Sequential:
    torch.manual_seed(seed)
    return torch.nn.Sequential(torch.nn.Linear(25, 16), torch.nn.ReLU(), torch.nn.Linear(16, 5))


def test_the_standardized_layer_folds_away_exactly() -> None:
    x = torch.rand(64, 25) * torch.linspace(0.01, 1, 25)
    x[:, 0] = 1.0  # a constant feature keeps std 1
    net = _net()
    wide = standardized(net, x)
    assert torch.allclose(wide(x), net(x), atol=1e-5)  # the same function before training
    fit(wide, x, torch.randint(0, 5, (64,)), epochs=3, lr=1e-2, batch=16, weight=None,
        gen=torch.Generator().manual_seed(0))
    plain = folded(wide)
    assert all(isinstance(m, (torch.nn.Linear, torch.nn.ReLU)) for m in plain)
    assert not torch.allclose(plain(x), net(x), atol=1e-3)  # it trained ...
    assert torch.allclose(plain(x), wide(x), atol=1e-4)     # ... and folding changes nothing


def test_dagger_aggregates_the_students_states_labelled_by_the_teacher() -> None:
    """With a student that does not learn (refit is a no-op), round 1's states are exactly the
    ones the student drives into on its seeds, and every label is the teacher's."""
    from zodrive.policies.victims import network_victim
    from zodrive.evaluation.rollout import clean_states

    teacher, student, env = _teacher(), _net(3), Walk()
    fits: list[int] = []
    x, y, records = dagger_rounds(env, teacher, student, (5, 5), rounds=2, steps=60, seed=100,
                                  refit=lambda net, xa, ya: fits.append(len(xa)) or [],
                                  evaluate=lambda net, xa, ya: {})
    assert fits == [60, 120, 180] and len(x) == 180
    assert [r["driver"] for r in records] == ["teacher", "student", "student"]
    assert torch.equal(y, torch.as_tensor(teacher.query(x.numpy().reshape(-1, 5, 5)).argmax(axis=1)))
    assert float(x[:60, 2].abs().max()) <= 0.15 + 1e-6  # the teacher's own states stay near 0
    own = clean_states(Walk(), network_victim(student, "discrete", (5, 5)), 160, 60)
    assert np.array_equal(x[60:120].numpy(), own.reshape(60, -1))
    assert float(x[60:, 2].abs().max()) > 0.15  # states the teacher never drives into


def test_class_weights_average_one_and_lift_rare_classes() -> None:
    y = torch.tensor([1] * 90 + [3] * 9 + [0])
    w = class_weights(y, 5, 0.5)
    assert float(w[y].mean()) == pytest.approx(1.0) and w[0] > w[3] > w[1]
    assert torch.equal(class_weights(y, 5, 0.0), torch.ones(5))


def test_dagger_distillation_writes_a_zip_that_reproduces_its_heldout_agreement(tmp_path: Path) -> None:
    """On the paper's preset (short episodes): the saved zip, read by the safe loader, agrees
    with the rules on the held-out teacher states exactly as train.json says, and those
    states come from seeds no round drove on."""
    from zodrive.policies.loading import load_network
    from zodrive.policies.resolve import load_victim
    from zodrive.training.distill import distill
    from zodrive.envs import load_preset, make_env
    from zodrive.evaluation.rollout import clean_states

    preset = load_preset("discrete", ["max_episode_steps=40"])
    out = distill("models/dqn", preset, 0.05, 120, tmp_path / "d", kappa=0.0, epochs=3, seed=7,
                  teacher="baseline:rules", dagger=1)
    train = json.loads((tmp_path / "d" / "train.json").read_text())
    assert train["method"]["name"] == "dagger-distillation" and len(train["rounds"]) == 2
    assert train["method"]["jitter"] == 0.5  # the rules read the observation: noisy labelled copies
    held = train["heldout_seeds"]
    assert all(r["seeds"][1] < held[0] for r in train["rounds"]) and train["rounds"][1]["aggregate"] == 240
    rules = load_victim("baseline:rules", preset)
    states = clean_states(make_env(preset), rules, held[0], 60)
    x = torch.as_tensor(states.reshape(60, -1))
    y = torch.as_tensor(rules.query(states).argmax(axis=1))
    student = load_network(out, preset).net
    names = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")
    assert agreement(student, x, y, names)["all"] == train["rounds"][-1]["heldout_teacher_states"]["all"]


def test_dagger_is_an_error_outside_distill(tmp_path: Path) -> None:
    from zodrive.training.robust import robust_train
    from zodrive.envs import load_preset
    from zodrive.errors import ZodriveError

    with pytest.raises(ZodriveError, match="--dagger applies to --method distill"):
        robust_train("models/dqn", load_preset("discrete"), "sa", 0.05, 100, tmp_path / "x", dagger=2)
    assert not (tmp_path / "x").exists()


def test_a_teacher_that_reads_the_simulator_gets_no_noisy_copies_and_the_record_says_so(tmp_path: Path) -> None:
    """The noisy labelled copies need a teacher that can label any observation; IDM + MOBIL reads
    the simulator, so none are made, and train.json records jitter 0 (it recorded 0.5)."""
    from zodrive.training.distill import distill
    from zodrive.envs import load_preset

    preset = load_preset("discrete", ["max_episode_steps=20"])
    distill("models/dqn", preset, None, 40, tmp_path / "d", kappa=0.0, epochs=1, seed=7,
            teacher="baseline:idm-mobil", dagger=1)
    method = json.loads((tmp_path / "d" / "train.json").read_text())["method"]
    assert method["teacher"] == "baseline:idm-mobil" and method["jitter"] == 0.0


def test_a_written_student_zip_is_the_same_bytes_whenever_it_is_written(tmp_path: Path) -> None:
    """A zip's member dates are fixed, so a run repeated with the same seed has the same SHA-256
    (bench rows and cards name a model by it)."""
    import zipfile

    from zodrive.envs import load_preset
    from zodrive.policies.loading import load_network
    from zodrive.runinfo import sha256
    from zodrive.training.distill import ZIP_DATE, _write_zip

    net = load_network("models/dqn", load_preset("discrete")).net
    _write_zip(Path("models/dqn/model.zip"), net, tmp_path / "a.zip")
    with zipfile.ZipFile(tmp_path / "a.zip") as archive:
        assert {info.date_time for info in archive.infolist()} == {ZIP_DATE}
    _write_zip(Path("models/dqn/model.zip"), net, tmp_path / "b.zip")
    assert sha256(tmp_path / "a.zip") == sha256(tmp_path / "b.zip")


def test_stable_baselines3_reads_a_written_student_and_acts_with_its_weights(tmp_path: Path) -> None:
    """`DQN.load` needs the optimizer's member (its keys must match exactly): a written student keeps it,
    without the teacher's moments, and SB3's Q-network is the student's (students written before 2026-12-07
    dropped the member, and SB3 refused them: `KeyError: 'policy.optimizer'`)."""
    import copy

    import numpy as np
    import torch
    from stable_baselines3 import DQN

    from zodrive.envs import load_preset
    from zodrive.policies.loading import load_network
    from zodrive.training.distill import _write_zip

    student = copy.deepcopy(load_network("models/dqn", load_preset("discrete")).net)
    for layer in student:
        if isinstance(layer, torch.nn.Linear):
            torch.nn.init.normal_(layer.weight, std=0.1)  # not the teacher's weights
    _write_zip(Path("models/dqn/model.zip"), student, tmp_path / "s.zip")
    model = DQN.load(tmp_path / "s.zip", device="cpu")
    assert model.policy.optimizer.state_dict()["state"] == {}
    obs = np.random.default_rng(0).uniform(-1, 1, (16, 25)).astype(np.float32)
    with torch.no_grad():
        theirs = model.q_net(torch.as_tensor(obs)).numpy()
        ours = student(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(theirs, ours, rtol=1e-5, atol=1e-6)
