"""Behaviour cloning with DAgger into a DDPG/TD3 actor (issue 22, the continuous side): a
stateful, simulator-reading teacher is asked once per step while it drives or not, the mixture
rollouts take its action with probability beta ** round, the per-dimension scaled regression
weighs the small steering like the acceleration, and the written zip is a DDPG zip whose actor
(and only it) is the student's."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from zodrive.attacks.victim import Victim
from zodrive.training.distill import (action_error, dagger_rounds, fit, folded, labelled_rollout, scaled_l1,
                                     scaled_mse, standardized)

ROOT = Path(__file__).resolve().parents[1]
DDPG = str(ROOT / "models" / "ddpg-driver")


class Lane(gym.Env):
    """A car seen as a (5, 5) observation: x[0, 2] its lateral offset, x[0, 3] its speed; the
    action [acceleration, steering] moves them by 0.1 a and 0.1 s; 20 steps per episode."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (5, 5), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def _obs(self) -> np.ndarray:
        obs = np.zeros((5, 5), np.float32)
        obs[:, 0], obs[0, 2], obs[0, 3] = 1.0, self.y, self.v
        return obs

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.y, self.v, self.t = float(self.np_random.uniform(-0.1, 0.1)), 0.0, 0
        return self._obs(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.v = float(np.clip(self.v + 0.1 * action[0], -1, 1))
        self.y = float(np.clip(self.y + 0.1 * action[1], -1, 1))
        self.t += 1
        return self._obs(), 0.0, False, self.t >= 20, {}


class Counting:
    """A stateful teacher like IDM + MOBIL: it reads its environment, not the observation, and
    keeps a counter of its calls (its memory) that it reports as its acceleration."""

    def __init__(self, env: Lane) -> None:
        self.env, self.calls = env, 0

    def victim(self) -> Victim:
        def query(obs: np.ndarray) -> np.ndarray:
            self.calls += 1
            return np.repeat(np.array([[self.calls / 1000, -self.env.y]], np.float32), len(obs), axis=0)

        return Victim(query=query, kind="continuous", obs_shape=(5, 5), reads="simulator")


def _still() -> Victim:
    return Victim(query=lambda x: np.zeros((len(x), 2), np.float32), kind="continuous", obs_shape=(5, 5))


def test_the_teacher_is_asked_once_per_step_whoever_drives() -> None:
    env = Lane()
    teacher = Counting(env)
    for beta in (1.0, 0.5, 0.0):
        before = teacher.calls
        states, labels = labelled_rollout(env, teacher.victim(), _still(), beta, 7, 50, np.random.default_rng(0))
        assert teacher.calls - before == 50 and len(states) == 50
        assert np.allclose(labels[:, 0], (before + 1 + np.arange(50)) / 1000)  # each label is the call at that state
        assert np.allclose(labels[:, 1], -states[:, 0, 2])  # read from the simulator as the state was seen


def test_beta_decides_who_drives() -> None:
    """beta 1: the teacher steers the car back to the centre; beta 0: the still student leaves
    it where it started; beta 0.5: in between, and deterministic given the generator."""
    env = Lane()
    teacher = Counting(env).victim()

    def spread(beta: float, seed: int = 0) -> np.ndarray:
        states, _ = labelled_rollout(env, teacher, _still(), beta, 11, 200, np.random.default_rng(seed))
        return states[:, 0, 2]

    driven, still, mixed = np.abs(spread(1.0)).mean(), np.abs(spread(0.0)).mean(), np.abs(spread(0.5)).mean()
    assert driven < mixed < still
    assert np.array_equal(spread(0.5), spread(0.5)) and not np.array_equal(spread(0.5), spread(0.5, seed=1))


def test_dagger_rounds_mix_with_a_decaying_beta() -> None:
    env = Lane()
    teacher = Counting(env)
    torch.manual_seed(0)
    student = torch.nn.Sequential(torch.nn.Linear(25, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2), torch.nn.Tanh())
    x, y, records = dagger_rounds(env, teacher.victim(), student, (5, 5), rounds=3, steps=40, seed=5,
                                  refit=lambda net, xa, ya: [], evaluate=lambda net, xa, ya: {},
                                  kind="continuous", beta=0.5)
    assert [r["beta"] for r in records] == [1.0, 0.5, 0.25, 0.125]
    assert records[0]["driver"] == "teacher" and records[1]["driver"].startswith("mixture")
    assert y.dtype == torch.float32 and y.shape == (160, 2) and teacher.calls == 160
    assert torch.allclose(y[:, 1], -x[:, 2])


def test_the_scaled_loss_trades_the_large_dimension_for_the_small_one() -> None:
    """A target whose second dimension is 20x smaller: the plain MSE fits the large one almost
    exactly and leaves most of the small one's variance; `scaled_mse` fits the small one
    markedly better, at the large one's expense (the errors relative to each spread move closer)."""
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(2000, 25, generator=gen)
    y = torch.stack([torch.tanh(x[:, 0] - x[:, 1]), 0.05 * torch.tanh(x[:, 2] * x[:, 3])], dim=1)

    def relative_error(criterion: Any) -> np.ndarray:
        torch.manual_seed(1)
        net = torch.nn.Sequential(torch.nn.Linear(25, 64), torch.nn.ReLU(), torch.nn.Linear(64, 2), torch.nn.Tanh())
        fit(net, x, y, epochs=40, lr=3e-3, batch=128, weight=None, gen=torch.Generator().manual_seed(2),
            criterion=criterion)
        per = action_error(net, x, y, ("acceleration", "steering"))["per_dim"]
        return np.array([per[n]["rmse"] / per[n]["label_std"] for n in ("acceleration", "steering")])

    plain = relative_error(torch.nn.functional.mse_loss)
    scaled = relative_error(scaled_mse(y.std(dim=0)))
    assert scaled[1] < 0.75 * plain[1] and scaled[0] > plain[0]
    assert scaled[1] / scaled[0] < 0.5 * plain[1] / plain[0]


def test_the_absolute_loss_keeps_the_lane_where_a_decision_is_a_minority() -> None:
    """States that look alike, on 20 % of which the teacher starts a lane change (steering 1)
    and on the rest keeps its lane (0): the scaled MSE learns the mean (0.2, a drift), the
    scaled absolute error the median (0: keep the lane); where the change is the majority
    (80 %) the absolute error changes lanes."""
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(2000, 25, generator=gen) * 0.01
    x[1000:, 0] += 1.0  # two groups of states
    change = torch.rand(2000, generator=gen) < torch.where(x[:, 0] > 0.5, 0.8, 0.2)
    y = torch.stack([torch.zeros(2000), change.float()], dim=1)

    def fitted(criterion: Any) -> torch.Tensor:
        torch.manual_seed(1)
        net = torch.nn.Sequential(torch.nn.Linear(25, 64), torch.nn.ReLU(), torch.nn.Linear(64, 2), torch.nn.Tanh())
        fit(net, x, y, epochs=60, lr=3e-3, batch=128, weight=None, gen=torch.Generator().manual_seed(2),
            criterion=criterion)
        with torch.no_grad():
            return net(torch.stack([x[:1000].mean(dim=0), x[1000:].mean(dim=0)]))[:, 1]

    scale = torch.tensor([1.0, 1.0])
    mean, median = fitted(scaled_mse(scale)), fitted(scaled_l1(scale))
    assert abs(float(mean[0]) - 0.2) < 0.07 and abs(float(median[0])) < 0.05
    assert float(median[1]) > 0.9


def test_the_student_zip_is_a_ddpg_zip_with_only_its_actor_replaced(tmp_path: Path) -> None:
    from zodrive.policies.loading import load_model, load_network
    from zodrive.policies.victims import sb3_victim
    from zodrive.training.distill import _write_zip

    source = load_network(DDPG)
    x = torch.rand(32, 25)
    student = standardized(source.net, x)
    with torch.no_grad():
        for layer in student:
            if isinstance(layer, torch.nn.Linear):
                layer.weight.mul_(0.5)
    _write_zip(Path(DDPG) / "model.zip", folded(student), tmp_path / "model.zip", "ddpg")
    written = load_network(tmp_path / "model.zip").net
    assert torch.allclose(written(x), student(x), atol=1e-5) and not torch.allclose(written(x), source.net(x))
    before, after = (torch.load(io.BytesIO(zipfile.ZipFile(f).read("policy.pth")), weights_only=True)
                     for f in (Path(DDPG) / "model.zip", tmp_path / "model.zip"))
    assert all(torch.equal(before[k], after[k]) for k in before if k.startswith("critic"))
    assert torch.equal(after["actor.mu.0.weight"], after["actor_target.mu.0.weight"])
    trusted = sb3_victim(load_model(tmp_path / "model.zip", trust=True))  # SB3's own loader reads it too
    assert np.allclose(trusted.query(x.numpy().reshape(-1, 5, 5)), written(x).detach().numpy(), atol=1e-5)


@pytest.mark.parametrize("extra,message", [
    (["--kappa", "0"], "clones a --teacher with --dagger ROUNDS"),
    (["--kappa", "0", "--dagger", "1", "--teacher", "baseline:robust-rules@0.05"],
     "baseline:robust-rules@0.05 drives discrete presets, not a continuous one"),
    (["--kappa", "0", "--dagger", "1", "--teacher", "baseline:brake"], "must be an observation-reading baseline"),
    (["--kappa", "0.5", "--eps", "0.05", "--dagger", "1", "--teacher", "baseline:idm-mobil"], "use --kappa 0"),
])
def test_bad_combinations_are_one_line_errors(tmp_path: Path, capsys, extra: list[str], message: str) -> None:
    from zodrive.cli import main

    code = main(["robust-train", DDPG, "--method", "distill", "--steps", "4", "--preset", "continuous",
                 "--out", str(tmp_path / "r"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "r" / "model.zip").exists()


def test_cloning_idm_mobil_writes_a_zip_that_reproduces_its_heldout_action_error(tmp_path: Path) -> None:
    """On the continuous preset (short episodes): the saved zip, read by the safe loader, is as
    far from IDM + MOBIL on the held-out teacher states as train.json says, and those states
    come from seeds no round drove on."""
    from zodrive.policies.loading import load_network
    from zodrive.system import make_policy_env
    from zodrive.training.distill import distill
    from zodrive.envs import load_preset

    preset = load_preset("continuous", ["max_episode_steps=40"])
    out = distill(DDPG, preset, None, 120, tmp_path / "d", kappa=0.0, epochs=3, seed=7,
                  teacher="baseline:idm-mobil", dagger=1)
    train = json.loads((tmp_path / "d" / "train.json").read_text())
    assert train["algo"] == "ddpg" and [r["beta"] for r in train["rounds"]] == [1.0, 0.5]
    assert train["method"]["jitter"] == 0.0 and "ego_jitter" not in train["method"]  # it reads the simulator
    held = train["heldout_seeds"]
    assert all(r["seeds"][1] < held[0] for r in train["rounds"]) and train["rounds"][1]["aggregate"] == 240
    teacher, env = make_policy_env("baseline:idm-mobil", preset)
    states, labels = labelled_rollout(env, teacher, teacher, 1.0, held[0], 60, np.random.default_rng(0))
    student = load_network(out, preset).net
    error = action_error(student, torch.as_tensor(states.reshape(60, -1)), torch.as_tensor(labels),
                         ("acceleration", "steering"))
    recorded = train["rounds"][-1]["heldout_teacher_states"]
    assert error["count"] == recorded["count"] == 60
    for name in ("acceleration", "steering"):
        assert error["per_dim"][name] == pytest.approx(recorded["per_dim"][name], abs=2e-4)


def test_the_labelling_teacher_replans_from_a_lane_it_was_driven_into() -> None:
    """Put the ego, centred, in the lane beside its own (as a student may drive it): IDM + MOBIL
    as evaluated steers hard back to the lane it never left in its own mind; the labelling
    teacher (`replan`) keeps the lane it is in. In its own lane both agree exactly."""
    from zodrive.drivers.baselines import IdmMobilDriver
    from zodrive.envs import load_preset, make_env

    def steering(replan: bool, shift: int) -> float:
        env = make_env(load_preset("continuous"))
        # seed 4: MOBIL refuses both lane changes outright (unsafe for the new follower). At seed 3, used before,
        # the better one fell short of MOBIL's threshold by only 0.05 m/s^2; the test failed twice in about 40
        # full-suite runs there, for a cause not found (the steering values below are +-1 and 0, far from theirs)
        env.reset(seed=4)
        driver = IdmMobilDriver(env, "continuous", replan=replan)
        driver()  # the first call of an episode: the target is the lane it starts in
        ego = env.unwrapped.vehicle
        # the premise (if MOBIL chose the lane the ego is then put into, steering to it is 0): the first call
        # kept the lane it starts in
        assert driver._target_lane == ego.lane_index, (driver._target_lane, ego.lane_index, ego.position)
        network = ego.road.network
        _from, _to, index = ego.lane_index
        lane = (_from, _to, index + shift if index + shift < len(network.graph[_from][_to]) else index - shift)
        longitudinal, _ = network.get_lane(lane).local_coordinates(ego.position)
        ego.position = network.get_lane(lane).position(longitudinal, 0.0)
        ego.heading = network.get_lane(lane).heading_at(longitudinal)
        ego.lane_index, ego.lane = lane, network.get_lane(lane)
        out = float(driver()[1])
        env.close()
        return out

    back, kept = steering(False, 1), steering(True, 1)
    assert abs(back) > 0.5 and abs(kept) < 0.05, (back, kept)  # the values, should this fail again
    assert steering(True, 0) == steering(False, 0)


def test_cloning_the_continuous_rules_jitters_their_states_and_fits_the_median(tmp_path: Path) -> None:
    """An observation-reading continuous teacher (`baseline:rules`) gets the noisy labelled copies
    and the absolute loss; the record says so, and the zip drives."""
    from zodrive.policies.resolve import load_victim
    from zodrive.training.distill import distill
    from zodrive.envs import load_preset

    preset = load_preset("continuous", ["max_episode_steps=40"])
    out = distill(DDPG, preset, None, 80, tmp_path / "d", kappa=0.0, epochs=2, seed=7,
                  teacher="baseline:rules", dagger=1)
    method = json.loads((tmp_path / "d" / "train.json").read_text())["method"]
    assert method["teacher"] == "baseline:rules" and method["jitter"] == 0.5 and method["ego_jitter"] == 0.2
    assert method["loss"].startswith("absolute error")
    student = load_victim(str(out), preset)
    assert student.kind == "continuous" and student.query(np.zeros((3, 5, 5), np.float32)).shape == (3, 2)
