"""Models trained inside VecNormalize, rl-zoo3 and Hugging Face folders: zodrive's episodes equal
the user's own loop with the statistics applied, the scenario comes from the folder, and a
normalization file that would run code is refused without running it."""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import zodrive
from zodrive.errors import ZodriveError
from zodrive.policies.normalize import read_normalization
from zodrive.policies.resolve import resolve_preset

ENV = "CartPole-v1"


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, PPO, VecNormalize]:
    """A PPO trained inside VecNormalize (statistics far from 0/1: the scale matters), saved as SB3 does."""
    folder = tmp_path_factory.mktemp("vecnorm")
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV)]), norm_reward=True, clip_obs=5.0)
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu").learn(512)
    venv.obs_rms.mean = venv.obs_rms.mean + np.array([0.3, 0.5, -0.02, 0.4])  # make a forgotten normalization show
    venv.obs_rms.var = venv.obs_rms.var * np.array([4.0, 0.2, 9.0, 0.5])
    model.save(folder / "model")
    venv.save(str(folder / "vecnormalize.pkl"))
    return folder, model, venv


def own_loop(model: PPO, venv: VecNormalize, seeds: range) -> list[float]:
    env, returns = gym.make(ENV), []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    return returns


def test_a_vecnormalize_model_gives_the_users_numbers(trained) -> None:
    folder, model, venv = trained
    result = zodrive.evaluate(str(folder), env_id=ENV, episodes=4, seed=3)
    expected = own_loop(model, venv, range(3, 7))
    assert [r["return"] for r in result.episodes] == expected
    raw = zodrive.evaluate(model, env_id=ENV, episodes=4, seed=3)  # the same network without the statistics
    assert [r["return"] for r in raw.episodes] != expected  # so the test can fail


def test_the_run_key_covers_the_statistics(trained, tmp_path: Path) -> None:
    folder, _, _ = trained
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    before = zodrive.resolve(str(copy)).key()
    assert "vecnormalize:sha256:" in before
    (copy / "vecnormalize.pkl").unlink()
    assert zodrive.resolve(str(copy)).key() != before


def test_rl_zoo3_and_hugging_face_folders(trained, tmp_path: Path) -> None:
    folder, model, venv = trained
    zoo = tmp_path / "zoo" / "CartPole-v1_1"
    (zoo / ENV).mkdir(parents=True)
    shutil.copy(folder / "model.zip", zoo / f"{ENV}.zip")
    shutil.copy(folder / "vecnormalize.pkl", zoo / ENV / "vecnormalize.pkl")
    (zoo / ENV / "args.yml").write_text("!!python/object/apply:collections.OrderedDict\n- - - algo\n    - ppo\n"
                                         f"  - - env\n    - {ENV}\n")
    (zoo / ENV / "env_kwargs.yml").write_text("{}\n")
    hub = tmp_path / "hub"
    hub.mkdir()
    shutil.copy(folder / "model.zip", hub / f"ppo-{ENV}.zip")
    shutil.copy(folder / "vecnormalize.pkl", hub / "vec_normalize.pkl")
    expected = own_loop(model, venv, range(3, 5))
    for where in (zoo, hub):
        assert resolve_preset(str(where), None)["env_id"] == ENV  # the scenario comes from the folder
        result = zodrive.evaluate(str(where), resolve_preset(str(where), None), episodes=2, seed=3)
        assert [r["return"] for r in result.episodes] == expected
    shutil.copy(folder / "model.zip", hub / "best_model.zip")
    with pytest.raises(ZodriveError, match="holds 2 models .*best_model.zip, ppo-CartPole-v1.zip"):
        zodrive.resolve(str(hub))
    # another model's statistics in a subfolder that is not this zip's rl-zoo3 folder are not this model's
    plain = tmp_path / "plain"
    (plain / "other").mkdir(parents=True)
    shutil.copy(folder / "model.zip", plain / "ppo.zip")
    shutil.copy(folder / "vecnormalize.pkl", plain / "other" / "vecnormalize.pkl")
    assert "vecnormalize" not in zodrive.resolve(str(plain / "ppo.zip")).key()


