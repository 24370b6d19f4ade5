"""Hostile and damaged inputs at the edge: each is refused in one line naming the file and what
is wrong (no traceback, no silent no-op). No highway-env episode runs here."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from zodrive.config import MAX_YAML_NODES, load_config, parse_override, read_yaml
from zodrive.errors import ZodriveError

BILLION_LAUGHS = """\
a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]
b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]
c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]
d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]
e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]
f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]
g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]
h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]
i: &i [*h, *h, *h, *h, *h, *h, *h, *h, *h]
"""


def _refusal(call, *args) -> str:
    with pytest.raises(ZodriveError) as info:
        call(*args)
    message = str(info.value)
    assert "\n" not in message
    return message


def _write(path: Path, data: str | bytes) -> Path:
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


NESTED = "base: discrete\nname:\n" + "".join("  " + line + "\n" for line in BILLION_LAUGHS.splitlines())


@pytest.mark.parametrize("text", [BILLION_LAUGHS, NESTED], ids=["top", "under a preset's name"])
def test_a_yaml_bomb_is_refused_at_once(tmp_path: Path, text: str) -> None:
    path = _write(tmp_path / "bomb.yaml", text)
    start = time.perf_counter()
    message = _refusal(read_yaml, path)
    assert time.perf_counter() - start < 2
    assert message == f"config file {path} is refused: its aliases expand to more than {MAX_YAML_NODES:,} values (a YAML bomb?)"


def test_ordinary_anchors_and_merge_keys_still_load(tmp_path: Path) -> None:
    path = _write(tmp_path / "ok.yaml", "common: &c {eps: 0.05, steps: 3}\nfirst: *c\nsecond:\n  <<: *c\n  eps: 0.1\n")
    assert read_yaml(path) == {"common": {"eps": 0.05, "steps": 3}, "first": {"eps": 0.05, "steps": 3},
                               "second": {"eps": 0.1, "steps": 3}}


@pytest.mark.parametrize("text", ["a: &a [*a]\n", "highway:\n  observation: &o {features: *o}\n"])
def test_a_recursive_alias_is_refused(tmp_path: Path, text: str) -> None:
    path = _write(tmp_path / "loop.yaml", text)
    assert "recursive alias" in _refusal(read_yaml, path)


def test_a_recursive_alias_in_an_override_is_refused() -> None:
    assert "recursive alias" in _refusal(parse_override, "highway.lanes_count=&a [*a]")


def test_a_duplicate_key_is_an_error_not_the_last_one_winning(tmp_path: Path) -> None:
    path = _write(tmp_path / "dup.yaml", "attack: random-search\neps: 0.05\nsteps: 3\neps: 0.5\n")
    message = _refusal(read_yaml, path)
    assert str(path) in message and "duplicate key 'eps'" in message and "line 2" in message
    assert "duplicate key 'a'" in _refusal(parse_override, "x={a: 1, a: 2}")


@pytest.mark.parametrize("kind", ["presets", "attacks", "recipes"])
def test_non_utf8_bytes_name_the_file(tmp_path: Path, kind: str) -> None:
    path = _write(tmp_path / "latin.yaml", b"# caf\xe9\nbase: x\n")
    message = _refusal(load_config, str(path), kind)
    assert message == f"config file {path} is not UTF-8 text (byte 0xe9 on line 1)"


def test_an_oversized_config_is_refused_unread(tmp_path: Path) -> None:
    path = _write(tmp_path / "big.yaml", "# " + "x" * (1 << 20) + "\n")
    assert "at most" in _refusal(read_yaml, path)


def test_a_missing_configs_folder_is_one_line(tmp_path: Path, monkeypatch) -> None:
    from zodrive.envs.presets import load_preset, preset_names

    monkeypatch.setenv("ZODRIVE_CONFIGS", str(tmp_path / "nonexistent"))
    for call, args in ((load_preset, ("discrete",)), (preset_names, ())):
        assert "ZODRIVE_CONFIGS=" in _refusal(call, *args) and "is not a folder" in _refusal(call, *args)


def test_a_non_utf8_preset_in_the_configs_folder_is_one_line(tmp_path: Path, monkeypatch) -> None:
    from zodrive.envs.presets import preset_summary

    (tmp_path / "presets").mkdir()
    path = _write(tmp_path / "presets" / "odd.yaml", b"# \xff\nenv_id: CartPole-v1\n")
    monkeypatch.setenv("ZODRIVE_CONFIGS", str(tmp_path))
    assert _refusal(preset_summary, "odd") == f"preset file {path} is not UTF-8 text (byte 0xff on line 1)"


@pytest.mark.parametrize("override, message", [
    ("highway.observation.features_range.x=[0]", "features_range.x must be [low, high]"),
    ("highway.reward_speed_range=[1]", "reward_speed_range must be [low, high]"),
    ("highway.reward_speed_range=[30, 20]", "reward_speed_range must be [low, high]"),
    ("highway.observation.features=[]", "features must hold at least 1 item"),
    ("highway.observation.features=[x, x]", "names 'x' twice"),
    ("highway.observation.features_range.vx=[1, 1]", "low < high"),
    ("highway.observation.features_range.x=[.nan, 1]", "must be a finite number, not nan"),
    ("highway.duration=.inf", "highway.duration must be a finite number, not inf"),
    ("highway.action.steering_range=[1, -1]", "low <= high"),
])
def test_preset_values_highway_env_would_crash_on_or_ignore(override: str, message: str) -> None:
    from zodrive.envs.presets import load_preset

    assert message in _refusal(load_preset, "discrete", [override])


def test_a_huge_value_is_never_formatted_whole() -> None:
    from zodrive.envs.presets import load_preset

    huge = "[" + ", ".join(["[1, 2, 3]"] * 2000) + "]"  # under the cap: the schema refuses it
    assert len(_refusal(load_preset, "discrete", [f"highway.observation.features={huge}"])) < 300
    huger = "[" + ", ".join(["[1, 2, 3]"] * 3000) + "]"  # over the cap, and no alias in it
    message = _refusal(load_preset, "discrete", [f"highway.observation.features={huger}"])
    assert len(message) < 300 and message.endswith(f"is refused: it holds more than {MAX_YAML_NODES:,} values")


# --- run folders: damaged records, the output rule, the lock ---------------------------------

@pytest.fixture(scope="module")
def idle_job():
    """A clean evaluation of a constant driver (no network; its one episode crashes in 43 steps)."""
    from zodrive.envs import load_preset
    from zodrive.evaluation.evaluate import EvalJob

    return EvalJob(model="baseline:idle", preset=load_preset("discrete"))


def _keyed(folder: Path, job, **files: str | bytes) -> Path:
    """`folder` holding `job`'s key and the given files (name with dots as `__`)."""
    from zodrive.runinfo import write_json

    folder.mkdir(parents=True, exist_ok=True)
    write_json(folder / "eval_key.json", job.key())
    for name, data in files.items():
        _write(folder / name.replace("__", "."), data)
    return folder


