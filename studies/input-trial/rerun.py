"""Re-run every concrete example of issues 47 and 46 as a user would type it, and write rerun.md.

Each example runs the installed `zodrive` CLI (or `python -c SNIPPET` where the example is a
Python call) through `subprocess`, with a timeout, `OMP_NUM_THREADS=1`, one at a time, in its own
folder under one fresh temporary folder. The hostile inputs (YAML bombs, non-UTF-8 files, crafted
model zips, damaged run folders, policy files, tiny models trained in a few hundred steps) are built
here, in that folder. Nothing in the checkout is written but `studies/input-trial/rerun.md`.

    . .venv/bin/activate && python studies/input-trial/rerun.py            # all (about 10-15 min)
    python studies/input-trial/rerun.py --only 47.T 46.4 --keep             # a subset; keep the temp folder

Verdicts: `refused in one line` (exit 2, one stderr line, no traceback); `runs` (exit 0 on a valid
input, and the record checked where the example is about a record); `TRACEBACK`; `SILENT` (exit 0
on an input that should be refused); `WRONG` (exit 0 but a record or number is wrong); and, where
the example is neither, `REFUSED (valid input)`, `refused in N lines` (an error after other output),
`exit N`, `TIMEOUT`, `skipped`, and for the newcomer items that are text, `text ok` / `TEXT WRONG`.
"""

from __future__ import annotations

import argparse
import base64
import datetime
import io
import json
import os
import pickle
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
PY = sys.executable
ZOD = [str(Path(PY).parent / "zodrive")] if (Path(PY).parent / "zodrive").exists() else ["zodrive"]
FAST = ["--episodes", "1", "--env-set", "max_episode_steps=5", "--no-progress"]
HF = ["--preset", "highway-fast"]
BAD = {"TRACEBACK", "SILENT", "WRONG", "TIMEOUT", "TEXT WRONG", "REFUSED (valid input)"}


@dataclass
class Res:
    rc: int | None
    out: str
    err: str
    secs: float
    timeout: bool = False


@dataclass
class Row:
    id: str
    example: str
    command: str
    rc: str
    line: str
    verdict: str
    note: str = ""
    secs: float = 0.0


ROOT: Path = Path()
INP: Path = Path()
ROWS: list[Row] = []
ONLY: list[str] | None = None


def want(id_: str) -> bool:
    return ONLY is None or any(id_.startswith(p) for p in ONLY)