class _Payload:
    def __reduce__(self):
        return (os.mkdir, (str(Path(os.environ["ZODRIVE_MARKER"])),))


def test_a_crafted_normalization_file_runs_nothing(tmp_path: Path, monkeypatch) -> None:
    marker = tmp_path / "ran"
    monkeypatch.setenv("ZODRIVE_MARKER", str(marker))
    bad = tmp_path / "vecnormalize.pkl"
    bad.write_bytes(pickle.dumps({"obs_rms": _Payload()}))
    with pytest.raises(ZodriveError, match="without running code: posix.mkdir|without running code: os.mkdir"):
        read_normalization(bad)
    assert not marker.exists()


def test_a_model_trained_on_another_observation_box_is_refused(tmp_path: Path) -> None:
    import json
    import zipfile

    model = PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=32, device="cpu")
    model.save(tmp_path / "pendulum")
    assert zodrive.evaluate(str(tmp_path / "pendulum.zip"), env_id="Pendulum-v1", episodes=1).summary["episodes"] == 1
    other = tmp_path / "other.zip"  # the same network, recorded as trained on a box of [-1, 1] everywhere
    with zipfile.ZipFile(tmp_path / "pendulum.zip") as src, zipfile.ZipFile(other, "w") as dst:
        for item in src.infolist():
            raw = src.read(item.filename)
            if item.filename == "data":
                data = json.loads(raw)
                data["observation_space"]["low"], data["observation_space"]["high"] = "[-1. -1. -1.]", "[1. 1. 1.]"
                raw = json.dumps(data).encode()
            dst.writestr(item, raw)
    with pytest.raises(ZodriveError, match="box low is \\[-1.0, -1.0, -1.0\\]; preset 'Pendulum-v1' declares"):
        zodrive.evaluate(str(other), env_id="Pendulum-v1", episodes=1)


def test_an_image_observation_with_tuple_settings_builds() -> None:
    from zodrive.envs import gym_preset, scenario

    preset = gym_preset("highway-fast-v0", ["highway.observation.type=GrayscaleObservation",
                                            "highway.observation.observation_shape=[36,18]",
                                            "highway.observation.stack_size=2",
                                            "highway.observation.weights=[0.2989,0.587,0.114]"])
    where = scenario(preset)
    assert where.obs_shape == (2, 36, 18) and where.bounds == (0.0, 255.0)  # the image's declared box


def test_the_scenario_comes_from_the_folder_or_is_refused(caplog, tmp_path: Path) -> None:
    import logging

    root = Path(__file__).resolve().parents[1] / "models"
    with caplog.at_level(logging.INFO, logger="zodrive"):
        assert resolve_preset(str(root / "dqn-driver"), None)["name"] == "discrete"  # its config.yaml
        assert resolve_preset(str(root / "ppo-highway-fast"), None)["name"] == "highway-fast"  # its train.json
    shutil.copy(root / "dqn" / "model.zip", tmp_path / "model.zip")
    with pytest.raises(ZodriveError, match="does not say where it was trained.*--preset or --env-id"):
        resolve_preset(str(tmp_path / "model.zip"), None)  # a bare zip says nothing: no default is guessed
    assert resolve_preset("baseline:slower", None)["name"] == "discrete"  # zodrive's own: its kind's preset


