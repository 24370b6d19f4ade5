"""Scenario presets, any gymnasium environment, and a policy from the user's own Python file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from highway_env.envs.common.observation import KinematicObservation

from zodrive.cli import main
from zodrive.errors import ZodriveError
from zodrive.envs import load_preset, make_env, preset_names, scenario
from zodrive.envs.fast_kinematics import FastKinematicObservation

FAST_SCENARIOS = ["highway", "highway-fast", "merge", "roundabout", "intersection", "racetrack"]


def test_env_list_shows_every_scenario_in_one_line_each(capsys) -> None:
    assert main(["env", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in FAST_SCENARIOS + ["exit", "discrete", "continuous"]:
        assert name in preset_names()
        line = next(li for li in lines if li.split()[0] == name)
        assert len(line.split()) > 3  # a name and what it is
    assert "--env-id" in lines[-1]


@pytest.mark.integration
@pytest.mark.parametrize("name", FAST_SCENARIOS)
def test_the_fast_observation_is_exact_in_every_scenario(name: str) -> None:
    preset = load_preset(name, ["highway.simulation_frequency=5"])
    env = make_env(preset)
    options = {k: v for k, v in preset["highway"]["observation"].items() if k != "type"}
    compared = 0
    for seed in range(3):
        env.reset(seed=seed)
        env.action_space.seed(seed)
        for _ in range(15):
            core = env.unwrapped
            stock, fast = KinematicObservation(core, **options), FastKinematicObservation(core, **options)
            np.testing.assert_array_equal(fast.observe(), stock.observe())
            compared += 1
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                break
    assert compared >= 10


def test_scenario_facts_come_from_the_environment() -> None:
    intersection = scenario(load_preset("intersection"))
    assert intersection.obs_shape == (15, 7) and intersection.action_names == ("SLOWER", "IDLE", "FASTER")
    racetrack = scenario(load_preset("racetrack"))
    assert racetrack.kind == "continuous" and racetrack.action_names == ("steering",)
    assert scenario(load_preset("exit")).bounds == (float("-inf"), float("inf"))  # not clipped


def _error(capsys, args: list[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_baselines_fit_the_scenarios_that_have_their_actions(tmp_path: Path, capsys) -> None:
    assert "LANE_LEFT, IDLE, LANE_RIGHT" in _error(capsys, ["evaluate", "baseline:faster", "--preset", "highway-fast",
                                                           "--env-set", "highway.action={type: DiscreteMetaAction, "
                                                           "longitudinal: false}"])
    assert main(["evaluate", "baseline:faster", "--preset", "intersection", "--episodes", "1", "--no-progress",
                 "--env-set", "highway.duration=3"]) == 0  # FASTER is index 2 there
    capsys.readouterr()
    assert "acts on steering" in _error(capsys, ["evaluate", "baseline:brake", "--preset", "racetrack", "--episodes", "1"])
    assert "straight road" in _error(capsys, ["evaluate", "baseline:rules", "--preset", "roundabout", "--episodes", "1"])
    assert "plans no route" in _error(capsys, ["evaluate", "baseline:idm-mobil", "--preset", "exit", "--episodes", "1"])


def _policy_file(tmp_path: Path) -> Path:
    path = tmp_path / "my_policy.py"
    path.write_text(
        "import numpy as np\n"
        "import torch\n"
        "def make_policy():\n"
        "    torch.manual_seed(0)\n"
        "    return torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(4, 2))\n"
        "def make_numpy():\n"
        "    return lambda obs: np.tile([0.0, 1.0], (len(obs), 1))\n"
        "def broken():\n"
        "    raise RuntimeError('no weights here')\n")
    return path


def test_a_torch_module_or_a_callable_from_a_python_file_is_a_victim(tmp_path: Path, capsys) -> None:
    path = _policy_file(tmp_path)
    out = tmp_path / "eval"
    assert main(["evaluate", f"{path}:make_policy", "--env-id", "CartPole-v1",
                 "--episodes", "2", "--attack", "random-search", "--eps", "0.5", "--target", "none", "--steps", "5",
                 "--out", str(out), "--no-progress"]) == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["preset"] == "CartPole-v1" and summary["max_linf"] <= 0.5 + 1e-6 and summary["queries_per_step"] > 1
    assert summary["attack_success_rate"] > 0  # a random linear policy flips inside a 0.5 ball
    assert main(["evaluate", f"{path}:make_numpy", "--env-id", "CartPole-v1", "--episodes", "1", "--no-progress"]) == 0
    assert "always" not in capsys.readouterr().err
    assert "no weights here" in _error(capsys, ["evaluate", f"{path}:broken", "--env-id", "CartPole-v1"])
    assert "no function" in _error(capsys, ["evaluate", f"{path}:missing", "--env-id", "CartPole-v1"])
    assert "--preset or --env-id" in _error(capsys, ["evaluate", f"{path}:make_policy"])
    assert "failed on a batch" in _error(capsys, ["evaluate", f"{path}:make_policy", "--preset", "highway-fast"])
    assert "outputs of shape" in _error(capsys, ["evaluate", f"{path}:make_numpy", "--preset", "highway-fast"])


def test_env_id_flags_are_checked(tmp_path: Path, capsys) -> None:
    path = _policy_file(tmp_path)
    assert "did you mean" in _error(capsys, ["evaluate", f"{path}:make_policy", "--env-id", "CartPole-v9"])
    assert "give one" in _error(capsys, ["evaluate", f"{path}:make_policy", "--env-id", "CartPole-v1",
                                         "--preset", "merge"])
    assert "--obs-bounds applies to --env-id" in _error(capsys, ["evaluate", "baseline:slower", "--obs-bounds", "0,1"])
    assert "LOW < HIGH" in _error(capsys, ["evaluate", "baseline:slower", "--obs-bounds", "1,0"])
    assert "target auto" in _error(capsys, ["evaluate", f"{path}:make_policy", "--env-id", "CartPole-v1",
                                            "--attack", "random-search"])
    assert "applies to stable-baselines3 zips" in _error(capsys, ["evaluate", "baseline:slower", "--trust-model"])


def test_a_box_per_dimension_and_a_feature_axis_come_from_the_environment() -> None:
    """Pendulum's box is per dimension (cos, sin in [-1, 1], the speed in [-8, 8]): every queried point keeps
    cos and sin in [-1, 1]; OccupancyGrid names its features along the first axis: presence stays frozen
    (issue 46). A range wider than the declared box is refused, not used."""
    import gymnasium as gym
    import numpy as np

    import zodrive
    from zodrive.envs import gym_preset, scenario_of_env

    pendulum = scenario_of_env(gym.make("Pendulum-v1"))
    assert pendulum.bounds == ((-1.0, -1.0, -8.0), (1.0, 1.0, 8.0))
    seen: list[np.ndarray] = []

    def still(obs: np.ndarray) -> np.ndarray:
        seen.append(np.asarray(obs).reshape(-1, 3))
        return np.zeros((len(seen[-1]), 1), dtype=np.float32)

    env = zodrive.AttackWrapper(gym.make("Pendulum-v1"), still, attack="random-search", eps=0.5, target="none",
                                steps=5)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(1, dtype=np.float32))
    rows = np.concatenate(seen)
    assert np.abs(rows[:, :2]).max() <= 1.0 and np.abs(rows[:, 2]).max() <= 8.0
    assert np.ptp(rows[:, 2]) > 0.5  # the speed was attacked (eps 0.5 is inside its wider range)

    grid = gym.make("racetrack-v0")  # OccupancyGrid: (presence, on_road) x 12 x 12
    assert scenario_of_env(grid).feature_axis == 0
    grids: list[np.ndarray] = []

    def straight(obs: np.ndarray) -> np.ndarray:
        grids.append(np.asarray(obs).reshape(-1, 2, 12, 12))
        return np.zeros((len(grids[-1]), 1), dtype=np.float32)

    env = zodrive.AttackWrapper(grid, straight, attack="random-search", eps=0.2, target="none", steps=3)
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    queried = np.concatenate(grids)
    assert (queried[:, 0] == queried[:1, 0]).all() and not (queried[:, 1] == queried[:1, 1]).all()

    from zodrive.envs import scenario

    with pytest.raises(ZodriveError, match="change nothing"):  # Pendulum declares every range: nothing to bound
        scenario(gym_preset("Pendulum-v1", obs_bounds=(-8.0, 8.0)))
    # CartPole declares x and the angle, not the speeds: obs_bounds bound the speeds, the declared ranges stay
    low, high = scenario(gym_preset("CartPole-v1", obs_bounds=(-5.0, 5.0))).bounds
    assert low == pytest.approx((-4.8, -5.0, -0.41887903, -5.0)) and high == pytest.approx((4.8, 5.0, 0.41887903, 5.0))


def test_a_policy_file_that_exits_or_returns_nan_is_one_line(tmp_path: Path, capsys) -> None:
    """sys.exit(0) while loading ended zodrive with exit 0 and no output; NaN scores drove as action 0."""
    (tmp_path / "exits.py").write_text("import sys\nsys.exit(0)\n")
    (tmp_path / "nan.py").write_text("import numpy as np\n\ndef make():\n"
                                     "    return lambda obs: np.full((len(obs), 5), np.nan, np.float32)\n")
    args = ["--preset", "highway-fast", "--episodes", "1", "--env-set", "max_episode_steps=3", "--no-progress"]
    for name, message in (("exits.py:make", "called sys.exit(0) while being loaded"),
                          ("nan.py:make", "returned NaN or infinite outputs")):
        assert main(["evaluate", str(tmp_path / name), *args]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
