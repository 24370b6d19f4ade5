"""The command line: a training + evaluation smoke run and every bad-input path."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from zodrive.cli import main


@pytest.fixture(scope="session")
def tiny_dqn(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dqn")
    code = main(["train", "--algo", "dqn", "--steps", "300", "--out", str(out), "--no-progress",
                 "--set", "hyperparameters.learning_starts=100"])
    assert code == 0
    return out


@pytest.mark.integration
def test_train_writes_a_complete_run_folder(tiny_dqn: Path) -> None:
    for name in ("model.zip", "config.yaml", "run.json", "train.json", "progress.csv", "monitor.monitor.csv"):
        assert (tiny_dqn / name).is_file(), name
    run = json.loads((tiny_dqn / "run.json").read_text())
    assert run["seed"] == 0 and "stable-baselines3" in run["versions"]
    assert "train --algo dqn" in run["command"]


def test_a_run_records_how_this_cpu_rounds_float32() -> None:
    """Another instruction set gives torch's kernels other last bits (tests/test_slow_reproducible.py):
    the fingerprint in every run's versions says which. Forcing ATen's scalar path changes it."""
    import torch

    from zodrive.runinfo import float_fingerprint, versions

    assert versions()["float32"] == float_fingerprint() and len(float_fingerprint()) == 12
    if torch.backends.cpu.get_cpu_capability() == "DEFAULT":
        pytest.skip("this CPU already takes ATen's scalar path")
    code = "from zodrive.runinfo import float_fingerprint; print(float_fingerprint())"
    scalar = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            env={**os.environ, "ATEN_CPU_CAPABILITY": "default"}).stdout.strip()
    assert len(scalar) == 12 and scalar != float_fingerprint()


def test_evaluate_writes_summary_and_records(tiny_dqn: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "eval"
    assert main(["evaluate", str(tiny_dqn), "--episodes", "2", "--seed", "5", "--out", str(out), "--no-progress",
                 "--env-set", "max_episode_steps=60"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("mean_return", "ci95", "pct_of_max", "collision_rate", "episodes", "seed"):
        assert key in summary
    assert summary["episodes"] == 2 and summary["seed"] == 5
    episodes = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert [e["seed"] for e in episodes] == [5, 6]
    assert "mean return" in capsys.readouterr().out


@pytest.mark.integration
def test_evaluation_is_deterministic_and_resumes(tiny_dqn: Path, tmp_path: Path) -> None:
    args = ["evaluate", str(tiny_dqn), "--episodes", "3", "--no-progress", "--attack", "zo-signsgd", "--steps", "5",
            "--env-set", "max_episode_steps=60"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    assert main(args + ["--out", str(tmp_path / "b")]) == 0
    a = json.loads((tmp_path / "a" / "summary.json").read_text())
    b = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert a["mean_return"] == b["mean_return"] and a["queries_per_step"] == b["queries_per_step"]
    # cut the run after one episode, then resume: the same numbers
    lines = (tmp_path / "a" / "episodes.jsonl").read_text().splitlines()
    (tmp_path / "a" / "episodes.jsonl").write_text(lines[0] + "\n" + lines[1][:10])
    (tmp_path / "a" / "summary.json").unlink()
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    c = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert c["mean_return"] == a["mean_return"]
    assert len((tmp_path / "a" / "episodes.jsonl").read_text().splitlines()) == 3


def test_a_folder_made_before_an_option_existed_still_resumes(tiny_dqn: Path, tmp_path: Path) -> None:
    """A key without a later option (here max_change) was made with its default: it resumes;
    a key whose recorded option differs is refused."""
    args = ["evaluate", str(tiny_dqn), "--no-progress", "--attack", "uniform-noise", "--env-set", "max_episode_steps=10",
            "--out", str(tmp_path / "old")]
    assert main(args + ["--episodes", "1"]) == 0
    key_path = tmp_path / "old" / "eval_key.json"
    key = json.loads(key_path.read_text())
    del key["attack"]["max_change"]
    key_path.write_text(json.dumps(key))
    assert main(args + ["--episodes", "2"]) == 0
    assert len((tmp_path / "old" / "episodes.jsonl").read_text().splitlines()) == 2
    assert main(args + ["--episodes", "3", "--max-change", "0.01"]) == 2


def test_attacked_summary_has_attack_fields(tiny_dqn: Path, tmp_path: Path) -> None:
    out = tmp_path / "att"
    assert main(["evaluate", str(tiny_dqn), "--episodes", "1", "--no-progress", "--attack", "zo-signsgd",
                 "--steps", "3", "--n-directions", "4", "--out", str(out), "--env-set", "max_episode_steps=60"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("attack", "eps", "attack_success_rate", "queries_per_step", "max_linf", "target_base_rate"):
        assert key in summary
    assert summary["max_linf"] <= 0.2 + 1e-6
    assert summary["queries_per_step"] <= 1 + 3 * 5
    steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    assert {"queries", "iterations", "success", "linf", "l2", "wall_time"} <= set(steps[0])


def _error(capsys, args: list[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zodrive: error:") and "\n" not in err and "Traceback" not in err
    return err


def test_bad_model_files(tmp_path: Path, capsys) -> None:
    assert "not found" in _error(capsys, ["evaluate", str(tmp_path / "missing.zip")])
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip at all")
    assert "not a stable-baselines3 model" in _error(capsys, ["evaluate", str(junk)])
    empty = tmp_path / "empty.zip"
    with zipfile.ZipFile(empty, "w") as z:
        z.writestr("hello.txt", "hi")
    assert "stable-baselines3" in _error(capsys, ["evaluate", str(empty)])


def test_model_that_does_not_fit_the_preset(tiny_dqn: Path, capsys) -> None:
    assert "DQN policy with discrete actions" in _error(capsys, ["evaluate", str(tiny_dqn), "--preset", "continuous"])
    err = _error(capsys, ["evaluate", str(tiny_dqn), "--env-set", "highway.observation.vehicles_count=7"])
    assert "shape" in err


@pytest.mark.parametrize(
    "args,message",
    [
        (["env", "show", "nope"], "unknown preset"),
        (["env", "show", "discrete", "--set", "highway.lanes_count"], "KEY.PATH=VALUE"),
        (["evaluate", "m.zip", "--episodes", "0"], "positive integer"),
        (["evaluate", "m.zip", "--episodes", "abc"], "positive integer"),
        (["train", "--algo", "ppo", "--out", "x"], "invalid choice"),
        (["evaluate", "m.zip", "--seed", "-1"], "integer >= 0"),
        (["train", "--algo", "dqn", "--seed", "-3", "--out", "x"], "integer >= 0"),
        (["render", "m.zip", "--seed", "-1", "--out", "x"], "integer >= 0"),
        (["evaluate", "m.zip", "--attack", "nes", "--attack-seed", "-1"], "integer >= 0"),
        (["adv-train", "m.zip", "--steps", "5", "--warmup", "-1", "--out", "x"], "integer >= 0"),
        (["render", "m.zip", "--out", "README.md"], "is a file, not a folder"),
        (["compare", "baseline:slower", "--attacks", "nosuch", "--out", "x"], "unknown attack"),
        (["evaluate", "baseline:slower", "--eps", "0.1"], "no --attack was given"),
        (["evaluate", "m.zip"], "model file not found"),
        (["env", "show", "discrete", "--set", "highway.lane_count=3"], "did you mean 'highway.lanes_count'"),
        (["train", "--algo", "dqn", "--out", "x", "--set", "hyperparameters.gama=1"], "did you mean 'hyperparameters.gamma'"),
        (["train", "--algo", "dqn", "--out", "x", "--set", "nosuch=1"], "unknown key 'nosuch'"),
    ],
)
def test_bad_arguments(args: list[str], message: str, capsys, monkeypatch) -> None:
    monkeypatch.chdir(Path(__file__).resolve().parents[1])  # README.md exists there
    assert message in _error(capsys, args)
    assert not Path("x").exists()  # no half-made output folder


@pytest.mark.parametrize(
    "flags,message",
    [(["--eps", "0"], "eps"), (["--steps", "0"], "steps"), (["--n-directions", "0"], "--n-directions"),
     (["--attack", "nope"], "unknown attack"), (["--target", "WARP"], "unknown target")],
)
def test_bad_attack_flags(tiny_dqn: Path, flags: list[str], message: str, capsys) -> None:
    args = ["evaluate", str(tiny_dqn), "--episodes", "1"] + (["--attack", "zo-signsgd"] if "--attack" not in flags else [])
    assert message in _error(capsys, args + flags)


def test_console_script_exits_nonzero_without_traceback(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "zodrive", "evaluate", str(tmp_path / "nope.zip")],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"zodrive: error: model file not found: {tmp_path / 'nope.zip'}"]


@pytest.mark.integration
@pytest.mark.parametrize("attack", [[], ["--attack", "random-search", "--steps", "5"]], ids=["clean", "attacked"])
def test_workers_do_not_change_the_numbers(tiny_dqn: Path, tmp_path: Path, attack: list[str]) -> None:
    args = ["evaluate", str(tiny_dqn), "--episodes", "3", "--no-progress", "--env-set", "max_episode_steps=40", *attack]
    assert main(args + ["--out", str(tmp_path / "one")]) == 0
    assert main(args + ["--out", str(tmp_path / "two"), "--workers", "2"]) == 0
    one = json.loads((tmp_path / "one" / "summary.json").read_text())
    two = json.loads((tmp_path / "two" / "summary.json").read_text())
    assert one["mean_return"] == two["mean_return"] and one["ci95"] == two["ci95"]
    assert one.get("attack_success_rate") == two.get("attack_success_rate")
    assert one.get("queries_per_step") == two.get("queries_per_step")


@pytest.mark.integration
def test_train_refuses_an_existing_run_and_resumes_from_a_checkpoint(tmp_path: Path, capsys, recwarn) -> None:
    out = tmp_path / "run"
    base = ["train", "--algo", "dqn", "--out", str(out), "--no-progress",
            "--set", "hyperparameters.learning_starts=50", "--set", "checkpoint_every=100"]
    assert main(base + ["--steps", "200"]) == 0
    assert (out / "checkpoints" / "dqn_200_steps.zip").is_file()
    assert (out / "checkpoints" / "dqn_replay_buffer_200_steps.pkl").is_file()
    assert main(base + ["--steps", "200"]) == 2
    assert "--resume" in capsys.readouterr().err
    # another recipe is refused (only the step budget may grow), and the run stays as it was
    assert main(base + ["--steps", "200", "--resume", "--set", "hyperparameters.gamma=0.5"]) == 2
    assert "another recipe" in capsys.readouterr().err
    for name in ("model.zip", "checkpoints/dqn_200_steps.zip", "checkpoints/dqn_replay_buffer_200_steps.pkl"):
        (out / name).unlink()  # as if the run was cut between steps 100 and 200
    assert main(base + ["--steps", "200", "--resume"]) == 0
    train = json.loads((out / "train.json").read_text())
    assert train["resumed_from"] == 100 and (out / "model.zip").is_file()
    assert (out / "checkpoints" / "dqn_200_steps.zip").is_file()  # the resumed run went on to 200
    assert main(base + ["--steps", "300", "--resume"]) == 0  # train it longer
    assert not [w for w in recwarn if "is ignored" in str(w.message)]  # SB3's n_steps warning on a load is wrong
    train = json.loads((out / "train.json").read_text())
    assert train["resumed_from"] == 200 and train["total_timesteps"] == 300
    (out / "notes.txt").write_text("mine")
    assert main(base + ["--steps", "200", "--force"]) == 0
    assert json.loads((out / "train.json").read_text())["resumed_from"] is None
    # --force cleared the old run: no checkpoint of the 300-step run is left to be taken for this one's
    assert sorted(p.name for p in (out / "checkpoints").glob("dqn_*_steps.zip")) == [
        "dqn_100_steps.zip", "dqn_200_steps.zip"]
    assert (out / "notes.txt").read_text() == "mine"  # what train did not write is kept


def test_evaluation_is_keyed_on_the_model_content(tiny_dqn: Path, tmp_path: Path, capsys) -> None:
    """A moved model still resumes; a swapped file at the same path is refused, and fewer
    episodes than are on disk never drop any."""
    moved = tmp_path / "moved.zip"
    moved.write_bytes((tiny_dqn / "model.zip").read_bytes())
    out = tmp_path / "eval"
    args = ["--episodes", "2", "--out", str(out), "--no-progress", "--env-set", "max_episode_steps=20", "--preset",
            "discrete"]  # the moved zip has no run folder to say where it drives
    assert main(["evaluate", str(tiny_dqn)] + args) == 0
    assert main(["evaluate", str(moved)] + args) == 0  # same bytes elsewhere: the same evaluation
    other = tmp_path / "other"
    assert main(["train", "--algo", "dqn", "--steps", "150", "--seed", "3", "--out", str(other), "--no-progress",
                 "--set", "hyperparameters.learning_starts=50"]) == 0
    moved.write_bytes((other / "model.zip").read_bytes())
    capsys.readouterr()
    assert main(["evaluate", str(moved)] + args) == 2
    assert "the model" in capsys.readouterr().err
    assert main(["evaluate", str(tiny_dqn), "--episodes", "1"] + args[2:]) == 2
    assert "never drops" in capsys.readouterr().err
    assert len((out / "episodes.jsonl").read_text().splitlines()) == 2


def test_adv_train_refuses_to_overwrite_a_run(tiny_dqn: Path, capsys) -> None:
    assert main(["adv-train", str(tiny_dqn), "--steps", "10", "--out", str(tiny_dqn), "--trust-model"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (tiny_dqn / "model.zip").is_file()


def test_bad_yaml_values_and_hyperparameters(tmp_path: Path, capsys) -> None:
    config = tmp_path / "a.yaml"
    config.write_text("attack: zo-signsgd\neps: banana\n")
    assert "must be a number" in _error(capsys, ["evaluate", "baseline:slower", "--attack", str(config)])
    out = tmp_path / "run"
    err = _error(capsys, ["train", "--algo", "dqn", "--out", str(out), "--set", "hyperparameters.learning_rate=banana"])
    assert "learning_rate must be a number" in err and not out.exists()


@pytest.mark.integration
def test_select_picks_a_checkpoint_on_tuning_seeds(tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    assert main(["train", "--algo", "dqn", "--steps", "200", "--out", str(run), "--no-progress", "--env-set",
                 "max_episode_steps=20", "--set", "hyperparameters.learning_starts=50", "--set", "checkpoint_every=100"]) == 0
    assert main(["select", str(run), "--episodes", "2", "--no-progress"]) == 0
    choice = json.loads((run / "selected.json").read_text())
    steps = [c["steps"] for c in choice["candidates"]]
    assert steps == [100, 200]  # the final model is the 200-step checkpoint: not evaluated twice
    assert choice["selected"]["mean_return"] == max(c["mean_return"] for c in choice["candidates"])
    summary = json.loads((run / "selection" / "100" / "summary.json").read_text())
    assert summary["seed"] == 50_000  # tuning seeds, never the evaluation seeds
    assert "selected:" in capsys.readouterr().out
    assert main(["select", str(tmp_path), "--episodes", "2"]) == 2


def test_compare_over_query_budgets_draws_the_budget_curve(tiny_dqn: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "grid"
    assert main(["compare", str(tiny_dqn), "--attacks", "zo-signsgd", "--query-budgets", "21", "42",
                 "--episodes", "1", "--out", str(out), "--no-progress", "--plot", str(out / "budget.png"),
                 "--env-set", "max_episode_steps=60"]) == 0
    rows = json.loads((out / "table.json").read_text())
    assert [r["query_budget"] for r in rows] == [None, 21, 42]
    assert rows[1]["queries_per_step"] <= 21 < rows[2]["queries_per_step"] <= 42
    assert (out / "cells" / f"{tiny_dqn.name}-zo-signsgd-eps0.2-qb21" / "summary.json").is_file()
    assert (out / "budget.png").stat().st_size > 0
    assert "Budget/step" in capsys.readouterr().out


@pytest.mark.integration
def test_compare_over_eps_and_defenses_gives_each_its_strongest_attack(tiny_dqn: Path, tmp_path: Path) -> None:
    out = tmp_path / "curve"
    pgd = tmp_path / "configs" / "pgd.yaml"  # steps for PGD alone: uniform noise takes none (--attack-set would be refused)
    pgd.parent.mkdir()
    pgd.write_text("attack: pgd\nsteps: 3\n")
    assert main(["compare", str(tiny_dqn), "baseline:slower", "baseline:rules", "--attacks", "uniform-noise", str(pgd),
                 "--eps", "0.05", "0.2", "--defense", "none", "kinematic", "--episodes", "2", "--out", str(out), "--no-progress",
                 "--env-set", "max_episode_steps=20",
                 "--plot", str(out / "robustness.png")]) == 0
    rows = json.loads((out / "table.json").read_text())
    model = [r for r in rows if r["model"] == tiny_dqn.name]
    assert len(model) == 2 * (1 + 2 * 2)  # defenses x (clean + attacks x eps)
    assert [r for r in rows if r["model"] == "baseline:slower"] == [
        r for r in rows if r["model"] == "baseline:slower" and r["attack"] == "none" and r["defense"] == "none"]
    assert (out / "cells" / f"{tiny_dqn.name}+kinematic-pgd-eps0.2" / "summary.json").is_file()
    rules = [r for r in rows if r["model"] == "baseline:rules"]  # no gradients: no white-box cells
    assert len(rules) == 2 * (1 + 2) and {r["attack"] for r in rules} == {"none", "uniform-noise"}
    assert max(r["queries_per_step"] for r in model if r["attack"] == "pgd (white-box)") <= 3  # --attack-set
    text = (out / "robustness.md").read_text()
    assert f"| {tiny_dqn.name} + kinematic |" in text and "(ignores its input)" in text
    worst = min(r["mean_return"] for r in model if r["defense"] == "none" and r["eps"] == 0.2)
    assert f"{worst:.1f} (" in text.split(f"| {tiny_dqn.name} |")[1].splitlines()[0]
    assert (out / "robustness.png").stat().st_size > 0


@pytest.mark.integration
def test_render_writes_png_gif_and_mp4(tmp_path: Path, capsys) -> None:
    out = tmp_path / "video"
    assert main(["render", "baseline:slower", "--out", str(out), "--env-set", "max_episode_steps=12"]) == 0
    for name in ("episode.png", "episode.gif", "episode.mp4", "episode.json"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "episode.mp4").read_bytes()[4:8] == b"ftyp"  # an MP4 container
    assert "episode.mp4" in capsys.readouterr().out


@pytest.mark.integration
def test_render_through_the_filter(tiny_dqn: Path, tmp_path: Path) -> None:
    out = tmp_path / "defended"
    assert main(["render", str(tiny_dqn), "--out", str(out), "--env-set", "max_episode_steps=8", "--defense",
                 "kinematic", "--attack", "uniform-noise"]) == 0
    assert json.loads((out / "episode.json").read_text())["defense"] == "kinematic"


@pytest.mark.slow
def test_compare_on_ray_gives_the_local_numbers(tiny_dqn: Path, tmp_path: Path) -> None:
    pytest.importorskip("ray")
    args = ["compare", "baseline:slower", str(tiny_dqn), "--attacks", "zo-signsgd", "--query-budgets", "21",
            "--episodes", "2", "--no-progress"]
    assert main(args + ["--out", str(tmp_path / "local")]) == 0
    assert main(args + ["--out", str(tmp_path / "ray"), "--backend", "ray", "--workers", "2"]) == 0
    local, ray = (json.loads((tmp_path / name / "table.json").read_text()) for name in ("local", "ray"))
    assert local == ray  # same cells, same order, same numbers


@pytest.mark.integration
def test_a_td3_row_trains_and_is_read_like_a_ddpg(tmp_path: Path) -> None:
    out = tmp_path / "td3"
    assert main(["train", "--algo", "td3", "--steps", "200", "--set", "hyperparameters.learning_starts=50",
                 "--out", str(out), "--no-progress"]) == 0
    from zodrive.policies.policy import resolve
    from zodrive.policies.safe_load import load_policy_network

    assert resolve(str(out)).action_kind() == "continuous"
    assert load_policy_network(out / "model.zip").n_outputs == 2  # the actor, rebuilt without unpickling
    assert json.loads((out / "train.json").read_text())["algo"] == "td3"


def test_a_reader_that_closes_the_pipe_stops_the_command_quietly() -> None:
    """`zodrive … | head` is a pipeline, not an error: no message, no traceback, exit 141 (128 + SIGPIPE)."""
    proc = subprocess.Popen([sys.executable, "-m", "zodrive", "baselines"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before the command writes
    err = proc.stderr.read().decode()
    assert proc.wait() == 141 and err == ""


def test_a_failed_write_leaves_no_stray_file(tmp_path: Path, monkeypatch) -> None:
    """A full disk left `.summary.json.XXXX` behind, and the next run refused the folder for it."""
    import os

    from zodrive.runinfo import write_atomic

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(OSError):
        write_atomic(tmp_path / "summary.json", "{}")
    assert list(tmp_path.iterdir()) == []