def env_for(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env.update({"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "COLUMNS": "100", "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"})
    env.pop("ZODRIVE_CONFIGS", None)
    env.pop("ZODRIVE_MODELS", None)
    env.update(extra or {})
    return env


def run(argv: list[str], cwd: Path, timeout: float = 90, env: dict[str, str] | None = None) -> Res:
    t0 = time.monotonic()
    try:
        p = subprocess.run(argv, cwd=cwd, env=env_for(env), capture_output=True, text=True,
                           errors="replace", timeout=timeout, stdin=subprocess.DEVNULL, check=False)
        return Res(p.returncode, p.stdout, p.stderr, time.monotonic() - t0)
    except subprocess.TimeoutExpired as exc:
        def s(x: object) -> str:
            return x.decode(errors="replace") if isinstance(x, bytes) else (x or "")  # type: ignore[return-value]
        return Res(None, s(exc.stdout), s(exc.stderr), time.monotonic() - t0, timeout=True)


def lines(text: str) -> list[str]:
    # tqdm redraws with \r: count each redraw once, as a terminal would show it
    return [ln.split("\r")[-1].strip() for ln in text.splitlines() if ln.split("\r")[-1].strip()]


def last(text: str) -> str:
    ls = lines(text)
    return ls[-1] if ls else ""


def classify(r: Res, expect: str) -> str:
    """expect: 'refuse', 'run' or 'either' (a refusal or a run are both right)."""
    if r.timeout:
        return "TIMEOUT"
    if "Traceback (most recent call last)" in r.err or "Traceback (most recent call last)" in r.out:
        return "TRACEBACK"
    n = len(lines(r.err))
    if r.rc == 0:
        return "SILENT" if expect == "refuse" else "runs"
    if r.rc == 2 and n == 1:
        return "REFUSED (valid input)" if expect == "run" else "refused in one line"
    if expect == "run":
        return "REFUSED (valid input)"
    if r.rc == 2:
        return f"refused in {n} lines"
    return f"exit {r.rc}"


def show(argv: list[str] | str) -> str:
    text = argv if isinstance(argv, str) else shlex.join(argv)
    text = text.replace(ZOD[0], "zodrive").replace(PY, "python")
    text = text.replace(str(INP), "$IN").replace(str(ROOT), "$TMP").replace(str(REPO), "$REPO")
    return text


def fresh(name: str) -> Path:
    d = ROOT / "runs" / re.sub(r"[^A-Za-z0-9_.-]", "_", name)
    if d.exists():
        shutil.rmtree(d)
    d.mkdir(parents=True)
    return d


def record(id_: str, example: str, command: str, r: Res | None, verdict: str, note: str = "",
           line: str | None = None) -> Row:
    if not want(id_):
        return None  # type: ignore[return-value]
    if r is not None and "Traceback (most recent call last)" in r.err:
        exc = [ln for ln in lines(r.err) if re.match(r"^[\w.]+(Error|Exception|Exit)\b", ln)]
        line = exc[-1] if exc else last(r.err)
    if line is None and r is not None:
        line = last(r.err) or last(r.out)
    row = Row(id_, example, show(command), "–" if r is None else ("timeout" if r.timeout else str(r.rc)),
              show(line or "")[:300], verdict, show(note), 0.0 if r is None else r.secs)
    ROWS.append(row)
    print(f"[{row.id}] {row.verdict:22s} rc={row.rc:7s} {row.secs:5.1f}s  {example}\n      {row.line[:160]}",
          flush=True)
    if note:
        print(f"      note: {note[:200]}", flush=True)
    return row


Check = Callable[[Res, Path], "tuple[str, str] | None"]


def ex(id_: str, example: str, argv: list[str], expect: str = "refuse", *, check: Check | None = None,
       setup: Callable[[Path], None] | None = None, timeout: float = 90, env: dict[str, str] | None = None,
       line_from: str = "err") -> Row:
    """Run one CLI example in a fresh folder; `check(res, cwd)` may return (verdict, note)."""
    if not want(id_):
        return None  # type: ignore[return-value]
    cwd = fresh(id_)
    if setup:
        setup(cwd)
    r = run(argv, cwd, timeout, env)
    verdict, note = classify(r, expect), ""
    if check and not r.timeout and verdict not in ("TRACEBACK",):
        got = check(r, cwd)
        if got:
            verdict, note = got
    line = (last(r.err) or last(r.out)) if line_from == "err" else (last(r.out) or last(r.err))
    if line_from.startswith("grep:"):
        pat = re.compile(line_from[5:])
        hits = [ln for ln in lines(r.out) + lines(r.err) if pat.search(ln)]
        line = hits[0] if hits else (last(r.err) or last(r.out))
    envs = " ".join(f"{k}={v}" for k, v in (env or {}).items())
    return record(id_, example, (envs + " " if envs else "") + shlex.join(argv), r, verdict, note, line)


def snippet(id_: str, example: str, code: str, expect: str = "run", *, check: Check | None = None,
            timeout: float = 120, shown: str | None = None) -> Row:
    if not want(id_):
        return None  # type: ignore[return-value]
    cwd = fresh(id_)
    (cwd / "snippet.py").write_text(code)
    r = run([PY, "snippet.py"], cwd, timeout)
    verdict, note = classify(r, expect), ""
    if check and not r.timeout and verdict != "TRACEBACK":
        got = check(r, cwd)
        if got:
            verdict, note = got
    line = last(r.err) if r.rc else (last(r.out) or last(r.err))
    return record(id_, example, shown or f"python snippet.py  # {example}", r, verdict, note, line)


def textcheck(id_: str, example: str, what: str, ok: bool, line: str, note: str = "") -> Row:
    return record(id_, example, what, None, "text ok" if ok else "TEXT WRONG", note, line)


# ---------------------------------------------------------------------------------------------
# inputs


BOMB = textwrap.dedent("""\
    a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
    b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
    c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
    d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
    e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
    f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
    g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
    h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
    i: &i [*h,*h,*h,*h,*h,*h,*h,*h,*h]
    """)


def policy_files() -> None:
    """Policy files `FILE.py:make` (numpy callables) for the user-policy examples."""
    head = "import numpy as np\n"
    files = {
        # scores of the 5 meta-actions from a fixed random linear map (so an attack has work to do)
        "x.py": head + textwrap.dedent("""\
            def make():
                w = np.random.default_rng(0).normal(size=(25, 5))
                return lambda obs: np.asarray(obs, np.float32).reshape(len(obs), -1) @ w
            """),
        "raise4.py": head + textwrap.dedent("""\
            def make():
                calls = [0]
                w = np.random.default_rng(0).normal(size=(25, 5))
                def f(obs):
                    calls[0] += 1
                    if calls[0] == 4:
                        raise RuntimeError("policy broke on call 4")
                    return np.asarray(obs, np.float32).reshape(len(obs), -1) @ w
                return f
            """),
        "nan.py": head + "def make():\n    return lambda obs: np.full((len(obs), 5), np.nan)\n",
        "batchshape.py": head + "def make():\n    return lambda obs: np.zeros((len(obs), 5 if len(obs) == 1 else 4))\n",
        "exit0.py": "import sys\nsys.exit(0)\ndef make():\n    return None\n",
        "faster.py": head + "def make():\n    return lambda obs: np.tile([0.0, 0.0, 0.0, 1.0, 0.0], (len(obs), 1))\n",
        # a Pendulum policy that reads its observation and logs the largest |cos|, |sin| and |speed| it is queried on
        "pendlog.py": head + textwrap.dedent("""\
            import os
            def make():
                log = os.environ["ROWLOG"]
                def f(obs):
                    obs = np.asarray(obs, np.float64).reshape(len(obs), -1)
                    with open(log, "a") as fh:
                        fh.write(f"{np.abs(obs[:, :2]).max()} {np.abs(obs[:, 2]).max()}\\n")
                    return np.clip(obs[:, 0:1] + 0.25 * obs[:, 2:3], -2, 2).astype(np.float32)
                return f
            """),
        "actions.py": head + "def make():\n    return lambda obs: np.full(len(obs), 4)  # always SLOWER, as actions\n",
        "cart.py": head + "def make():\n    return lambda obs: np.zeros((len(obs), 2))\n",
        "steer.py": head + "def make():\n    return lambda obs: np.zeros((len(obs), 1), np.float32)\n",
        # a victim that logs how many rows it receives, to the file named by $ROWLOG
        "logger.py": head + textwrap.dedent("""\
            import os
            def make():
                w = np.random.default_rng(0).normal(size=(25, 5))
                log = os.environ["ROWLOG"]
                def f(obs):
                    with open(log, "a") as fh:
                        fh.write(f"{len(obs)}\\n")
                    return np.asarray(obs, np.float32).reshape(len(obs), -1) @ w
                return f
            """),
    }
    for name, text in files.items():
        (INP / name).write_text(text)


def crafted_zip(dst: Path, edit_data: Callable[[dict], None] | None = None, pth: bytes | None = None,
                serialized_payload: bytes | None = None) -> Path:
    """A copy of models/dqn/model.zip with its `data` JSON edited and/or `policy.pth` replaced."""
    src = REPO / "models" / "dqn" / "model.zip"
    dst.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            blob = zin.read(item.filename)
            if item.filename == "data" and (edit_data or serialized_payload):
                data = json.loads(blob)
                if edit_data:
                    edit_data(data)
                if serialized_payload:
                    b64 = base64.b64encode(serialized_payload).decode()
                    data["observation_space"][":serialized:"] = b64
                    data["action_space"][":serialized:"] = b64
                blob = json.dumps(data).encode()
            if item.filename == "policy.pth" and pth is not None:
                blob = pth
            zout.writestr(item, blob)
    return dst


class Marker:
    """A pickle that creates a file when it is unpickled (what a stranger's file could run)."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (os.system, (f"touch {shlex.quote(self.path)}",))


def torch_bytes(obj: object) -> bytes:
    import torch
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def build_inputs() -> None:
    INP.mkdir(parents=True)
    shutil.copytree(REPO / "models" / "dqn", INP / "dqn")
    (INP / "bomb.yaml").write_text(BOMB)
    (INP / "recursive.yaml").write_text("attack: random-search\nsteps: &a [1, *a]\n")
    (INP / "recursive-preset.yaml").write_text("env_id: &a [*a]\n")
    (INP / "dup.yaml").write_text("attack: random-search\nsteps: 3\nsteps: 4\n")
    preset = (REPO / "configs" / "presets" / "highway-fast.yaml").read_bytes()
    (INP / "latin1-preset.yaml").write_bytes(preset + b"# caf\xe9 \xff\xfe\n")
    (INP / "latin1-attack.yaml").write_bytes(b"attack: random-search  # caf\xe9 \xff\n")
    policy_files()

    import torch
    sd = {k: v for k, v in torch.load(io.BytesIO(zipfile.ZipFile(REPO / "models/dqn/model.zip").read("policy.pth")),
                                       weights_only=True).items()}

    def shape_text(d: dict) -> None:
        d["observation_space"]["_shape"] = ["five", 5]

    def shape_null(d: dict) -> None:
        d["observation_space"]["_shape"] = None

    def arch_text(d: dict) -> None:
        d["policy_kwargs"]["net_arch"] = ["wide", 256]

    def arch_null(d: dict) -> None:
        d["policy_kwargs"] = None

    def arch_neg(d: dict) -> None:
        d["policy_kwargs"]["net_arch"] = [-1]

    def n_text(d: dict) -> None:
        d["action_space"]["n"] = "five"

    crafted_zip(INP / "zip-shape-text" / "model.zip", shape_text)
    crafted_zip(INP / "zip-shape-null" / "model.zip", shape_null)
    crafted_zip(INP / "zip-arch-text" / "model.zip", arch_text)
    crafted_zip(INP / "zip-kwargs-null" / "model.zip", arch_null)
    crafted_zip(INP / "zip-arch-neg" / "model.zip", arch_neg)
    crafted_zip(INP / "zip-n-text" / "model.zip", n_text)
    crafted_zip(INP / "zip-pth-empty" / "model.zip", pth=torch_bytes({}))
    crafted_zip(INP / "zip-pth-strings" / "model.zip", pth=torch_bytes({k: "tensor" for k in sd}))
    # a model zip whose serialized spaces would create a marker file if SB3's loader read it
    crafted_zip(INP / "stranger" / "models" / "dqn" / "model.zip",
                serialized_payload=pickle.dumps(Marker(ROOT / "MARKER-sha256sums")))


def train_dqn_run(out: Path, steps: int, every: int, extra: list[str] | None = None) -> Res:
    return run(ZOD + ["train", "--algo", "dqn", "--steps", str(steps), "--set", f"checkpoint_every={every}",
                      "--set", "hyperparameters.learning_starts=50", "--env-set", "max_episode_steps=20",
                      "--out", str(out), "--no-progress"] + (extra or []), out.parent, 120)


TRAIN_SB3 = textwrap.dedent("""\
    import sys, shutil, pathlib
    import gymnasium as gym
    import highway_env  # noqa: F401
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    out = pathlib.Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    # a plain PPO on highway-fast (a few hundred steps: a toy)
    for name in ("ppo", "sac", "cnn"):
        (out / name).mkdir(exist_ok=True)
    PPO("MlpPolicy", gym.make("highway-fast-v0"), n_steps=64, batch_size=32, n_epochs=1, seed=0).learn(128).save(out / "ppo" / "ppo.zip")
    # a PPO trained inside VecNormalize
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("highway-fast-v0")]))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=32, n_epochs=1, seed=0).learn(192)
    (out / "vecnorm").mkdir(exist_ok=True)
    model.save(out / "vecnorm" / "model.zip")
    venv.save(str(out / "vecnorm" / "vecnormalize.pkl"))
    # a SAC on highway-fast with continuous actions
    env = gym.make("highway-fast-v0", config={"action": {"type": "ContinuousAction"}})
    SAC("MlpPolicy", env, learning_starts=32, buffer_size=1000, seed=0).learn(64).save(out / "sac" / "sac.zip")
    # a CnnPolicy PPO on GrayscaleObservation
    cfg = {"observation": {"type": "GrayscaleObservation", "observation_shape": (64, 64), "stack_size": 4,
                           "weights": [0.2989, 0.5870, 0.1140], "scaling": 1.75}}
    PPO("CnnPolicy", gym.make("highway-fast-v0", config=cfg), n_steps=16, batch_size=16, n_epochs=1,
        seed=0).learn(16).save(out / "cnn" / "cnn.zip")
    print("trained")
    """)

OWN_LOOP = textwrap.dedent("""\
    # the user's own evaluation loop: SB3's PPO with the VecNormalize statistics applied
    import json, sys
    import gymnasium as gym, numpy as np
    import highway_env  # noqa: F401
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    zip_, stats, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    model = PPO.load(zip_, device="cpu")
    norm = VecNormalize.load(stats, DummyVecEnv([lambda: gym.make("highway-fast-v0")]))
    norm.training = False
    returns = []
    for i in range(n):
        env = gym.make("highway-fast-v0")
        obs, _ = env.reset(seed=100000 + i)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(norm.normalize_obs(obs[None]), deterministic=True)
            obs, r, term, trunc, _ = env.step(int(action[0]))
            total += r
            done = term or trunc
        returns.append(total)
    print(json.dumps(returns))
    """)


def episode_returns(folder: Path) -> list[float]:
    eps = [json.loads(ln) for ln in (folder / "episodes.jsonl").read_text().splitlines() if ln.strip()]
    eps.sort(key=lambda e: e["episode"])
    key = next(k for k in ("return", "episode_return", "total_reward", "reward") if k in eps[0])
    return [float(e[key]) for e in eps]


# ---------------------------------------------------------------------------------------------
# issue 47


def issue47() -> None:
    dqn = str(INP / "dqn" / "model.zip")
    ev = ZOD + ["evaluate"]
    bomb, rec = str(INP / "bomb.yaml"), str(INP / "recursive.yaml")

    # --- Measured: tracebacks -------------------------------------------------------------
    ex("47.T1", "billion-laughs YAML as --preset", ev + ["baseline:slower", "--preset", bomb] + FAST, timeout=60)
    ex("47.T2", "billion-laughs YAML as --attack file", ev + ["baseline:slower", *HF, "--attack", bomb] + FAST,
       timeout=60)
    ex("47.T3", "--episodes 1000000000000", ev + ["baseline:slower", *HF, "--episodes", "1000000000000",
                                                  "--no-progress"])
    ex("47.T4", "--n-directions 10000000000 (hand-checked)",
       ev + [dqn, "--attack", "zo-signsgd", "--n-directions", "10000000000"] + FAST)
    ex("47.T5", "train --set hyperparameters.buffer_size=10000000000",
       ZOD + ["train", "--algo", "dqn", "--steps", "100", "--set", "hyperparameters.buffer_size=10000000000",
              "--out", "run", "--no-progress"])
    ex("47.T6", "--query-budget 10**30 (hand-checked)",
       ev + [dqn, "--attack", "random-search", "--query-budget", str(10**30)] + FAST)
    ex("47.T7", "--env-set highway.duration=.inf", ev + ["baseline:slower", *HF, "--env-set", "highway.duration=.inf",
                                                         "--episodes", "1", "--no-progress"], timeout=60)
    ex("47.T8", "non-UTF-8 bytes in a preset", ev + ["baseline:slower", "--preset", str(INP / "latin1-preset.yaml")]
       + FAST)
    ex("47.T9", "non-UTF-8 bytes in an attack file",
       ev + ["baseline:slower", *HF, "--attack", str(INP / "latin1-attack.yaml")] + FAST)

    def monitor_latin1(cwd: Path) -> None:
        shutil.copytree(INP / "run300", cwd / "run")
        with open(cwd / "run" / "monitor.monitor.csv", "ab") as fh:
            fh.write(b"1.0,5,caf\xe9\xff\n")
    ex("47.T10", "non-UTF-8 bytes in a monitor CSV (curves)", ZOD + ["curves", "run"], setup=monitor_latin1)

    zips = [("47.T11", "crafted zip: text for the observation shape", "zip-shape-text"),
            ("47.T12", "crafted zip: null observation shape", "zip-shape-null"),
            ("47.T13", "crafted zip: text in net_arch", "zip-arch-text"),
            ("47.T14", "crafted zip: policy_kwargs null", "zip-kwargs-null"),
            ("47.T15", "crafted zip: action_space n is text", "zip-n-text"),
            ("47.T16", "crafted zip: policy.pth with no layers", "zip-pth-empty"),
            ("47.T17", "crafted zip: policy.pth with strings for tensors", "zip-pth-strings"),
            ("47.T18", "crafted zip: net_arch [-1]", "zip-arch-neg")]
    reference = run(ev + [dqn, "--preset", "discrete"] + FAST, ROOT)
    ref_line = next((ln for ln in lines(reference.out) if ln.startswith("mean return")), "?")

    def weights_decide(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        got = next((ln for ln in lines(r.out) if ln.startswith("mean return")), "")
        if got == ref_line:
            return "runs", ("net_arch is not read: the network is rebuilt from policy.pth's shapes, and it gives the "
                            f"unedited zip's numbers ({got})")
        return "WRONG", f"{got} vs the unedited zip's {ref_line}"
    for id_, what, name in zips:
        edits_arch = name in ("zip-arch-text", "zip-arch-neg")
        ex(id_, what, ev + [str(INP / name / "model.zip"), "--preset", "discrete"] + FAST,
           "either" if edits_arch else "refuse", check=weights_decide if edits_arch else None)

    def evaluated(cwd: Path, episodes: int = 1) -> None:
        r = run(ev + ["baseline:slower", *HF, "--episodes", str(episodes), "--env-set", "max_episode_steps=5",
                      "--out", "o", "--no-progress"], cwd)
        assert r.rc == 0, r.err

    def eval_key_not_json(cwd: Path) -> None:
        evaluated(cwd)
        (cwd / "o" / "eval_key.json").write_text("not json {")
    again = ev + ["baseline:slower", *HF, "--episodes", "2", "--env-set", "max_episode_steps=5", "--out", "o",
                  "--no-progress"]
    ex("47.T19", "damaged --out: eval_key.json not JSON", again, setup=eval_key_not_json)

    def summary_truncated(cwd: Path) -> None:
        evaluated(cwd)
        s = (cwd / "o" / "summary.json").read_text()
        (cwd / "o" / "summary.json").write_text(s[: len(s) // 2])
    ex("47.T20", "damaged --out: truncated summary.json (resume)", again, "either", setup=summary_truncated)

    def card_summary_truncated(cwd: Path) -> None:
        shutil.copytree(INP / "dqn", cwd / "dqn")
        s = (cwd / "dqn" / "eval" / "summary.json").read_text()
        (cwd / "dqn" / "eval" / "summary.json").write_text(s[: len(s) // 2])
    ex("47.T21", "card on a truncated eval/summary.json", ZOD + ["card", "dqn", "--force"], setup=card_summary_truncated)

    def episode_key_missing(cwd: Path) -> None:
        evaluated(cwd, 2)
        p = cwd / "o" / "episodes.jsonl"
        rows = [json.loads(ln) for ln in p.read_text().splitlines() if ln.strip()]
        rows[0].pop("episode", None)
        p.write_text("".join(json.dumps(r) + "\n" for r in rows))
    ex("47.T22", "damaged --out: episodes.jsonl line without `episode`",
       ev + ["baseline:slower", *HF, "--episodes", "3", "--env-set", "max_episode_steps=5", "--out", "o",
             "--no-progress"], setup=episode_key_missing)

    def run_json_broken(cwd: Path) -> None:
        shutil.copytree(INP / "dqn", cwd / "dqn")
        (cwd / "dqn" / "run.json").write_text('{"algo": "dqn", ')
    ex("47.T23", "card on a broken run.json", ZOD + ["card", "dqn", "--force"], setup=run_json_broken)

    ex("47.T24", "--env-set highway.observation.features_range.x=[0]",
       ev + ["baseline:slower", *HF, "--env-set", "highway.observation.features_range.x=[0]"] + FAST)
    ex("47.T25", "--env-set highway.reward_speed_range=[1]",
       ev + ["baseline:slower", *HF, "--env-set", "highway.reward_speed_range=[1]"] + FAST)
    ex("47.T26", "recursive YAML alias in an attack file", ev + ["baseline:slower", *HF, "--attack", rec] + FAST)
    ex("47.T27", "recursive YAML alias in a preset",
       ev + ["baseline:slower", "--preset", str(INP / "recursive-preset.yaml")] + FAST)
    ex("47.T28", "--defense kinematic with --env-id CartPole-v1",
       ev + [f"{INP}/cart.py:make", "--env-id", "CartPole-v1", "--defense", "kinematic", "--episodes", "1",
             "--no-progress"])
    ex("47.T29", "ZODRIVE_CONFIGS=/nonexistent", ev + ["baseline:slower", *HF] + FAST,
       env={"ZODRIVE_CONFIGS": "/nonexistent"})
    ex("47.T30", "train --set hyperparameters.policy_kwargs.net_arch=[-1]",
       ZOD + ["train", "--algo", "dqn", "--steps", "100", "--set", "hyperparameters.policy_kwargs.net_arch=[-1]",
              "--out", "run", "--no-progress"])
    ex("47.T31", "a user policy that raises on its 4th call", ev + [f"{INP}/raise4.py:make", *HF] + FAST)

    # --- Measured: silent runs ----------------------------------------------------------------
    ex("47.S1", "--attack pgd --n-directions 5 (hand-checked)", ev + [dqn, "--attack", "pgd", "--n-directions", "5"]
       + FAST)
    ex("47.S2", "--attack pgd --mu 0.01", ev + [dqn, "--attack", "pgd", "--mu", "0.01"] + FAST)
    ex("47.S3", "compare --address without --backend ray",
       ZOD + ["compare", "baseline:slower", *HF, "--attacks", "uniform-noise", "--eps", "0.05", "--episodes", "1",
              "--env-set", "max_episode_steps=5", "--address", "127.0.0.1:6379", "--out", "cmp", "--no-progress"])
    ex("47.S4", "--defense kinematic on a constant baseline",
       ev + ["baseline:slower", *HF, "--defense", "kinematic"] + FAST)
    ex("47.S5", "--attack '' (empty name)", ev + [dqn, "--attack", ""] + FAST)
    ex("47.S6", "train --set total_timesteps=abc beside --steps",
       ZOD + ["train", "--algo", "dqn", "--steps", "100", "--set", "total_timesteps=abc", "--out", "run",
              "--no-progress"])
    ex("47.S7", "duplicate key in an attack YAML", ev + ["baseline:slower", *HF, "--attack", str(INP / "dup.yaml")]
       + FAST)
    ex("47.S8", "train --set checkpoint_every=-5",
       ZOD + ["train", "--algo", "dqn", "--steps", "100", "--set", "checkpoint_every=-5", "--out", "run",
              "--no-progress"])
    ex("47.S9", "--env-set highway.observation.features=[]",
       ev + ["baseline:slower", *HF, "--env-set", "highway.observation.features=[]"] + FAST)
    ex("47.S10", "--env-set highway.observation.features_range.vx=[1,1]",
       ev + ["baseline:slower", *HF, "--env-set", "highway.observation.features_range.vx=[1,1]"] + FAST)
    ex("47.S11", "a policy returning all-NaN scores", ev + [f"{INP}/nan.py:make", *HF] + FAST)
    ex("47.S12", "a policy whose output shape depends on the batch",
       ev + [f"{INP}/batchshape.py:make", *HF, "--attack", "random-search", "--eps", "0.05"] + FAST)
    ex("47.S13", "sys.exit(0) inside the user's policy file", ev + [f"{INP}/exit0.py:make", *HF] + FAST)

    # --- Measured: wrong records ------------------------------------------------------------------
    def longer_run(cwd: Path) -> None:
        shutil.copytree(INP / "run300", cwd / "run")

    def no_old_checkpoints(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        ck = sorted(p.name for p in (cwd / "run" / "checkpoints").glob("*.zip"))
        steps = [int(m.group(1)) for n in ck if (m := re.search(r"_(\d+)_steps", n))]
        old = [s for s in steps if s > 100]
        if old:
            return "WRONG", f"old checkpoints kept after --force: {ck}"
        return "runs", f"checkpoints now: {ck}"
    ex("47.W1", "train --force over a longer run (300 steps) leaves no old checkpoints (hand-checked)",
       ZOD + ["train", "--algo", "dqn", "--steps", "100", "--set", "checkpoint_every=50", "--set",
              "hyperparameters.learning_starts=50", "--env-set", "max_episode_steps=20", "--out", "run", "--force",
              "--no-progress"], "run", setup=longer_run, check=no_old_checkpoints, timeout=120)
    concurrent_evaluate()
    ex("47.W3", "--attack uniform-noise --steps 5 (hand-checked)", ev + [dqn, "--attack", "uniform-noise", "--steps", "5"]
       + FAST)
    ex("47.W4", "--attack fgsm --steps 50 (hand-checked)", ev + [dqn, "--attack", "fgsm", "--steps", "50"] + FAST)

    # --- Measured: overwrites without --force ---------------------------------------------------
    def unchanged(paths: list[str]) -> Check:
        def chk(r: Res, cwd: Path) -> tuple[str, str] | None:
            before = json.loads((cwd / ".before.json").read_text())
            changed = [p for p in paths if not (cwd / p).exists() or (cwd / p).read_bytes().hex() != before[p]]
            if changed:
                return ("WRONG" if r.rc == 0 else classify(r, "refuse") + " but WRONG"), f"changed: {changed}"
            return None
        return chk

    def snap(cwd: Path, paths: list[str]) -> None:
        (cwd / ".before.json").write_text(json.dumps({p: (cwd / p).read_bytes().hex() for p in paths}))

    def committed_eval(cwd: Path) -> None:
        shutil.copytree(REPO / "models" / "dqn" / "eval", cwd / "eval")
        snap(cwd, ["eval/summary.json"])
    ex("47.O1", "evaluate --out into a copy of committed models/dqn/eval",
       ev + [dqn, "--out", "eval"] + FAST, setup=committed_eval, check=unchanged(["eval/summary.json"]))

    mine = ["mine/episodes.jsonl", "mine/steps.jsonl", "mine/notes.txt"]

    def users_files(cwd: Path) -> None:
        (cwd / "mine").mkdir()
        (cwd / "mine" / "episodes.jsonl").write_text('{"my": "own data"}\n')
        (cwd / "mine" / "steps.jsonl").write_text('{"my": "steps"}\n')
        (cwd / "mine" / "notes.txt").write_text("my notes\n")
        snap(cwd, mine)
    ex("47.O2", "evaluate --out into a folder of the user's episodes.jsonl, steps.jsonl, notes.txt",
       ev + [dqn, "--out", "mine"] + FAST, setup=users_files, check=unchanged(mine))

    def grid_json(cwd: Path) -> None:
        (cwd / "g").mkdir()
        (cwd / "g" / "grid.json").write_text('{"cells": []}\n')
        snap(cwd, ["g/grid.json"])
    ex("47.O3", "evaluate --out into a folder with grid.json", ev + [dqn, "--out", "g"] + FAST, setup=grid_json,
       check=unchanged(["g/grid.json"]))

    def png(cwd: Path) -> None:
        from PIL import Image
        Image.new("RGB", (40, 30), "red").save(cwd / "plot.png")  # the user's own figure
        snap(cwd, ["plot.png"])
    ex("47.O4", "compare --plot over an existing PNG",
       ZOD + ["compare", "baseline:slower", *HF, "--attacks", "uniform-noise", "--eps", "0.05", "--episodes", "1",
              "--env-set", "max_episode_steps=5", "--out", "cmp", "--plot", "plot.png", "--no-progress"],
       setup=png, check=unchanged(["plot.png"]), line_from="out")

    def png_run(cwd: Path) -> None:
        png(cwd)
        shutil.copytree(INP / "run300", cwd / "run")
    ex("47.O5", "curves --plot over an existing PNG (the control: refused before the fix too)",
       ZOD + ["curves", "run", "--plot", "plot.png"], setup=png_run, check=unchanged(["plot.png"]))

    # --- Measured: valid inputs refused ---------------------------------------------------------
    def cells(n: int) -> Check:
        def chk(r: Res, cwd: Path) -> tuple[str, str] | None:
            if r.rc != 0:
                return None
            sums = sorted(str(p.parent.relative_to(cwd / "cmp")) for p in (cwd / "cmp").rglob("summary.json"))
            if len(sums) < n:
                return "WRONG", f"{len(sums)} cell summaries, {n} expected: {sums}"
            return "runs", f"{len(sums)} cells: {sums}"
        return chk
    ex("47.V1", "compare --eps 0.1 0.1000001 (two cells)",
       ZOD + ["compare", dqn, "--preset", "discrete", "--attacks", "uniform-noise", "--eps", "0.1", "0.1000001",
              "--episodes", "1", "--env-set", "max_episode_steps=5", "--out", "cmp", "--no-progress"], "run",
       check=cells(3), timeout=120)

    def two_models(cwd: Path) -> None:
        for name, src in (("a", REPO / "models/dqn/model.zip"), ("b", REPO / "models/dqn-robust/model.zip")):
            (cwd / name).mkdir()
            shutil.copy(src, cwd / name / "model.zip")
    ex("47.V2", "compare two different models both named model.zip",
       ZOD + ["compare", "a/model.zip", "b/model.zip", "--preset", "discrete", "--attacks", "uniform-noise", "--eps",
              "0.1", "--episodes", "1", "--env-set", "max_episode_steps=5", "--out", "cmp", "--no-progress"], "run",
       setup=two_models, check=cells(4), timeout=120)

    # --- Measured: refusals after work started -----------------------------------------------------
    ex("47.R1", "baseline:idm-mobil --defense kinematic (progress bars on: refused before any bar?)",
       ev + ["baseline:idm-mobil", *HF, "--defense", "kinematic", "--episodes", "1", "--env-set",
             "max_episode_steps=5"])
    ex("47.R2", "--eps 1e300 (hand-checked)", ev + [dqn, "--attack", "random-search", "--eps", "1e300"] + FAST)
    sigterm()


def concurrent_evaluate() -> None:
    if not want("47.W2"):
        return
    cwd = fresh("47.W2")
    argv = ZOD + ["evaluate", str(INP / "dqn" / "model.zip"), "--attack", "random-search", "--eps", "0.05",
                  "--steps", "20", "--episodes", "3", "--env-set", "max_episode_steps=20", "--out", "o",
                  "--no-progress"]
    t0 = time.monotonic()
    procs = [subprocess.Popen(argv, cwd=cwd, env=env_for(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    outs = [p.communicate(timeout=180) for p in procs]
    secs = time.monotonic() - t0
    rcs = [p.returncode for p in procs]
    errs = [e for _, e in outs]
    eps: list = []
    if (cwd / "o" / "episodes.jsonl").exists():
        eps = [json.loads(ln).get("episode") for ln in (cwd / "o" / "episodes.jsonl").read_text().splitlines()
               if ln.strip()]
    res = Res(max(rcs), "", "\n".join(errs), secs)
    if any("Traceback" in e for e in errs):
        verdict = "TRACEBACK"
    elif sorted(eps) != [0, 1, 2]:
        verdict = "WRONG"
    elif rcs == [0, 0] or sorted(rcs) == [0, 2]:
        verdict = "runs"
    else:
        verdict = f"exit {rcs}"
    line = " | ".join(last(e) or "(no stderr)" for e in errs)
    record("47.W2", "two identical evaluate runs into one --out at once", "2 x (" + shlex.join(argv) + ") &",
           res, verdict, f"exit codes {rcs}; episodes.jsonl episodes {eps}", line)


def sigterm() -> None:
    if not want("47.SIGTERM"):
        return
    cwd = fresh("47.SIGTERM")
    argv = ZOD + ["evaluate", str(INP / "dqn" / "model.zip"), "--episodes", "20", "--out", "o", "--no-progress"]
    t0 = time.monotonic()
    p = subprocess.Popen(argv, cwd=cwd, env=env_for(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(8)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    res = Res(p.returncode, out, err, time.monotonic() - t0)
    said = last(err) or last(out)
    verdict = "TRACEBACK" if "Traceback" in err else ("runs" if said else "SILENT")
    record("47.SIGTERM", "SIGTERM during evaluate --out (should say what was kept)", shlex.join(argv) + "; kill -TERM",
           res, verdict, f"exit {p.returncode}; a message is the fix", said or "(nothing printed)")


def newcomer() -> None:
    # N1: the README's PPO snippet, as written except for the training length
    readme = (REPO / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, re.DOTALL)
    ppo = next(b for b in blocks if "PPO(" in b)
    short = ppo.replace("learn(100_000)", "learn(64)").replace("n_steps=512", "n_steps=64")

    def saved(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc == 0 and not (cwd / "ppo.zip").exists():
            return "WRONG", "no ppo.zip written"
        if r.rc == 0:
            r2 = run(ZOD + ["evaluate", "ppo.zip", "--preset", "highway-fast"] + FAST, cwd)
            return classify(r2, "run"), (f"then `zodrive evaluate ppo.zip --preset highway-fast` (README step 1): "
                                         f"exit {r2.rc}: {last(r2.out)}")
        return None
    snippet("47.N1", "README's PPO snippet (learn(100_000) -> learn(64), n_steps 512 -> 64 for time)", short,
            check=saved, shown="python <README PPO block, learn(64)>")

    # N2: mkdocs build --strict
    if want("47.N2"):
        mkdocs_build()
    newcomer_rest(readme)


def mkdocs_build() -> None:
    cwd = fresh("47.N2")
    r = run([PY, "-m", "mkdocs", "build", "--strict", "-f", str(REPO / "mkdocs.yml"), "-d", str(cwd / "site")],
            REPO, 180)
    if r.rc is not None and r.rc != 0 and "No module named mkdocs" in r.err:
        record("47.N2", "mkdocs build --strict", "python -m mkdocs build --strict", r, "skipped", "mkdocs not installed")
    else:
        warns = [ln for ln in lines(r.err) if ln.startswith("WARNING")]
        record("47.N2", "mkdocs build --strict", "python -m mkdocs build --strict -d $TMP/site", r,
               classify(r, "run"), f"{len(warns)} warnings" + (f"; first: {warns[0]}" if warns else ""),
               warns[0] if warns and r.rc else last(r.err))
        site = cwd / "site"
        has_readme = (site / "readme" / "index.html").exists() or (site / "readme.html").exists()
        textcheck("47.N10a", "docs/: the README is part of the site", "ls $TMP/site/readme/", has_readme,
                  "site/readme/index.html " + ("exists" if has_readme else "missing"))


def newcomer_rest(readme: str) -> None:
    ci = (REPO / ".ci" / "run").read_text()
    pyproject = (REPO / "pyproject.toml").read_text()
    test_extra = re.search(r"^test\s*=\s*\[(.*?)\]", pyproject, re.DOTALL | re.MULTILINE)
    ok = "mkdocs" in (test_extra.group(1) if test_extra else "") and "pytest" in ci
    textcheck("47.N2b", "mkdocs build --strict runs in CI", "grep mkdocs .ci/run pyproject.toml tests/test_docs.py",
              ok, "[test] extra installs mkdocs; tests/test_docs.py builds --strict in the default suite"
              if ok else "mkdocs not in the [test] extra")

    # N3: how to get the CPU torch
    cons = (REPO / "constraints.txt").read_text()
    ok = "download.pytorch.org/whl/cpu" in cons and "download.pytorch.org/whl/cpu" in readme
    textcheck("47.N3", "constraints.txt / README say truthfully how to get the CPU torch",
              "grep whl/cpu constraints.txt README.md", ok,
              next((ln for ln in cons.splitlines() if "CUDA" in ln), ""))

    # N4: compare's progress bars name the cell and k of N
    def labels(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        bars = sorted({re.split(r":\s*\d+%|\|", ln)[0].strip() for ln in r.err.replace("\r", "\n").splitlines()
                       if "%" in ln or "it/s" in ln or "s/it" in ln})
        bare = [b for b in bars if b in ("clean episodes", "attacked episodes")]
        return ("WRONG" if bare or not bars else "runs"), f"bar labels: {bars[:6]}"
    ex("47.N4", "compare's progress bars (labelled with the cell, k of N?)",
       ZOD + ["compare", "baseline:slower", "baseline:faster", *HF, "--attacks", "uniform-noise", "--eps", "0.05",
              "0.1", "--episodes", "1", "--env-set", "max_episode_steps=5", "--out", "cmp"], "run", check=labels,
       timeout=120, line_from="grep:cell|of")

    # N5 / N8: render with an attack: a progress bar, every decision in the GIF, the final PNG note
    def render_check(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        notes = []
        bar = "rendering" in r.err
        notes.append("progress bar " + ("drawn" if bar else "NOT drawn"))
        frames = None
        try:
            from PIL import Image
            with Image.open(cwd / "r" / "episode.gif") as im:
                frames = getattr(im, "n_frames", 1)
        except Exception as exc:  # noqa: BLE001
            notes.append(f"gif unreadable: {exc}")
        meta = json.loads((cwd / "r" / "episode.json").read_text()) if (cwd / "r" / "episode.json").exists() else {}
        steps = None
        for k in ("steps", "decisions", "length", "actions"):
            if k in meta:
                steps = meta[k] if isinstance(meta[k], int) else len(meta[k])
                break
        notes.append(f"gif frames {frames}, decisions {steps}")
        return ("runs" if bar else "WRONG"), "; ".join(notes)
    ex("47.N5", "render (attacked): progress while rendering, GIF keeps every decision",
       ZOD + ["render", str(INP / "dqn" / "model.zip"), "--attack", "random-search", "--eps", "0.05", "--env-set",
              "max_episode_steps=8", "--out", "r"], "run", check=render_check, timeout=180)

    # N6: zodrive baselines' time
    cwd = fresh("47.N6")
    r = run(ZOD + ["baselines"], cwd) if want("47.N6") else Res(0, "", "", 0)
    v = classify(r, "run")
    if v == "runs" and r.secs > 5:
        v = "WRONG"
    record("47.N6", "`zodrive baselines` lists names quickly", "zodrive baselines", r, v,
           f"{r.secs:.1f} s (was 10 s)", last(r.out))

    # N7: the HTML report, regenerated from a copy of the committed reproduction (nothing recomputed)
    def copy_repro(cwd: Path) -> None:
        shutil.copytree(REPO / "results" / "reproduction", cwd / "repro")

    def report(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        html = (cwd / "repro" / "report.html").read_text(errors="replace")
        bad = []
        if re.search(r"<pre>\s*\|", html):
            bad.append("a Markdown table in <pre>")
        if re.search(r"\b1 episodes\b", html):
            bad.append("'1 episodes'")
        return ("WRONG", "; ".join(bad)) if bad else ("runs", "report.html: tables are <table>, no '1 episodes'")
    ex("47.N7", "HTML report (zodrive reproduce over a copy of results/reproduction)",
       ZOD + ["--models", str(REPO / "models"), "reproduce", "--out", "repro", "--no-progress"], "run", setup=copy_repro, check=report, timeout=300)
    record("47.N7b", "HTML report at 1 episode per cell ('1 episode', not '1 episodes')",
           "zodrive reproduce --episodes 1", None, "skipped",
           "a 1-episode reproduction runs 16 cells of 450 steps (minutes on this loaded machine); "
           "47.N7 checks the regenerated report's text", "")

    # N9: help texts
    cwd = fresh("47.N9")
    r = run(ZOD + ["evaluate", "--help"], cwd) if want("47.N9") else Res(0, "", "", 0)
    helptext = r.out
    opts = re.findall(r"^  (-{1,2}[\w-]+)(.*)$", helptext, re.MULTILINE)
    blocks = re.split(r"\n(?=  -)", helptext)
    bare = [b.split()[0] for b in blocks if b.startswith("  -") and len(b.split("\n")) == 1
            and len(re.split(r"\s{2,}", b.strip())) == 1]
    nws = next((b for b in blocks if b.strip().startswith("--no-warm-start")), "")
    bad = []
    if bare:
        bad.append(f"without help: {bare}")
    if "(default: True)" in nws:
        bad.append("--no-warm-start says (default: True)")
    record("47.N9a", "`evaluate --help`: every option has help text; --no-warm-start's default", "zodrive evaluate --help",
           r, "WRONG" if bad else classify(r, "run"), "; ".join(bad) or f"{len(opts)} options, all with help",
           " ".join(nws.split()))
    r = run(ZOD + ["--help"], cwd)
    tl = next((ln.strip() for ln in r.out.splitlines() if ln.strip().startswith("train ")), "")
    record("47.N9b", "top-level help names TD3 for train", "zodrive --help", r,
           "runs" if "TD3" in tl else "WRONG", "", tl)

    # N10: docs text
    idx = (REPO / "docs" / "index.md").read_text()
    textcheck("47.N10b", "docs/index.md and README agree on the one-query attacks", "grep one-query docs/index.md README.md",
              "two one-query" in idx and "two one-query" in readme and "a one-query attack" not in idx,
              next((ln for ln in idx.splitlines() if "one-query" in ln), ""))
    record("47.N10c", "results table cut off at 1280 px", "(a browser check)", None, "skipped",
           "needs a browser at 1280 px; not checked by this script", "")

    # N11: the benchmark takes any victim the CLI takes
    cwd = fresh("47.N11")
    argv = [PY, str(REPO / "benchmarks" / "attack_speed.py"), "--model", str(REPO / "models" / "dqn-close"),
            "--states", "1", "--steps", "5", "--n-directions", "4", "--episodes", "1", "--max-steps", "5", "--envs", "1"]
    r = run(argv, cwd, 180) if want("47.N11") else Res(0, "", "", 0)
    record("47.N11", "benchmarks/attack_speed.py --model models/dqn-close", shlex.join(argv), r,
           classify(r, "run"), "", last(r.err) if r.rc else last(r.out))

    # the 491-invocation trial itself
    record("47.TRIAL", "the full 491-invocation trial", "(the trial's own harness)", None, "skipped",
           "hours of runs; the property test of the CLI (tests/) stands in for it", "")


# ---------------------------------------------------------------------------------------------
# issue 46


def issue46() -> None:
    ev = ZOD + ["evaluate"]
    models = INP / "sb3"
    trained = (models / "ppo" / "ppo.zip").exists()

    # 1. VecNormalize: zodrive's episodes equal the user's own loop with the statistics applied
    n = 3
    own: list[float] | None = None
    if trained:
        cwd = fresh("46.1-own")
        (cwd / "own.py").write_text(OWN_LOOP)
        r = run([PY, "own.py", str(models / "vecnorm" / "model.zip"), str(models / "vecnorm" / "vecnormalize.pkl"),
                 str(n)], cwd, 180)
        if r.rc == 0:
            own = json.loads(last(r.out))

    def same_as_own(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        got = episode_returns(cwd / "o")
        if own is None:
            return "runs", f"zodrive {got}; own loop failed, not compared"
        ok = len(got) == len(own) and all(abs(a - b) < 1e-6 for a, b in zip(got, own))
        return ("runs" if ok else "WRONG"), (f"zodrive {[round(x, 4) for x in got]} vs own loop "
                                             f"{[round(x, 4) for x in own]}")
    if trained:
        ex("46.1", "PPO trained inside VecNormalize (vecnormalize.pkl beside the zip), vs own loop",
           ev + [str(models / "vecnorm" / "model.zip"), *HF, "--episodes", str(n), "--out", "o", "--no-progress"],
           "run", check=same_as_own, timeout=180)

        # extra (not in the issue): a plain zip whose folder holds another model's subfolder with its
        # vecnormalize.pkl: are those statistics applied to this model?
        plain = fresh("46.1x-plain")
        r0 = run(ev + [str(models / "ppo" / "ppo.zip"), *HF, "--episodes", str(n), "--out", "o", "--no-progress"],
                 plain, 180)
        plain_returns = episode_returns(plain / "o") if r0.rc == 0 else None

        def sibling(cwd: Path) -> None:
            (cwd / "m" / "other").mkdir(parents=True)
            shutil.copy(models / "ppo" / "ppo.zip", cwd / "m" / "ppo.zip")
            shutil.copy(models / "vecnorm" / "vecnormalize.pkl", cwd / "m" / "other" / "vecnormalize.pkl")

        def same_as_plain(r: Res, cwd: Path) -> tuple[str, str] | None:
            if r.rc != 0:
                return None
            got = episode_returns(cwd / "o")
            if plain_returns is None:
                return "runs", f"returns {got}; the plain run failed"
            if got != plain_returns:
                return "WRONG", (f"another model's m/other/vecnormalize.pkl was applied to m/ppo.zip: returns "
                                 f"{[round(x, 4) for x in got]} vs {[round(x, 4) for x in plain_returns]} alone")
            return "runs", "the sibling's statistics were not applied"
        ex("46.1x", "extra: m/ppo.zip (no normalization) beside m/other/vecnormalize.pkl of another model",
           ev + ["m/ppo.zip", *HF, "--episodes", str(n), "--out", "o", "--no-progress"], "either", setup=sibling,
           check=same_as_plain, timeout=180)

        # 2. rl-zoo3 and Hugging Face folders
        def zoo(cwd: Path) -> None:
            d = cwd / "logs" / "ppo" / "highway-fast-v0_1"
            (d / "highway-fast-v0").mkdir(parents=True)
            shutil.copy(models / "vecnorm" / "model.zip", d / "highway-fast-v0.zip")
            shutil.copy(models / "vecnorm" / "vecnormalize.pkl", d / "highway-fast-v0" / "vecnormalize.pkl")
            od = "!!python/object/apply:collections.OrderedDict"
            (d / "highway-fast-v0" / "args.yml").write_text(
                f"{od}\n- - - algo\n    - ppo\n  - - env\n    - highway-fast-v0\n  - - seed\n    - 0\n")
            (d / "highway-fast-v0" / "config.yml").write_text(
                f"{od}\n- - - normalize\n    - true\n  - - n_timesteps\n    - 192\n  - - policy\n    - MlpPolicy\n")
            (d / "highway-fast-v0" / "env_kwargs.yml").write_text("{}\n")
        ex("46.2a", "rl-zoo3 folder (highway-fast-v0.zip, args.yml, config.yml, env_kwargs.yml, vecnormalize.pkl), "
           "no --preset, vs own loop",
           ev + ["logs/ppo/highway-fast-v0_1", "--episodes", str(n), "--out", "o", "--no-progress"], "run",
           setup=zoo, check=same_as_own, timeout=180)

        def hf(cwd: Path) -> None:
            d = cwd / "ppo-highway-fast-v0"
            d.mkdir()
            shutil.copy(models / "vecnorm" / "model.zip", d / "ppo-highway-fast-v0.zip")
            shutil.copy(models / "vecnorm" / "vecnormalize.pkl", d / "vec_normalize.pkl")
            od = "!!python/object/apply:collections.OrderedDict"
            (d / "args.yml").write_text(f"{od}\n- - - algo\n    - ppo\n  - - env\n    - highway-fast-v0\n")
            (d / "env_kwargs.yml").write_text("{}\n")
            (d / "config.yml").write_text(f"{od}\n- - - normalize\n    - true\n")
        ex("46.2b", "Hugging Face folder (ppo-highway-fast-v0.zip, vec_normalize.pkl, args.yml), no --preset, "
           "vs own loop", ev + ["ppo-highway-fast-v0", "--episodes", str(n), "--out", "o", "--no-progress"], "run",
           setup=hf, check=same_as_own, timeout=180)

        def two_zips(cwd: Path) -> None:
            (cwd / "f").mkdir()
            shutil.copy(models / "ppo" / "ppo.zip", cwd / "f" / "a.zip")
            shutil.copy(models / "ppo" / "ppo.zip", cwd / "f" / "b.zip")
        ex("46.2c", "a folder with two zips and no model.zip (names them?)", ev + ["f", *HF] + FAST,
           setup=two_zips)

        # 3. the scenario is never a silent guess
        def says_default(r: Res, cwd: Path) -> tuple[str, str] | None:
            if r.rc != 0:
                return None
            s = json.loads((cwd / "o" / "summary.json").read_text())
            head = (lines(r.err) + lines(r.out))[:3]
            said = any("default" in ln for ln in head)
            rec = {k: v for k, v in s.items() if "preset" in k or "scenario" in k}
            in_summary = "default" in json.dumps(s)
            if not said:
                return "SILENT", f"summary: {rec}; first lines: {head[:2]}"
            return "runs", (f"warned: {head[0]}" + ("" if in_summary else
                            f" | PARTIAL: summary.json records {rec} and does not say it was a default"))
        ex("46.3a", "PPO trained on highway-fast, evaluated without --preset (says the scenario was a default?)",
           ev + [str(models / "ppo" / "ppo.zip"), "--out", "o"] + FAST, "run", check=says_default)
        ex("46.3b", "SAC trained on highway-fast (continuous), evaluated without --preset",
           ev + [str(models / "sac" / "sac.zip"), "--out", "o"] + FAST, "run", check=says_default)
    else:
        for id_ in ("46.1", "46.2a", "46.2b", "46.3a", "46.3b"):
            record(id_, "needs the tiny SB3 models", "-", None, "skipped", "training them failed", "")

    # 4. every row the victim receives is counted
    for envs in ("8", "1"):
        for attack in ("random-search", "zo-signsgd"):
            logging_victim(envs, attack)

    # 5. nothing unpickled without consent
    def stranger_models(cwd: Path) -> None:
        shutil.copytree(INP / "stranger" / "models", cwd / "models")
        import hashlib
        digest = hashlib.sha256((cwd / "models" / "dqn" / "model.zip").read_bytes()).hexdigest()
        (cwd / "models" / "SHA256SUMS").write_text(f"{digest}  dqn/model.zip\n")

    def no_marker(name: str) -> Check:
        def chk(r: Res, cwd: Path) -> tuple[str, str] | None:
            if (ROOT / name).exists():
                (ROOT / name).unlink()
                return "WRONG", f"the payload ran: {name} created"
            return None
        return chk
    ex("46.5a", "adv-train trusting a SHA256SUMS in the working directory (a payload zip listed in it)",
       ZOD + ["adv-train", "models/dqn/model.zip", "--steps", "10", "--out", "adv", "--no-progress"],
       setup=stranger_models, check=no_marker("MARKER-sha256sums"))
    ex("46.5b", "adv-train with --models DIR holding that SHA256SUMS",
       ZOD + ["--models", "models", "adv-train", "models/dqn/model.zip", "--steps", "10", "--out", "adv",
              "--no-progress"], setup=stranger_models, check=no_marker("MARKER-sha256sums"))

    def stranger_run(cwd: Path) -> None:
        shutil.copytree(INP / "run300", cwd / "run")
        ck = cwd / "run" / "checkpoints"
        (ck / "SIGNATURES.json").unlink(missing_ok=True)
        crafted_zip(ck / "dqn_300_steps.zip", serialized_payload=pickle.dumps(Marker(ROOT / "MARKER-resume")))
        (ck / "dqn_replay_buffer_300_steps.pkl").write_bytes(pickle.dumps(Marker(ROOT / "MARKER-resume")))
    ex("46.5c", "train --resume on a stranger's run folder (payload checkpoint and replay buffer, unsigned)",
       ZOD + ["train", "--algo", "dqn", "--steps", "400", "--set", "checkpoint_every=100", "--set",
              "hyperparameters.learning_starts=50", "--env-set", "max_episode_steps=20", "--resume", "--out", "run",
              "--no-progress"],
       setup=stranger_run, check=no_marker("MARKER-resume"))

    # 6. metrics that mean what they say
    def no_nan(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        succ = next((ln for ln in lines(r.out) if "success" in ln), "")
        if "nan" in succ.lower():
            return "WRONG", succ
        return "runs", succ
    ex("46.6a", "a 100% base rate (a policy that always takes FASTER, attacked toward FASTER): no 'nan%'",
       ev + [f"{INP}/faster.py:make", *HF, "--attack", "random-search", "--eps", "0.05"] + FAST, "run", check=no_nan,
       line_from="grep:success")

    def untargeted(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        succ = next((ln for ln in lines(r.out) if "success" in ln), "")
        return ("WRONG" if "target" in succ and "missed" in succ else "runs"), succ
    ex("46.6b", "an untargeted run's wording (--target none)",
       ev + [str(INP / "dqn" / "model.zip"), "--attack", "random-search", "--eps", "0.05", "--target", "none"] + FAST,
       "run", check=untargeted, line_from="grep:success")

    def path_positive(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        m = re.search(r"path: (-?[\d.]+) m", r.out)
        on = re.search(r"on road: [\d.]+% of steps", r.out)
        if not m or float(m.group(1)) < 0 or not on:
            return "WRONG", f"path {m.group(0) if m else '?'}; on-road share {'present' if on else 'missing'}"
        return "runs", f"{m.group(0)}; {on.group(0)}"
    ex("46.6c", "distance on intersection is the path travelled (was x-displacement, -34 m)",
       ev + ["baseline:slower", "--preset", "intersection", "--episodes", "1", "--env-set", "max_episode_steps=8",
             "--no-progress"], "run", check=path_positive, line_from="grep:path")
    record("46.6d", "off-road of a SAC that drives 560 m beside the road", "(needs a SAC trained for hours)", None,
           "skipped", "no such model here; the 'on road: % of steps' line is checked in 46.6c", "")

    # 7. observations beyond Kinematics
    ex("46.7a", "racetrack-v0's OccupancyGrid via --env-id, attacked (hand-checked)",
       ev + [f"{INP}/steer.py:make", "--env-id", "racetrack-v0", "--attack", "random-search", "--eps", "0.05",
             "--target", "none", "--steps", "5"] + FAST, "run", timeout=120)

    def pendulum_box(r: Res, cwd: Path) -> tuple[str, str] | None:
        if r.rc != 0:
            return None
        s = json.loads((cwd / "o" / "summary.json").read_text())
        rows = [tuple(map(float, ln.split())) for ln in (cwd / "rows.log").read_text().splitlines() if ln.strip()]
        trig, speed = max(a for a, _ in rows), max(b for _, b in rows)
        note = (f"queried |cos|,|sin| <= {trig:.6f}, |speed| <= {speed:.4f} over {len(rows)} calls; "
                f"max_linf {s.get('max_linf')}")
        return ("runs" if trig <= 1 + 1e-6 and speed <= 8 + 1e-6 else "WRONG"), note
    ex("46.7b", "Pendulum-v1 without --obs-bounds, attacked (hand-checked)",
       ev + [f"{INP}/pendlog.py:make", "--env-id", "Pendulum-v1", "--attack", "random-search", "--eps", "0.5",
             "--target", "none", "--steps", "5", "--out", "o", "--episodes", "1", "--env-set", "max_episode_steps=10",
             "--no-progress"], "run", check=pendulum_box, env={"ROWLOG": str(ROOT / "runs" / "46.7b" / "rows.log")})
    ex("46.7c", "Pendulum-v1 with --obs-bounds=-8,8 (hand-checked)",
       ev + [f"{INP}/steer.py:make", "--env-id", "Pendulum-v1", "--obs-bounds=-8,8", "--attack", "random-search",
             "--eps", "0.5", "--target", "none", "--steps", "5", "--episodes", "1", "--no-progress"])
    gray = ("highway.observation={type: GrayscaleObservation, observation_shape: [64, 64], stack_size: 4, "
            "weights: [0.2989, 0.5870, 0.1140], scaling: 1.75}")
    if trained:
        def advice(r: Res, cwd: Path) -> tuple[str, str] | None:
            if r.rc == 2 and ("--obs-bounds" in r.err or "--trust-model" not in r.err):
                return "WRONG", "the advice does not lead to --trust-model"
            return None
        ex("46.7d", "CnnPolicy on GrayscaleObservation, without --trust-model (the advice must not loop)",
           ev + [str(models / "cnn" / "cnn.zip"), *HF, "--env-set", gray] + FAST, check=advice)
        ex("46.7e", "CnnPolicy on GrayscaleObservation under --trust-model (hand-checked; tuple observation_shape "
           "through --env-set)",
           ev + [str(models / "cnn" / "cnn.zip"), *HF, "--env-set", gray, "--trust-model"] + FAST, "run", timeout=120)

    # 8. smaller
    ex("46.8a", "a discrete numpy callable that returns actions", ev + [f"{INP}/actions.py:make", *HF] + FAST, "run")

    def not_sb3_wording(r: Res, cwd: Path) -> tuple[str, str] | None:
        if "needs an SB3 model" in r.err:
            return "WRONG", "still says 'needs an SB3 model'"
        return None
    ex("46.8b", "--attack pgd on a numpy callable (refused for lack of gradients, not 'needs an SB3 model')",
       ev + [f"{INP}/x.py:make", *HF, "--attack", "pgd"] + FAST, check=not_sb3_wording)

    def not_model_file(r: Res, cwd: Path) -> tuple[str, str] | None:
        if "model file not found" in r.err:
            return "WRONG", "still says 'model file not found'"
        return None
    ex("46.8c", "zodrive export my_policy.py:make", ZOD + ["export", f"{INP}/x.py:make", "--out", "p.onnx"],
       "either", check=not_model_file)


def logging_victim(envs: str, attack: str) -> None:
    id_ = f"46.4-{attack}-envs{envs}"
    if not want(id_):
        return
    cwd = fresh(id_)
    log = cwd / "rows.log"
    argv = ZOD + ["evaluate", f"{INP}/logger.py:make", *HF, "--attack", attack, "--eps", "0.05", "--steps", "10",
                  "--envs", envs, "--episodes", "2", "--env-set", "max_episode_steps=5", "--out", "o", "--no-progress"]
    r = run(argv, cwd, 180, {"ROWLOG": str(log)})
    verdict, note = classify(r, "run"), ""
    if r.rc == 0:
        seen = [int(x) for x in log.read_text().split()] if log.exists() else []
        s = json.loads((cwd / "o" / "summary.json").read_text())
        vr = s.get("victim_rows", {})
        reported = sum(v for v in vr.values() if isinstance(v, (int, float)))
        ok = sum(seen) == reported
        verdict = "runs" if ok else "WRONG"
        note = (f"victim saw {sum(seen)} rows in {len(seen)} calls; summary victim_rows {vr} "
                f"(sum {reported}); queries/step {s.get('queries_per_step')}")
    record(id_, f"logging victim, {attack}, --envs {envs}: rows seen == rows reported", f"ROWLOG=rows.log {shlex.join(argv)}",
           r, verdict, note)


# ---------------------------------------------------------------------------------------------


def write_md(path: Path, started: float) -> None:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                            check=False).stdout.strip()
    counts: dict[str, int] = {}
    for row in ROWS:
        counts[row.verdict] = counts.get(row.verdict, 0) + 1
    esc = lambda s: s.replace("|", "\\|").replace("\n", " ")
    out = ["# Issues 46 and 47: every example re-run",
           "",
           (f"Generated by `studies/input-trial/rerun.py` on {datetime.datetime.now():%Y-%m-%d %H:%M}, "
            f"commit `{commit}`, in {time.monotonic() - started:.0f} s "
            f"(`OMP_NUM_THREADS=1`, one example at a time, each in a fresh temporary folder; `$IN` is the folder "
            f"of built inputs, `$TMP` the temporary root)."),
           "",
           "Verdicts: " + ", ".join(f"{k}: {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1])) + ".",
           "",
           "| # | Example | Command | Exit | Last stderr line (or the relevant stdout line) | Verdict | Note |",
           "|---|---|---|---|---|---|---|"]
    for row in ROWS:
        verdict = f"**{row.verdict}**" if row.verdict in BAD or "WRONG" in row.verdict else row.verdict
        out.append(f"| {row.id} | {esc(row.example)} | `{esc(row.command)}` | {row.rc} | {esc(row.line)} | "
                   f"{verdict} | {esc(row.note)} |")
    bad = [r for r in ROWS if r.verdict in BAD or "WRONG" in r.verdict]
    out += ["", "## Still failing", ""]
    out += [f"- **{r.id}** {r.example} — {r.verdict}: `{r.command}` → {r.line} {r.note}".rstrip() for r in bad] or ["None."]
    path.write_text("\n".join(out) + "\n")


def main() -> None:
    global ROOT, INP, ONLY
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="id prefixes to run (e.g. 47.T 46.4)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder")
    parser.add_argument("--md", default=str(HERE / "rerun.md"), help="the Markdown table to write")
    args = parser.parse_args()
    ONLY = args.only
    started = time.monotonic()
    ROOT = Path(tempfile.mkdtemp(prefix="zodrive-rerun-"))
    INP = ROOT / "in"
    print(f"temporary folder: {ROOT}", flush=True)
    try:
        build_inputs()
        r = train_dqn_run(INP / "run300", 300, 100)
        assert r.rc == 0, r.err
        r = run([PY, "-c", TRAIN_SB3, str(INP / "sb3")], INP, 600)
        if r.rc != 0:
            print("training the tiny SB3 models failed:\n" + r.err[-2000:], flush=True)
        print(f"inputs built in {time.monotonic() - started:.0f} s", flush=True)

        issue47()
        newcomer()
        issue46()
    finally:
        write_md(Path(args.md), started)
        print(f"wrote {args.md}", flush=True)
        if args.keep:
            print(f"kept {ROOT}")
        else:
            shutil.rmtree(ROOT, ignore_errors=True)


if __name__ == "__main__":
    main()