def test_summary_json_says_where_an_unnamed_scenario_came_from(tmp_path: Path, capsys) -> None:
    from zodrive.cli import main

    root = Path(__file__).resolve().parents[1] / "models"
    shutil.copy(root / "dqn" / "model.zip", tmp_path / "model.zip")
    args = ["--episodes", "1", "--env-set", "max_episode_steps=2", "--no-progress"]
    assert main(["evaluate", str(tmp_path / "model.zip"), *args, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not say where it was trained" in err[0]  # one line, no warning before it
    assert not (tmp_path / "a").exists()
    shutil.copy(root / "dqn" / "config.yaml", tmp_path / "config.yaml")  # now its run folder says where
    assert main(["evaluate", str(tmp_path / "model.zip"), *args, "--out", str(tmp_path / "c")]) == 0
    assert "config.yaml" in json.loads((tmp_path / "c" / "summary.json").read_text())["scenario_source"]
    assert main(["evaluate", str(tmp_path / "model.zip"), *args, "--preset", "discrete", "--out", str(tmp_path / "b")]) == 0
    assert "scenario_source" not in json.loads((tmp_path / "b" / "summary.json").read_text())  # named by the user


HF_KWARGS = {"config": {"lanes_count": 4, "vehicles_count": 30, "duration": 20, "vehicles_density": 1.5}}


@pytest.fixture(scope="module")
def zoo_run(tmp_path_factory) -> Path:
    """An rl-zoo3 *run* folder (`logs/ppo/highway-fast-v0_1/`): training writes the user's --env-kwargs into
    `highway-fast-v0/args.yml`; `env_kwargs.yml` appears only when a model is pushed. The PPO is untrained:
    only where it drives is checked here."""
    import yaml

    run = tmp_path_factory.mktemp("logs") / "ppo" / "highway-fast-v0_1"
    (run / "highway-fast-v0").mkdir(parents=True)
    model = PPO("MlpPolicy", gym.make("highway-fast-v0", config=HF_KWARGS["config"]), n_steps=64, seed=0, device="cpu")
    model.save(run / "highway-fast-v0")
    (run / "highway-fast-v0" / "args.yml").write_text(
        "!!python/object/apply:collections.OrderedDict\n- - - algo\n    - ppo\n  - - env\n    - highway-fast-v0\n"
        "  - - env_kwargs\n    - " + yaml.safe_dump(HF_KWARGS, default_flow_style=True))
    return run


def test_an_rl_zoo3_run_folder_drives_its_args_yml_env_kwargs(zoo_run: Path) -> None:
    preset = resolve_preset(str(zoo_run), None)
    assert preset["env_id"] == "zodrive/highway-fast-v0"
    assert {k: preset["highway"][k] for k in HF_KWARGS["config"]} == HF_KWARGS["config"]
    (zoo_run / "highway-fast-v0" / "env_kwargs.yml").write_text("config: {lanes_count: 5}\n")
    try:  # two files that disagree: zodrive cannot tell which the model was trained with
        with pytest.raises(ZodriveError, match="give different env_kwargs"):
            resolve_preset(str(zoo_run), None)
    finally:
        (zoo_run / "highway-fast-v0" / "env_kwargs.yml").unlink()


def test_a_named_preset_that_drops_the_models_config_is_refused_unless_shifted(zoo_run: Path, tmp_path: Path,
                                                                                capsys) -> None:
    from zodrive.cli import main
    from zodrive.policies.resolve import resolve_scenario

    with pytest.raises(ZodriveError, match="highway-fast differs from where .*args.yml says .* was trained "
                                           r"\(duration 30, not 20; lanes_count 3, not 4; vehicles_count 20, not 30; "
                                           r"vehicles_density 1, not 1.5\)"):
        resolve_preset(str(zoo_run), "highway-fast")
    config, source = resolve_scenario(str(zoo_run), "highway-fast", shifted=True)
    assert config["highway"].get("lanes_count") is None and source.startswith("shifted: highway-fast differs")
    ok = resolve_scenario(str(zoo_run), "highway-fast", [f"highway.{k}={v}" for k, v in HF_KWARGS["config"].items()])
    assert ok[1] is None  # the preset made equal to the training config is not shifted
    args = ["--episodes", "1", "--env-set", "max_episode_steps=2", "--no-progress"]
    assert main(["evaluate", str(zoo_run), "--preset", "highway-fast", *args, "--out", str(tmp_path / "a")]) == 2
    assert "--shifted" in capsys.readouterr().err
    assert main(["evaluate", str(zoo_run), "--shifted", *args, "--out", str(tmp_path / "b")]) == 2  # nothing shifted
    assert "--shifted applies to a scenario named by --preset" in capsys.readouterr().err
    assert main(["evaluate", str(zoo_run), "--preset", "highway-fast", "--shifted", *args,
                 "--out", str(tmp_path / "c")]) == 0
    assert json.loads((tmp_path / "c" / "summary.json").read_text())["scenario_source"].startswith("shifted:")


def test_another_version_of_the_environment_is_refused(tmp_path: Path) -> None:
    from zodrive.policies.resolve import resolve_scenario

    model = PPO("MlpPolicy", gym.make("merge-v0"), n_steps=64, seed=0, device="cpu")
    with pytest.raises(ZodriveError, match="environment merge-v1, not merge-v0"):
        zodrive.evaluate(model, "merge", episodes=1)  # the model still holds the merge-v0 it was trained on
    assert resolve_scenario(model, None)[0]["env_id"] == "merge-v0"  # where the model in memory says it was trained
    folder = tmp_path / "exit"
    folder.mkdir()
    PPO("MlpPolicy", gym.make("exit-v0"), n_steps=64, seed=0, device="cpu").save(folder / "ppo-exit-v0")  # HF's name
    with pytest.raises(ZodriveError, match="environment exit-v1, not exit-v0"):
        resolve_preset(str(folder), "exit")
    assert resolve_preset(str(folder), None)["env_id"] == "exit-v0"


def test_a_scenario_mapping_is_checked_as_a_preset_file_is() -> None:
    with pytest.raises(ZodriveError, match="needs a 'name'"):
        zodrive.evaluate("baseline:slower", {"foo": 1}, episodes=1)
    with pytest.raises(ZodriveError, match="foo"):
        zodrive.evaluate("baseline:slower", {"name": "mine", "foo": 1}, episodes=1)


def test_files_that_would_feed_nan_or_allocate_without_bound_are_refused(trained, tmp_path: Path) -> None:
    """A VecNormalize file asking numpy for a 93 GiB array, one with variance 0 and epsilon 0, and a zip of NaN
    weights: one line each, before anything is allocated or driven."""
    import io
    import zipfile

    import torch

    class Huge:
        def __reduce__(self):
            return (np._core.multiarray._reconstruct, (np.ndarray, (93 * 2**30 // 8,), np.dtype("f8")))

    (tmp_path / "huge.pkl").write_bytes(pickle.dumps(Huge()))
    with pytest.raises(ZodriveError, match=r"an array of shape \(12482248704,\) is not part of a VecNormalize"):
        read_normalization(tmp_path / "huge.pkl")
    folder, _, venv = trained
    zero = tmp_path / "zero"
    zero.mkdir()
    shutil.copy(folder / "model.zip", zero / "model.zip")
    venv.obs_rms.var, venv.epsilon = venv.obs_rms.var * 0, 0.0
    try:
        venv.save(str(zero / "vecnormalize.pkl"))
    finally:
        venv.obs_rms.var, venv.epsilon = venv.obs_rms.var + 1.0, 1e-8
    with pytest.raises(ZodriveError, match="variance 0 with epsilon 0"):
        read_normalization(zero / "vecnormalize.pkl")
    nan = tmp_path / "nan.zip"
    with zipfile.ZipFile(folder / "model.zip") as src, zipfile.ZipFile(nan, "w") as out:
        for item in src.namelist():
            data = src.read(item)
            if item == "policy.pth":
                weights = torch.load(io.BytesIO(data))
                buffer = io.BytesIO()
                torch.save({k: v * float("nan") if v.is_floating_point() else v for k, v in weights.items()}, buffer)
                data = buffer.getvalue()
            out.writestr(item, data)
    with pytest.raises(ZodriveError, match="NaN or infinite weights"):
        zodrive.evaluate(str(nan), env_id=ENV, episodes=1)


def test_certify_and_export_refuse_a_model_trained_on_normalized_observations(trained, tmp_path: Path) -> None:
    """They work on the network alone: with the statistics beside it, their bounds or file would not be this
    policy's (they were computed on the raw network while evaluate applied the statistics)."""
    from zodrive.cli import main

    folder, _, _ = trained
    assert main(["certify", str(folder), "--env-id", ENV, "--eps", "0.01", "--episodes", "1"]) == 2
    assert main(["export", str(folder), "--out", str(tmp_path / "m.onnx")]) == 2
    assert not (tmp_path / "m.onnx").exists()
