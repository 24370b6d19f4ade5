"""Every option does what it says (issue 20): no traceback, no silent no-op, no wrong record,
one overwrite policy. Each case below was a finding of a 196-invocation trial of the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zodrive.cli import main

ROOT = Path(__file__).resolve().parents[1]
DQN = str(ROOT / "models" / "dqn")


def _error(capsys, args: list[str]) -> str:
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not err.startswith("zodrive: error: zodrive")  # one prefix
    return err


@pytest.mark.parametrize("args,message", [
    # wrong results recorded as right
    (["compare", "baseline:rules", "--attacks", "random-search", "--attack-set", "early_stop=nope", "--out", "{tmp}/c"],
     "early_stop must be true or false"),
    (["evaluate", str(ROOT / "models" / "ddpg"), "--attack", "zo-signsgd", "--loss", "paper"], "acts continuously"),
    (["evaluate", DQN, "--attack", "zo-signsgd", "--loss", "paper", "--target", "none"], "has no such choice"),
    # ignored without a word
    (["adv-train", DQN, "--no-attack", "--attack", "pgd", "--steps", "5", "--out", "{tmp}/a"], "no effect"),
    (["robust-train", DQN, "--method", "sa", "--epochs", "3", "--eps", "0.1", "--steps", "5", "--out", "{tmp}/r"],
     "--epochs has no effect with --method sa"),
    (["robust-train", DQN, "--method", "at", "--kappa", "1", "--eps", "0.1", "--steps", "5", "--out", "{tmp}/r"],
     "--kappa has no effect"),
    (["reproduce", "--quick", "--episodes", "50", "--out", "{tmp}/q"], "give one of them"),
    (["train", "--algo", "dqn", "--resume", "--out", "{tmp}/empty"], "nothing to resume"),
    (["train", "--algo", "dqn", "--resume", "--force", "--out", "{tmp}/empty"], "give one of them"),
    (["evaluate", "baseline:slower", "--attack", "random-search"], "constant action"),
    (["certify", DQN, "--eps", "0.01", "--tol", "0.1"], "--tol applies to continuous policies"),
    # tracebacks
    (["evaluate", "baseline:slower", "--env-set", "highway.duration=abc"], "highway.duration must be a number"),
    (["evaluate", "baseline:slower", "--env-set", "highway.collision_reward=abc"], "collision_reward must be a number"),
    (["env", "show", "discrete", "--set", "highway.duration=abc"], "highway.duration must be a number"),
    (["evaluate", "baseline:slower", "--out", "/proc/x"], "cannot write there"),
    (["evaluate", "baseline:slower", "--out", "/proc/a/b/c"], "cannot write there"),
    (["export", DQN, "--out", "/proc/a/b/c.onnx"], "cannot write there"),
    (["reproduce", "--out", "/sys/x/y"], "cannot write there"),
    (["compare", "baseline:slower", "--out", "{tmp}/c", "--plot", "/proc/p.png"], "cannot write there"),
    (["compare", "baseline:slower", "--out", "{tmp}/c", "--plot", "{tmp}/p.txt"], "image file"),
    (["compare", "baseline:slower", "--out", "{tmp}/c", "--plot", "{tmp}"], "image file"),
    # nonsense accepted
    (["evaluate", "baseline:slower", "--env-set", "highway.duration=-5"], "highway.duration must be > 0"),
    (["robust-train", DQN, "--method", "sa", "--kappa", "-1", "--eps", "0.1", "--steps", "5", "--out", "{tmp}/r"],
     "--kappa: expected a finite number >= 0"),
    (["train", "--algo", "dqn", "--out", "{tmp}/t", "--set", "hyperparameters.batch_size=-4"],
     "batch_size must be an integer >= 1"),
    (["evaluate", DQN, "--attack", "zo-signsgd", "--eps", "inf"], "--eps: expected a finite number in (0, 1e+06], got inf"),
    # words
    (["export", str(ROOT / "README.md"), "--out", "{tmp}/m.onnx"], "not a stable-baselines3 model"),
    # plain cloning has no radius (issue 22)
    (["robust-train", DQN, "--method", "distill", "--kappa", "0", "--eps", "0.05", "--steps", "5", "--out", "{tmp}/r"],
     "--eps has no effect with --kappa 0"),
    (["robust-train", DQN, "--method", "sa", "--steps", "5", "--out", "{tmp}/r"], "needs --eps"),
    (["robust-train", DQN, "--method", "at", "--dagger", "2", "--eps", "0.1", "--steps", "5", "--out", "{tmp}/r"],
     "--dagger has no effect with --method at"),
    # lockstep and the default attack's switches (issue 21)
    (["evaluate", DQN, "--attack", "zo-signsgd", "--attack-share", "0.5", "--envs", "4"],
     "cannot run side by side here (a frequency budget decides an episode's steps one by one"),
    (["evaluate", "baseline:idm-mobil", "--envs", "2"], "reads its own simulator"),
    (["evaluate", DQN, "--envs", "0"], "--envs"),
    (["evaluate", DQN, "--attack", "zo-signsgd", "--patience", "3", "--no-patience"], "contradict each other"),
    (["evaluate", DQN, "--no-warm-start"], "no --attack was given"),
    # found again by studies/input-trial/rerun.py
    (["train", "--algo", "dqn", "--steps", "100", "--set", "hyperparameters.buffer_size=10000000000", "--out", "{tmp}/t"],
     "buffer_size must be at most 10,000,000"),
    (["train", "--algo", "dqn", "--steps", "100", "--set", "hyperparameters.policy_kwargs.net_arch=[-1]", "--out",
      "{tmp}/t"], "net_arch must list layer widths"),
    (["train", "--algo", "dqn", "--steps", "100", "--set", "total_timesteps=abc", "--out", "{tmp}/t"],
     "--steps and --set total_timesteps=... both set the step budget"),
    (["train", "--algo", "dqn", "--set", "checkpoint_every=-5", "--out", "{tmp}/t"], "checkpoint_every must be an integer >= 0"),
    (["evaluate", str(ROOT / "tests" / "golden" / "cart_policy.py") + ":make", "--env-id", "CartPole-v1", "--defense",
      "kinematic"], "is not a highway-env preset"),
    (["compare", "baseline:slower", "--out", "{tmp}/c", "--plot", str(ROOT / "docs" / "leaderboard.png")],
     "already holds a figure"),
    # limits at the edge and the option rule, generated from the attack schema (issue 47)
    (["evaluate", "baseline:slower", "--preset", "highway-fast", "--env-set", "highway.observation.vehicle_count=7"],
     "highway.observation.vehicle_count is not an option of FastKinematics"),
    (["evaluate", "baseline:slower", "--preset", "highway-fast", "--env-set",
      "highway.observation={type:GrayscaleObservation}"], "is not an option of FastKinematics"),  # no space: one key
    (["evaluate", DQN, "--attack", "zo-signsgd", "--n-directions", "10000000000"],
     "--n-directions: expected an integer in [1, 10000], got 10000000000"),
    (["evaluate", DQN, "--attack", "zo-signsgd", "--query-budget", str(10**30)], "--query-budget: expected an integer in [1, 1e+09]"),
    (["evaluate", DQN, "--attack", "zo-signsgd", "--eps", "1e300"], "--eps: expected a finite number in (0, 1e+06], got 1e300"),
    (["evaluate", DQN, "--attack", "pgd", "--n-directions", "5"], "attack pgd: n_directions has no effect"),
    (["evaluate", DQN, "--attack", "pgd", "--mu", "0.1"], "attack pgd: mu has no effect"),
    (["evaluate", DQN, "--attack", "uniform-noise", "--steps", "5"], "attack uniform-noise: steps has no effect"),
    (["evaluate", DQN, "--attack", "fgsm", "--steps", "50"], "attack fgsm: steps has no effect"),
    (["evaluate", DQN, "--attack", "random-search", "--step-size", "0.1"], "attack random-search: step_size has no effect"),
    (["compare", DQN, "--attacks", "fgsm", "pgd", "--attack-set", "steps=3", "--out", "{tmp}/c"],
     "attack fgsm: steps has no effect"),
])
def test_each_finding_is_one_clear_line(tmp_path: Path, capsys, args: list[str], message: str) -> None:
    err = _error(capsys, [a.replace("{tmp}", str(tmp_path)) for a in args])
    assert message in err
    assert not (tmp_path / "a").exists() and not (tmp_path / "r").exists()  # no stub after a failed start


def test_an_attack_file_with_a_string_boolean_or_nothing_in_it_is_refused(tmp_path: Path, capsys) -> None:
    config = tmp_path / "a.yaml"
    config.write_text('attack: zo-signsgd\nearly_stop: "false"\n')
    assert "early_stop must be true or false, not 'false'" in _error(capsys, ["evaluate", DQN, "--attack", str(config)])
    config.write_text("")
    assert "names no attack" in _error(capsys, ["evaluate", DQN, "--attack", str(config)])


def test_paper_mode_records_no_budget(tmp_path: Path, capsys) -> None:
    out = tmp_path / "e"
    assert main(["evaluate", DQN, "--attack", "zo-signsgd", "--mode", "paper", "--eps", "0.01", "--steps", "2",
                 "--episodes", "1", "--env-set", "max_episode_steps=5", "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["eps"] is None and summary["mode"] == "paper"  # 0.01 is no budget here
    assert "unconstrained" in capsys.readouterr().out


def test_select_from_a_step_past_every_checkpoint_is_refused_and_writes_nothing(tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    assert main(["train", "--algo", "dqn", "--steps", "120", "--out", str(run), "--no-progress", "--env-set",
                 "max_episode_steps=10", "--set", "hyperparameters.learning_starts=50", "--set",
                 "checkpoint_every=60"]) == 0
    capsys.readouterr()
    assert "no checkpoints from step 99999999" in _error(capsys, ["select", str(run), "--from-step", "99999999"])
    assert not (run / "selected.json").exists() and not (run / "selection").exists()


def test_nothing_is_overwritten_without_force(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "model"
    folder.mkdir()
    (folder / "CARD.md").write_text("# hand-written\n## Notes\n- keep me\n")
    assert "use --force" in _error(capsys, ["card", str(folder)])
    assert "keep me" in (folder / "CARD.md").read_text()
    (tmp_path / "render").mkdir()
    (tmp_path / "render" / "episode.png").write_bytes(b"x")
    assert "use --force" in _error(capsys, ["render", "baseline:slower", "--out", str(tmp_path / "render")])
    (tmp_path / "m.onnx").write_bytes(b"x")
    assert "use --force" in _error(capsys, ["export", DQN, "--out", str(tmp_path / "m.onnx")])


def test_compare_refuses_another_grid_in_its_folder(tmp_path: Path, capsys) -> None:
    out = tmp_path / "grid"
    base = ["compare", "baseline:slower", "--episodes", "1", "--env-set", "max_episode_steps=3", "--no-progress",
            "--out", str(out)]
    assert main(base) == 0
    assert main(base + ["--episodes", "2"]) == 0  # the same grid resumes with more episodes
    capsys.readouterr()
    assert "another comparison" in _error(capsys, base[:1] + ["baseline:idle"] + base[2:])
    assert main(base[:1] + ["baseline:idle"] + base[2:] + ["--force"]) == 0


def test_models_from_the_environment_must_exist(monkeypatch, capsys) -> None:
    monkeypatch.setenv("ZODRIVE_MODELS", "/nonexistent")
    assert "ZODRIVE_MODELS=/nonexistent: not a folder" in _error(capsys, ["evaluate", "baseline:slower"])


def test_help_states_each_default_once(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    out = capsys.readouterr().out
    assert "(default 100000) (default" not in out and "(default: [])" not in out and "(default: None)" not in out


def test_interrupted_train_names_the_flag_that_resumes(monkeypatch, tmp_path: Path, capsys) -> None:
    import zodrive.cli as cli

    def interrupted(args):  # noqa: ANN001
        raise KeyboardInterrupt

    monkeypatch.setitem(cli.COMMANDS, "train", interrupted)
    assert main(["train", "--algo", "dqn", "--out", str(tmp_path / "t")]) == 130
    assert "--resume" in capsys.readouterr().err


def test_the_default_attack_can_search_every_step_from_scratch() -> None:
    """`zo-signsgd` carries its perturbation and gives up stalled steps by default; the two
    switches turn that off, and the paper's literal config never had it."""
    from zodrive.attacks.spec import load_attack
    from zodrive.cli import attack_spec_from_args, build_parser

    parse = lambda *flags: attack_spec_from_args(build_parser().parse_args(["evaluate", DQN, *flags]))  # noqa: E731
    default = parse("--attack", "zo-signsgd")
    assert (default.warm_start, default.patience) == (True, 10)
    scratch = parse("--attack", "zo-signsgd", "--no-warm-start", "--no-patience")
    assert (scratch.warm_start, scratch.patience) == (False, None)
    assert scratch.to_dict() == {**default.to_dict(), "warm_start": False, "patience": None}
    paper = load_attack("zo-signsgd-paper")
    assert (paper.warm_start, paper.patience, paper.early_stop) == (False, None, False)