@pytest.mark.parametrize("files, message", [
    ({"eval_key__json": "{not json"}, "evaluation key {out}/eval_key.json is damaged, not JSON"),
    ({"eval_key__json": b"\xff\xfe{}"}, "evaluation key {out}/eval_key.json is not UTF-8 text"),
    ({"episodes__jsonl": '{"return": 1.0}\n'}, "run record {out}/episodes.jsonl is damaged: line 1 has no 'episode'"),
    ({"episodes__jsonl": '[1, 2]\n'}, "line 1 holds list, not a JSON object"),
    ({"episodes__jsonl": '{"episode": "zero"}\n'}, "has episode 'zero', not an episode index"),
    ({"summary__json": '{"episodes": 10, "mean_ret'}, "summary {out}/summary.json is damaged, not JSON"),
])
def test_a_damaged_run_folder_is_one_line_naming_the_file(tmp_path: Path, idle_job, files, message) -> None:
    from zodrive.evaluation.evaluate import evaluate

    out = _keyed(tmp_path / "run", idle_job, **files)
    assert message.format(out=out) in _refusal(evaluate, idle_job, 1, out)


def test_a_folder_zodrive_did_not_write_is_never_written_into(tmp_path: Path, idle_job) -> None:
    from zodrive.evaluation.evaluate import evaluate

    out = tmp_path / "mine"
    out.mkdir()
    mine = {"notes.txt": "my notes\n", "grid.json": "{}\n", "episodes.jsonl": '{"episode": 0, "mine": true}\n'}
    for name, text in mine.items():
        _write(out / name, text)
    message = _refusal(evaluate, idle_job, 1, out)
    assert message == (f"{out} holds files no zodrive evaluation wrote (episodes.jsonl, grid.json, notes.txt); "
                       "use --force to write into it (its own files are kept), or choose another --out")
    assert {p.name: p.read_text() for p in out.iterdir()} == mine
    evaluate(idle_job, 1, out, progress=False, force=True)  # force: the user's own files stay
    assert (out / "notes.txt").read_text() == "my notes\n" and (out / "grid.json").read_text() == "{}\n"
    assert "mine" not in (out / "episodes.jsonl").read_text() and (out / "summary.json").is_file()
    assert not (out / ".lock").exists()


