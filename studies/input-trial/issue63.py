"""Re-run the examples of issue 63 ("Right numbers, every machine") as a user would type them, and write
issue63.md: the installed `zodrive` CLI, or a short Python script where the example is Python, each in its
own folder under one fresh temporary folder, with the helpers of `rerun.py` (timeouts, verdicts, table).

    . .venv/bin/activate && python studies/input-trial/issue63.py        # about 3 minutes on 2 cores

The models it needs are built here, untrained (only where they drive and what they are matters): a PPO on
highway-fast-v0 saved bare, in an rl-zoo3 run folder and in a folder whose env_kwargs.yml changes the
scenario; a PPO on exit-v0 and merge-v0; a RecurrentPPO, a frame-stacked PPO, a parking-v0 SAC; a CartPole
PPO inside VecNormalize. Nothing in the checkout is written but `studies/input-trial/issue63.md`.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import textwrap
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rerun as R  # noqa: E402  (the trial's helpers: run, ex, snippet, record, write_md)

ZOD, PY, REPO = R.ZOD, R.PY, R.REPO
FAST = ["--episodes", "1", "--env-set", "max_episode_steps=3", "--no-progress"]

BUILD = textwrap.dedent("""\
    import sys, os, json
    from pathlib import Path
    import gymnasium as gym, highway_env  # noqa: F401
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    out = Path(sys.argv[1])
    kw = {"n_steps": 64, "batch_size": 64, "seed": 0, "device": "cpu"}
    hf = PPO("MlpPolicy", gym.make("highway-fast-v0"), **kw)
    (out / "bare").mkdir(parents=True); hf.save(out / "bare" / "ppo")
    run = out / "logs" / "ppo" / "highway-fast-v0_1"; (run / "highway-fast-v0").mkdir(parents=True)
    cfg = {"lanes_count": 4, "vehicles_count": 30, "duration": 20, "vehicles_density": 1.5}
    PPO("MlpPolicy", gym.make("highway-fast-v0", config=cfg), **kw).save(run / "highway-fast-v0")
    (run / "highway-fast-v0" / "args.yml").write_text(
        "!!python/object/apply:collections.OrderedDict\\n- - - algo\\n    - ppo\\n  - - env\\n    - highway-fast-v0\\n"
        "  - - env_kwargs\\n    - {config: " + json.dumps(cfg) + "}\\n")
    hub = out / "hub"; hub.mkdir(); hf.save(hub / "ppo-highway-fast-v0")
    (hub / "env_kwargs.yml").write_text("config: " + json.dumps(cfg) + "\\n")
    ex = out / "exit"; ex.mkdir(); PPO("MlpPolicy", gym.make("exit-v0"), **kw).save(ex / "ppo-exit-v0")
    bad = out / "badkw"; bad.mkdir(); hf.save(bad / "ppo-highway-fast-v0"); (bad / "env_kwargs.yml").write_text("config: 5\\n")
    sac = out / "parking"; sac.mkdir()
    SAC("MultiInputPolicy", gym.make("parking-v0"), learning_starts=10, seed=0, device="cpu").save(sac / "sac")
    raw = out / "raw"; raw.mkdir(); unnormalized = {"observation": {"type": "Kinematics", "normalize": False}}
    PPO("MlpPolicy", gym.make("highway-fast-v0", config=unnormalized), **kw).save(raw / "ppo-highway-fast-v0")
    (raw / "env_kwargs.yml").write_text("config: " + json.dumps(unnormalized) + "\\n")
    vn = out / "vecnorm"; vn.mkdir(); venv = VecNormalize(DummyVecEnv([lambda: gym.make("CartPole-v1")]))
    PPO("MlpPolicy", venv, **kw).save(vn / "model"); venv.save(str(vn / "vecnormalize.pkl"))
    print("built")
    """)


def api(code: str) -> str:
    """A Python example; a ZodriveError (the API's refusal) is printed as the CLI prints one, with exit 2, so the
    verdicts read alike; any other exception stays a traceback."""
    body = textwrap.indent(textwrap.dedent(code), "    ")
    return ("import sys, warnings, zodrive, numpy as np, gymnasium as gym, highway_env\n"
            "from zodrive.errors import ZodriveError\n"
            "warnings.filterwarnings('ignore')  # the user's own gym.make('merge-v0') and SB3 wrapping notices\n"
            f"try:\n{body}\nexcept ZodriveError as exc:\n    print(f'zodrive: error: {{exc}}', file=sys.stderr)\n"
            "    sys.exit(2)\n")


def refused_with(words: str) -> R.Check:
    def check(r: R.Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc == 2 and words not in r.err:
            return "WRONG", f"refused, but not for '{words}'"
        return None

    return check


def printed(words: str) -> R.Check:
    def check(r: R.Res, cwd: Path) -> tuple[str, str] | None:
        return None if words in r.out + r.err else ("WRONG", f"'{words}' not printed")

    return check


def issue63() -> None:
    i = R.INP
    hf = ["--preset", "highway-fast"]
    # 2. no scenario guessed
    R.ex("63.2a", "a bare highway-fast PPO zip without --preset (printed 320.56 on the paper's preset)",
         ZOD + ["evaluate", str(i / "bare" / "ppo.zip"), *FAST], check=refused_with("does not say where"))
    R.ex("63.2b", "a damaged zip without --preset: its damage, in one line", ZOD + ["evaluate", str(i / "junk.zip"),
         *FAST], setup=lambda cwd: (i / "junk.zip").write_bytes(b"PK\x03\x04 not a zip"), check=refused_with("zip"))
    R.ex("63.2c", "a crafted zip with 10^30 actions: one line, no WARNING before it",
         ZOD + ["evaluate", str(i / "zip-n-huge" / "model.zip"), *FAST])
    # 3. the model's own config
    R.snippet("63.3a", "an rl-zoo3 run folder: args.yml's env_kwargs are applied", api(f"""
        from zodrive.policies.resolve import resolve_preset
        p = resolve_preset({str(i / 'logs' / 'ppo' / 'highway-fast-v0_1')!r}, None)
        print({{k: p['highway'][k] for k in ('lanes_count', 'vehicles_count', 'duration', 'vehicles_density')}})
        """), check=printed("'lanes_count': 4, 'vehicles_count': 30, 'duration': 20, 'vehicles_density': 1.5"))
    R.ex("63.3b", "--preset highway-fast on a folder whose env_kwargs.yml sets lanes 4, vehicles 30, duration 20",
         ZOD + ["evaluate", str(i / "hub"), *hf, *FAST], check=refused_with("--shifted"))
    R.ex("63.3c", "... with --shifted: runs, and summary.json says it was shifted",
         ZOD + ["evaluate", str(i / "hub"), *hf, "--shifted", "--out", "out", *FAST], expect="run",
         check=lambda r, cwd: None if json.loads((cwd / "out" / "summary.json").read_text())["scenario_source"]
         .startswith("shifted:") else ("WRONG", "no shifted source"))
    R.ex("63.3d", "--preset exit on an exit-v0 folder (ran exit-v1)", ZOD + ["evaluate", str(i / "exit"), "--preset",
         "exit", *FAST], check=refused_with("exit-v1, not exit-v0"))
    R.snippet("63.3e", "a model trained on merge-v0, evaluated with 'merge' (ran merge-v1)", api("""
        from stable_baselines3 import PPO
        model = PPO("MlpPolicy", gym.make("merge-v0"), n_steps=64, seed=0, device="cpu")
        zodrive.evaluate(model, "merge", episodes=1)
        """), expect="refuse", check=refused_with("merge-v1, not merge-v0"))
    R.ex("63.3f", "an env_kwargs.yml with config: 5", ZOD + ["evaluate", str(i / "badkw"), *FAST],
         check=refused_with("not a mapping"))
    # 4. the API refuses what the CLI refuses
    R.snippet("63.4a", "zodrive.evaluate(RecurrentPPO(...)) (a raw RuntimeError)", api("""
        from sb3_contrib import RecurrentPPO
        zodrive.evaluate(RecurrentPPO("MlpLstmPolicy", "CartPole-v1", n_steps=32, device="cpu"), env_id="CartPole-v1")
        """), expect="refuse", check=refused_with("recurrent"))
    R.snippet("63.4b", "RecurrentPPO with lstm_hidden_size=25 (returned a wrong Result)", api("""
        from sb3_contrib import RecurrentPPO
        m = RecurrentPPO("MlpLstmPolicy", "CartPole-v1", n_steps=32, device="cpu", policy_kwargs={"lstm_hidden_size": 25})
        print(zodrive.evaluate(m, env_id="CartPole-v1", episodes=1))
        """), expect="refuse", check=refused_with("recurrent"))
    R.snippet("63.4c", "a frame-stacked PPO: refused for its stacking", api("""
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack
        m = PPO("MlpPolicy", VecFrameStack(DummyVecEnv([lambda: gym.make("CartPole-v1")]), 4), n_steps=32, device="cpu")
        zodrive.evaluate(m, env_id="CartPole-v1", episodes=1)
        """), expect="refuse", check=refused_with("stacked frames"))
    R.ex("63.4d", "a parking-v0 SAC (Dict observation): was 'its observation_space is damaged'",
         ZOD + ["evaluate", str(i / "parking" / "sac.zip"), "--preset", "highway-fast", *FAST],
         check=refused_with("observes a Dict"))
    # 5. recorded values are what ran
    R.ex("63.5a", "--eps 5 (recorded eps=5.0 while 2 ran)", ZOD + ["evaluate", "baseline:rules", *hf, "--attack",
         "random-search", "--eps", "5", *FAST], check=refused_with("more than any observation value can move"))
    R.ex("63.5b", "eps on an unnormalized observation says what it moves",
         ZOD + ["evaluate", str(i / "raw"), "--attack", "random-search", "--eps", "0.05", "--steps", "2", *FAST],
         expect="either", line_from="grep:eps=0.05", check=printed("up to 0.05 m on positions"))
    # 6. the leaderboard
    R.ex("63.6a", "`zodrive leaderboard` with no --out (rewrote the checkout's docs/leaderboard.md)",
         ZOD + ["leaderboard"], check=refused_with("--out"))
    R.ex("63.6b", "leaderboard --out over a file zodrive did not write", ZOD + ["leaderboard", "--board", str(REPO / "results" / "bench"),
                                                                    "--out", "notes.md"],
         setup=lambda cwd: (cwd / "notes.md").write_text("mine\n"), check=refused_with("--force"))
    R.ex("63.6c", "a 20-episode-style unofficial row: its own table, unranked, never bold",
         ZOD + ["bench", "baseline:rules", "--scenario", "highway-fast", "--episodes", "1", "--board", "b",
                "--no-progress"], expect="run", timeout=600, line_from="grep:^bench:",
         check=lambda r, cwd: None if "Unofficial rows of highway-fast" in (cwd / "b" / "leaderboard.md").read_text()
         and "**" not in (cwd / "b" / "leaderboard.md").read_text().split("Unofficial rows")[1]
         else ("WRONG", "not in a table apart"))
    # 8. smaller things
    R.ex("63.8a", "--patience help (said 'default: none' while zo-signsgd runs with 10)", ZOD + ["evaluate", "--help"],
         expect="run", line_from="grep:10 in the", env={"COLUMNS": "200"},
         check=printed("10 in the random-search-fallback, zo-signsgd configs"))
    R.ex("63.8b", "a mistyped attack", ZOD + ["evaluate", "baseline:rules", *hf, "--attack", "zo-signsdg", *FAST],
         check=refused_with("did you mean 'zo-signsgd'"))
    R.ex("63.8c", "a mistyped preset", ZOD + ["evaluate", "baseline:rules", "--preset", "higway-fast", *FAST],
         check=refused_with("did you mean 'highway-fast'"))
    R.ex("63.8d", "baseline:rules under zo-signsgd: says it shows only decisions",
         ZOD + ["evaluate", "baseline:rules", *hf, "--attack", "zo-signsgd", "--eps", "0.05", "--steps", "2", *FAST],
         expect="run", line_from="grep:decision alone", check=printed("lower bound"))
    # 9. the input trial's categories
    for name, row in (("empty", {}), ("list", []), ("episodes-many", "many")):
        def setup(cwd: Path, row=row) -> None:
            good = json.loads((REPO / "results/bench/highway-fast/baseline-slower/row.json").read_text())
            data = {**good, "episodes": row} if row == "many" else row
            (cwd / "b" / "highway-fast" / "x").mkdir(parents=True)
            (cwd / "b" / "highway-fast" / "x" / "row.json").write_text(json.dumps(data))
        R.ex(f"63.9a-{name}", f"leaderboard over a row.json of the wrong shape ({name})",
             ZOD + ["leaderboard", "--board", "b", "--out", "l.md"], setup=setup, check=refused_with("not a bench row"))

    def fifo(cwd: Path) -> None:
        (cwd / "b" / "highway-fast" / "x").mkdir(parents=True)
        os.mkfifo(cwd / "b" / "highway-fast" / "x" / "row.json")
    R.ex("63.9b", "a row.json that is a FIFO (hung)", ZOD + ["leaderboard", "--board", "b", "--out", "l.md"],
         setup=fifo, timeout=30, check=refused_with("not a regular file"))

    def zero(cwd: Path) -> None:
        (cwd / "b" / "highway-fast" / "x").mkdir(parents=True)
        os.symlink("/dev/zero", cwd / "b" / "highway-fast" / "x" / "row.json")
    R.ex("63.9c", "a row.json linked to /dev/zero (MemoryError)", ZOD + ["leaderboard", "--board", "b", "--out", "l.md"],
         setup=zero, timeout=30, check=refused_with("not a regular file"))
    R.snippet("63.9d", "a vecnormalize.pkl of numpy names asking for a 93 GiB array", api(f"""
        import pickle, shutil
        from pathlib import Path
        class Huge:
            def __reduce__(self):
                return (np._core.multiarray._reconstruct, (np.ndarray, (93 * 2**30 // 8,), np.dtype("f8")))
        d = Path("vn"); d.mkdir(); shutil.copy({str(i / 'vecnorm' / 'model.zip')!r}, d / "model.zip")
        (d / "vecnormalize.pkl").write_bytes(pickle.dumps(Huge()))
        zodrive.evaluate(str(d), env_id="CartPole-v1", episodes=1)
        """), expect="refuse", check=refused_with("is not part of a VecNormalize file"))
    for key, bad, words in (("episodes", "10**12", "must be an integer"), ("seed", "-1", "must be an integer")):
        R.snippet(f"63.9e-{key}", f"zodrive.evaluate(..., {key}={bad})", api(f"""
            zodrive.evaluate("baseline:slower", "highway-fast", {key}={bad})
            """), expect="refuse", check=refused_with(words))
    R.snippet("63.9f", "AttackWrapper(None, ...)", api("""
        zodrive.AttackWrapper(None, "baseline:rules")
        """), expect="refuse", check=refused_with("wraps a gymnasium environment"))
    for what, argv in (("certify", ["certify", str(i / "vecnorm"), "--env-id", "CartPole-v1", "--eps", "0.01",
                                    "--episodes", "1"]),
                       ("export", ["export", str(i / "vecnorm"), "--out", "m.onnx"])):
        R.ex(f"63.9g-{what}", f"{what} on a VecNormalize model (worked on the raw network)", ZOD + argv,
             check=refused_with("normalized by"))
    for bad in ("", "a|b"):
        R.ex(f"63.9h-{bad or 'empty'}", f"bench --name {bad!r}", ZOD + ["bench", "baseline:slower", "--scenario",
             "highway-fast", "--name", bad, "--board", "b"], check=refused_with("one folder name"))
    R.snippet("63.9i", "evaluate(model, {'foo': 1}) (ran a preset called None)", api("""
        zodrive.evaluate("baseline:slower", {"foo": 1})
        """), expect="refuse", check=refused_with("needs a 'name'"))
    R.snippet("63.9j", "trust_model=True on a baseline (the CLI refuses)", api("""
        zodrive.evaluate("baseline:slower", "highway-fast", trust_model=True)
        """), expect="refuse", check=refused_with("trust_model applies"))
    R.ex("63.9k", "--backend ray with an address Ray cannot use (a traceback)",
         ZOD + ["compare", "baseline:slower", "--preset", "highway-fast", "--attacks", "random-search", "--eps", "0.05",
                "--episodes", "1", "--out", "c", "--backend", "ray", "--address", "nonsense", "--no-progress"],
         timeout=120, check=refused_with("did not start"))
    R.ex("63.9l", "--obs-bounds on CartPole (refused: it covered the declared x and angle)",
         ZOD + ["evaluate", str(i / "vecnorm"), "--env-id", "CartPole-v1", "--obs-bounds=-5,5", *FAST],
         expect="either", check=lambda r, cwd: None if "obs_bounds" not in r.err else ("WRONG", r.err.strip()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="id prefixes to run (e.g. 63.3 63.9)")
    parser.add_argument("--md", default=str(R.HERE / "issue63.md"))
    args = parser.parse_args()
    R.ONLY = args.only
    started = time.monotonic()
    R.ROOT = Path(tempfile.mkdtemp(prefix="zodrive-63-"))
    R.INP = R.ROOT / "in"
    R.INP.mkdir(parents=True)
    try:
        R.crafted_zip(R.INP / "zip-n-huge" / "model.zip", lambda d: d["action_space"].update(n=10**30))
        built = R.run([PY, "-c", BUILD, str(R.INP)], R.INP, 600)
        assert built.rc == 0, built.err[-2000:]
        issue63()
    finally:
        R.write_md(Path(args.md), started)
        text = Path(args.md).read_text().replace("# Issues 46 and 47: every example re-run", "# Issue 63: every "
                                                 "example re-run").replace("studies/input-trial/rerun.py",
                                                                           "studies/input-trial/issue63.py")
        Path(args.md).write_text(text)
        shutil.rmtree(R.ROOT, ignore_errors=True)
        print(f"wrote {args.md}")


if __name__ == "__main__":
    main()