def test_a_longer_run_of_the_same_evaluation_is_kept(tmp_path: Path, idle_job) -> None:
    """A copy of a committed models/*/eval folder (key and a 100-episode summary, no episodes)."""
    from zodrive.evaluation.evaluate import evaluate

    out = _keyed(tmp_path / "eval", idle_job, summary__json='{"episodes": 100, "mean_return": 1.0}\n')
    before = (out / "summary.json").read_text()
    message = _refusal(evaluate, idle_job, 1, out)
    assert message == (f"{out} already holds 100 episodes of this evaluation and zodrive never drops recorded "
                       "episodes: ask for at least 100, choose another --out, or use --force to replace them")
    assert (out / "summary.json").read_text() == before


def test_another_evaluation_is_refused_and_force_clears_its_run(tmp_path: Path, idle_job) -> None:
    from dataclasses import replace

    from zodrive.evaluation.evaluate import evaluate

    out = _keyed(tmp_path / "eval", replace(idle_job, seed=5), summary__json='{"episodes": 100}\n',
                 steps__jsonl='{"episode": 7}\n', notes__txt="kept\n")
    assert "holds a different evaluation (the first seed differs); use --force" in _refusal(evaluate, idle_job, 1, out)
    summary = evaluate(idle_job, 1, out, progress=False, force=True)
    assert summary["episodes"] == 1 and summary["seed"] == idle_job.seed
    assert (out / "notes.txt").read_text() == "kept\n" and '"episode": 7' not in (out / "steps.jsonl").read_text()


def test_a_second_run_into_a_locked_folder_is_refused_at_once(tmp_path: Path, idle_job) -> None:
    from zodrive.evaluation.evaluate import evaluate
    from zodrive.runinfo import run_lock

    out = tmp_path / "eval"
    out.mkdir()
    with run_lock(out):  # another run holds the folder
        start = time.perf_counter()
        message = _refusal(evaluate, idle_job, 1, out)
        assert time.perf_counter() - start < 10
    assert message.startswith(f"{out} is in use by another zodrive run")
    assert sorted(p.name for p in out.iterdir()) == []  # nothing written, the lock file gone with its holder


def test_the_lock_is_held_by_another_process_too(tmp_path: Path) -> None:
    import subprocess
    import sys

    from zodrive.runinfo import run_lock

    code = ("import sys, time; from pathlib import Path; from zodrive.runinfo import run_lock\n"
            "with run_lock(Path(sys.argv[1])):\n    print('held', flush=True); time.sleep(30)\n")
    holder = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(ZodriveError, match="in use by another zodrive run"):
            with run_lock(tmp_path):
                pass
    finally:
        holder.kill()
        holder.wait()
    with run_lock(tmp_path):  # the lock died with its holder
        pass


def test_an_out_that_is_a_file_is_one_line(tmp_path: Path, idle_job) -> None:
    from zodrive.evaluation.evaluate import evaluate

    path = _write(tmp_path / "file", "x")
    assert _refusal(evaluate, idle_job, 1, path) == f"--out {path} is a file, not a folder"


def test_a_broken_run_json_under_card(tmp_path: Path) -> None:
    from zodrive.experiments.card import write_card

    _write(tmp_path / "run.json", '{"command": "zodrive train", "vers')
    assert _refusal(write_card, tmp_path).startswith(f"run record {tmp_path}/run.json is damaged, not JSON")
    _write(tmp_path / "run.json", '{"command": "zodrive train"}')
    assert _refusal(write_card, tmp_path) == (f"run record {tmp_path}/run.json has no 'versions' "
                                              "(damaged, or not a record zodrive wrote)")


@pytest.mark.parametrize("text, message", [
    (b'#{"t_start": 0}\nr,l,t\n1.5,10,0.1\n\xff,3,0\n', "monitor file {p} is not UTF-8 text (byte 0xff on line 4)"),
    ('#{"t_start": 0}\nr,l,t\n1.5,10,0.1\nabc,3,0\n', "monitor file {p} is damaged: line 4 is not a row of numbers"),
    ('#{"t_start": 0}\nx,y\n1,2\n', "monitor file {p} has no 'r' and 'l' columns"),
])
def test_a_damaged_monitor_file_is_one_line(tmp_path: Path, text, message) -> None:
    from zodrive.experiments.curves import read_monitor

    path = _write(tmp_path / "monitor.monitor.csv", text)
    assert message.format(p=path) in _refusal(read_monitor, tmp_path)


def test_a_good_monitor_file_reads() -> None:
    from zodrive.experiments.curves import read_monitor

    returns, lengths = read_monitor(Path(__file__).resolve().parents[1] / "models" / "ddpg-driver")
    assert len(returns) == len(lengths) > 0


# --- cells keyed on exact numbers and on content ------------------------------------------------

REPO = Path(__file__).resolve().parents[1]


def test_cell_names_are_exact_and_committed_cells_keep_theirs() -> None:
    import re

    from zodrive.evaluation import store
    from zodrive.experiments.cells import number_name

    assert number_name(0.1) == "0.1" and number_name(0.1000001) == "0.1000001" and number_name(1e-05) == "1e-05"
    checked = 0
    for cell in store.walk(REPO / "results"):  # every committed cell, in its folder or packed
        if cell.parent.name != "cells":
            continue
        eps = ((store.read(cell).key or {}).get("attack") or {}).get("eps")
        named = re.search(r"-eps([0-9.e+-]+?)(?:-qb\d+)?$", cell.name)
        if eps is not None and named and _number(named.group(1)) == eps:
            assert number_name(eps) == named.group(1), cell
            checked += 1
    assert checked > 100


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None  # a study's own naming (eps0.2-100)


def test_two_models_named_model_zip_get_two_names() -> None:
    from zodrive.experiments.cells import policy_names

    assert policy_names(["dqn", "ddpg", "baseline:idle"], ["sha256:a", "sha256:b", "baseline:idle"]) == \
        ["dqn", "ddpg", "baseline:idle"]  # no clash: the names committed grids hold
    names = policy_names(["model", "model", "model"], ["sha256:a", "sha256:b", "sha256:a"])
    assert names[0] == names[2] != names[1] and all(n.startswith("model-") for n in names)


def test_compare_puts_close_eps_and_same_named_models_in_their_own_cells(tmp_path: Path, monkeypatch) -> None:
    import shutil

    from zodrive.experiments import compare as grid

    first, second = tmp_path / "a" / "model.zip", tmp_path / "b" / "model.zip"
    for path, source in ((first, "dqn-close"), (second, "dqn-driver")):
        path.parent.mkdir()
        shutil.copy(REPO / "models" / source / "model.zip", path)
    seen: list = []
    monkeypatch.setattr(grid, "run_cells", lambda cells, **_: seen.extend(cells))
    grid.compare([str(first), str(second)], ["random-search"], [0.1, 0.1000001], 1, tmp_path / "out",
                 preset="discrete", progress=False)
    folders = [cell.folder.name for cell in seen]
    assert len(set(folders)) == len(folders) == 6, folders
    assert sum(name.endswith("-eps0.1000001") for name in folders) == 2

