"""zodrive bench and the leaderboard: a row from a protocol's cells, resumable, generated tables."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from zodrive.bench.bench import PROTOCOLS, physical_eps
from zodrive.bench.leaderboard import leaderboard_markdown, read_rows
from zodrive.cli import main
from zodrive.experiments.cells import GridCell

MODEL = Path(__file__).resolve().parents[1] / "models" / "ppo-highway-fast"


@pytest.mark.integration
def test_a_bench_row_and_its_leaderboard(tmp_path: Path, capsys, monkeypatch) -> None:
    board = tmp_path / "board"
    args = ["bench", str(MODEL), "--scenario", "highway-fast", "--name", "ppo", "--episodes", "2",
            "--board", str(board), "--no-progress"]
    assert main(args) == 0
    row = json.loads((board / "highway-fast" / "ppo" / "row.json").read_text())
    assert row["protocol"] == PROTOCOLS["highway-fast"].name() and row["official"] is False
    assert row["key"].startswith("sha256:") and row["clean_episodes"] == row["episodes"] == 2  # a quick look: 2 of each
    assert not (board / "highway-fast" / "ppo" / "clean").exists()
    for folder in (board / "highway-fast" / "ppo", board / "highway-fast" / "brake"):  # the data, no renderings
        assert (folder / "table.json").is_file()
        assert not any((folder / name).exists() for name in ("grid.json", "table.csv", "table.md", "robustness.md"))
    table = json.loads((board / "highway-fast" / "ppo" / "table.json").read_text())
    clean = next(c["mean_return"] for c in table if c["attack"] == "none")
    for cell in row["attacked"]:  # the row keeps the cell that hurts most inside each eps-ball
        attacked = [c["mean_return"] for c in table if c["attack"] in PROTOCOLS["highway-fast"].black_box
                    and c["eps"] <= cell["eps"]]
        assert len(attacked) == 2 * (1 + PROTOCOLS["highway-fast"].eps.index(cell["eps"]))
        assert cell["return"] == min(*attacked, clean)
        assert cell["pgd_return"] is not None  # white-box apart, since the PPO has gradients
    assert row["brake"]["collision_rate"] >= 0 and 0 < row["robustness_area"] <= 1.5
    text = (board / "leaderboard.md").read_text()  # an unofficial row: in a table of its own, unranked, never bold
    ppo = next(line for line in text.splitlines() if line.startswith("| ppo |"))
    assert text.index("Unofficial rows of highway-fast") < text.index(ppo) and "**" not in ppo
    import zodrive.evaluation.evaluate as evaluation

    def no_episode(*args, **kwargs):
        raise AssertionError("a finished cell ran again")

    monkeypatch.setattr(evaluation, "run_episodes", no_episode)
    assert main(args) == 0  # resumes: every cell is done, nothing runs again
    assert json.loads((board / "highway-fast" / "ppo" / "row.json").read_text()) == row
    out = tmp_path / "leaderboard.md"
    assert main(["leaderboard", "--board", str(board), "--out", str(out), "--plot", str(tmp_path / "b.png")]) == 0
    assert out.read_text() == leaderboard_markdown(read_rows(board))
    assert (tmp_path / "b.png").stat().st_size > 0
    mine = tmp_path / "notes.md"
    mine.write_text("my notes\n")  # a file zodrive did not write is replaced only with --force
    assert main(["leaderboard", "--board", str(board), "--out", str(mine)]) == 2
    assert mine.read_text() == "my notes\n"
    assert main(["leaderboard", "--board", str(board), "--out", str(out), "--plot", str(mine)]) == 2
    assert main(["leaderboard", "--board", str(board), "--out", str(mine), "--force"]) == 0
    assert main(["leaderboard", "--board", str(board)]) == 2  # no default: the checkout's board only when asked


def test_a_forced_bench_drops_the_old_row_before_it_runs(tmp_path: Path, monkeypatch) -> None:
    """While a forced bench replaces another policy's cells, the leaderboard must not pair the old row
    with the new cells: the old row goes first, and the folder has no row until the new one is done."""
    import zodrive.bench.bench as bench_module

    args = ["bench", "baseline:slower", "--scenario", "highway-fast", "--name", "x", "--episodes", "1",
            "--board", str(tmp_path), "--no-progress"]
    assert main(args) == 0
    row = tmp_path / "highway-fast" / "x" / "row.json"
    assert json.loads(row.read_text())["key"] == "baseline:slower"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(bench_module, "compare", interrupted)
    try:
        main(["bench", "baseline:idle", *args[2:], "--force"])
    except KeyboardInterrupt:
        pass
    assert not row.exists()


def _cell(attack: str, eps: float, mean_return: float, collisions: float = 0.0) -> dict:
    return {"model": "m", "attack": attack, "eps": eps, "mean_return": mean_return, "ci95_low": mean_return - 1,
            "ci95_high": mean_return + 1, "collision_rate": collisions, "queries_per_step": 1.0, "mean_speed": 20.0}


def _bench_folder(folder: Path, cells: list[dict], brake_collisions: float = 0.2) -> Path:
    """A finished bench folder made of `cells` (table.json), each attacked cell with one crashed episode."""
    (folder / "brake").mkdir(parents=True)
    (folder / "table.json").write_text(json.dumps(cells))
    (folder / "brake" / "table.json").write_text(json.dumps([{**_cell("none", 0.0, 5.0, brake_collisions),
                                                               "model": "baseline:slower"}]))
    brake = GridCell("baseline:slower").folder(folder / "brake")  # the same rate on every first 5k episodes
    brake.mkdir(parents=True)
    brake.joinpath("episodes.jsonl").write_text("".join(
        json.dumps({"episode": i, "return": 5.0, "crashed": int((i + 1) * brake_collisions) > int(i * brake_collisions)})
        + "\n" for i in range(300)))
    for c in cells:
        if c["attack"] != "none":
            cell = GridCell.from_entry(c).folder(folder)  # the folder compare gives the entry's cell
            cell.mkdir(parents=True)
            (cell / "episodes.jsonl").write_text(json.dumps({"episode": 0, "crashed": True, "queries": 7}) + "\n")
    return folder


def test_the_return_at_eps_is_the_worst_inside_the_eps_ball(tmp_path: Path) -> None:
    """Version 2: an attack at a smaller eps (or none at all) is inside the ball, so a weaker search at a
    larger eps never raises the row's return there; collisions past the brake's count at any cell."""
    from zodrive.bench.bench import bench_row

    proto = PROTOCOLS["highway-fast"]  # eps 0.01, 0.02, 0.05
    cells = [_cell("none", 0.0, 10.0, 0.1),
             _cell("random-search", 0.01, 8.0, 0.1), _cell("zo-signsgd", 0.01, 9.0),
             _cell("random-search", 0.02, 9.5, 0.5), _cell("zo-signsgd", 0.02, 8.5),
             _cell("random-search", 0.05, 7.0, 0.9), _cell("zo-signsgd", 0.05, 12.0),
             _cell("pgd (white-box)", 0.01, 5.0), _cell("pgd (white-box)", 0.02, 6.0), _cell("pgd (white-box)", 0.05, 5.5)]
    row = bench_row("m", "k", proto, _bench_folder(tmp_path / "a", cells), 100)
    assert [p["return"] for p in row["attacked"]] == [8.0, 8.0, 7.0]  # version 1 said 8.0, 8.5, 7.0
    assert [p["attack_eps"] for p in row["attacked"]] == [0.01, 0.01, 0.05]
    assert [p["pgd_return"] for p in row["attacked"]] == [5.0, 5.0, 5.0]
    assert row["eps_collisions_pass_brake"] == 0.02  # random search at 0.02 crashes 50 %, the brake 20 %
    assert row["robustness_area"] == pytest.approx((0.01 * 9 + 0.01 * 8 + 0.03 * 7.5) / (0.05 * 10))

    helped = [_cell("none", 0.0, 5.0), _cell("random-search", 0.01, 6.0), _cell("zo-signsgd", 0.01, 5.0)]
    row = bench_row("m", "k", PROTOCOLS["discrete"], _bench_folder(tmp_path / "b", helped), 30)
    first = row["attacked"][0]  # a tie with clean goes to the attack; an attack that only helps is not one
    assert (first["return"], first["attack"], first["attack_eps"]) == (5.0, "zo-signsgd", 0.01)
    assert row["attacked"][0]["queries_to_crash"] == 7.0 and row["robustness_area"] == pytest.approx(1.0)


def test_compare_keeps_the_strongest_attack_inside_each_eps_ball() -> None:
    """`zodrive compare`'s robustness table and plot use the same rule as the bench row: at each eps the
    strongest row at that eps, a smaller one, or clean, and they say where a row came from."""
    from zodrive.experiments.compare import robustness_markdown, strongest

    rows = [{**_cell("none", None, 300.0), "defense": "none", "mean_speed": 20.0},
            {**_cell("random-search", 0.05, 90.0), "defense": "none", "mean_speed": 27.0},
            {**_cell("pgd (white-box)", 0.05, 80.0), "defense": "none", "mean_speed": 27.0},
            {**_cell("random-search", 0.2, 130.0), "defense": "none", "mean_speed": 29.0},
            {**_cell("random-search", 0.01, 310.0), "defense": "none", "mean_speed": 20.0}]
    curve = strongest(rows)["m"]
    assert [curve[e]["mean_return"] for e in (0.0, 0.01, 0.05, 0.2)] == [300.0, 300.0, 80.0, 80.0]
    text = robustness_markdown(rows)
    assert "80.0 (pgd (white-box) at ε 0.05, 27.0 m/s) |" in text and "300.0 (clean: no attack hurt more" in text


def test_rows_of_two_protocol_versions_never_share_a_table() -> None:
    def row(protocol: str) -> dict:
        return {"protocol": protocol, "scenario": "merge", "policy": protocol, "official": True, "key": "k", "episodes": 100,
                "clean": {"return": 1.0, "ci95": [0.0, 2.0], "collision_rate": 0.0, "speed": 20.0},
                "attacked": [{"eps": 0.01, "return": 1.0, "collision_rate": 0.0, "queries_to_crash": None,
                              "pgd_return": None}], "robustness_area": 1.0, "eps_collisions_pass_brake": None}

    current = PROTOCOLS["merge"].name()
    text = leaderboard_markdown([row("merge-v1"), row(current)])
    assert "## merge (protocol merge-v1) — an earlier version" in text and f"## merge (protocol {current})\n" in text


def test_eps_is_stated_in_the_scenarios_units() -> None:
    units = physical_eps(PROTOCOLS["highway-fast"])
    assert units["0.05"]["x"] == 10.0 and units["0.05"]["vx"] == 4.0  # x normalized by +-200 m, vx by +-80 m/s


def test_a_bench_refuses_in_one_line(tmp_path: Path, capsys) -> None:
    assert main(["bench", "baseline:slower", "--scenario", "highway-fast", "--name", "../x", "--board",
                 str(tmp_path)]) == 2
    assert "one folder name" in capsys.readouterr().err
    assert main(["leaderboard", "--board", str(tmp_path / "none"), "--out", str(tmp_path / "l.md")]) == 2


def test_the_committed_leaderboard_is_generated_from_the_committed_rows() -> None:
    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "leaderboard.md").read_text()
    assert text == leaderboard_markdown(read_rows(root / "results" / "bench"))  # never typed


def test_the_margin_over_the_brake_is_paired_on_the_rows_own_episodes() -> None:
    """Δ brake is computed from the row folder's clean episodes and the board's brake, seed by seed: the brake's
    own row is exactly 0, and the committed highway-fast DQN (seed 0) beats the brake by a margin its CI shows."""
    from zodrive.bench.bench import brake_folder, brake_margin, row_clean_folder

    board = Path(__file__).resolve().parents[1] / "results" / "bench" / "highway-fast"
    brake = board / "brake"  # one per scenario, no row keeps a copy
    assert [brake_folder(row.parent) for row in board.glob("*/row.json")] == [brake] * len(list(board.glob("*/row.json")))
    for name in ("baseline-slower", "dqn-seed-0"):
        row = json.loads((board / name / "row.json").read_text())
        assert brake_margin(row_clean_folder(row, board / name), brake) == row["vs_brake"]
    assert brake_margin(board / "baseline-slower" / "clean", brake) == [0.0, 0.0, 0.0]
    mean, low, high = brake_margin(board / "dqn-seed-0" / "clean", brake)
    assert 0 < low < mean < high
    assert brake_margin(board / "dqn-seed-0", brake) is None  # 100 episodes against 300


def test_the_margin_over_every_constant_comes_from_the_constant_rows_of_the_same_table() -> None:
    """Each row is paired with every constant action benched under its protocol (not with itself), and the
    leaderboard shows the constant it beats by the least: on intersection that is IDLE/FASTER, not the brake."""
    from zodrive.bench.leaderboard import _closest_constant

    rows = {(r["scenario"], r["policy"]): r for r in read_rows(Path(__file__).resolve().parents[1] / "results" / "bench")}
    slower = rows[("intersection", "baseline-slower")]
    assert set(slower["vs_constants"]) == {"idle", "faster"}
    dqn = rows[("intersection", "dqn-seed-1")]
    assert set(dqn["vs_constants"]) == {"slower", "idle", "faster"}
    assert dqn["vs_constants"]["slower"][1] > 0 > dqn["vs_constants"]["faster"][1]  # beats the brake, not FASTER
    assert _closest_constant(dqn).endswith(("vs idle", "vs faster"))
    assert _closest_constant({"vs_constants": {}, "vs_brake": [1.0, 0.5, 1.5]}) == "**+1.00** (+0.50 to +1.50) vs slower"
    assert _closest_constant({"vs_constants": {"slower": [0.3, 0.0, 0.6]}}) == "+0.30 (+0.00 to +0.60) vs slower"
    assert _closest_constant({"vs_constants": {"idle": None}}) == "–"


def test_the_plot_gives_a_family_one_colour_and_each_seed_its_own_marker() -> None:
    """Merge has 15 rows: drawn in a 10-colour cycle, two policies shared a colour and could not be told apart;
    and colours given by sorted position changed whenever a row was added."""
    from zodrive.bench.leaderboard_plot import family_and_seed, family_colours, line_style

    assert family_and_seed("dqn-g99-seed-1") == ("dqn-g99", 1)
    assert family_and_seed("baseline-slower") == ("baseline-slower", 0)
    colours = family_colours(["dqn", "dqn-g99"])
    one, two = (line_style({"policy": f"dqn-g99-seed-{i}", "key": "sha256:x"}, colours) for i in (1, 2))
    assert one["color"] == two["color"] and one["marker"] != two["marker"]
    assert line_style({"policy": "dqn-seed-1", "key": "sha256:y"}, colours)["color"] != one["color"]
    assert family_colours(["dqn", "dqn-g99", "attention", "imitation"])["dqn-g99"] == colours["dqn-g99"]  # stable
    assert len(set(family_colours([f"f{i}" for i in range(12)]).values())) == 12  # no colour repeats in a panel
    brake = line_style({"policy": "baseline-slower", "key": "baseline:slower"}, colours)
    rules = line_style({"policy": "baseline-rules", "key": "baseline:rules"}, family_colours(["baseline-rules"]))
    assert brake["linestyle"] == "--" != one["linestyle"] and rules["linestyle"] == "-"  # rules read, and are attacked


EXTRACTOR = '''
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor


class RowMean(BaseFeaturesExtractor):
    """A network of the user's own: the mean over the observation's vehicle rows."""

    def __init__(self, observation_space):
        super().__init__(observation_space, features_dim=observation_space.shape[-1])

    def forward(self, obs):
        return obs.mean(dim=1)
'''


@pytest.mark.integration
def test_a_network_of_the_users_own_is_benched_only_with_trust_and_its_row_says_so(tmp_path: Path, capsys,
                                                                                  monkeypatch) -> None:
    import gymnasium as gym
    from stable_baselines3 import DQN

    from zodrive.envs import load_preset, make_env

    (tmp_path / "my_net.py").write_text(EXTRACTOR)
    monkeypatch.syspath_prepend(str(tmp_path))
    from my_net import RowMean

    env = make_env(load_preset("intersection"))
    assert isinstance(env.observation_space, gym.spaces.Box) and env.observation_space.shape == (15, 7)
    DQN("MlpPolicy", env, policy_kwargs={"features_extractor_class": RowMean, "net_arch": [8]}, seed=0,
        device="cpu").save(tmp_path / "mine")
    board = tmp_path / "board"
    args = ["bench", str(tmp_path / "mine.zip"), "--scenario", "intersection", "--name", "mine", "--episodes", "1",
            "--board", str(board), "--no-progress"]
    assert main(args) == 2  # read safely, the extractor is refused, not guessed
    assert "--trust-model" in capsys.readouterr().err
    assert main([*args, "--trust-model"]) == 0
    row = json.loads((board / "intersection" / "mine" / "row.json").read_text())
    assert row["trust_model"] is True and row["attacked"][-1]["pgd_return"] is not None
    assert "| mine† |" in (board / "leaderboard.md").read_text()
    monkeypatch.delitem(sys.modules, "my_net")  # and off the path: the zip names code that is not here
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p != str(tmp_path)])
    (tmp_path / "copy.zip").write_bytes((tmp_path / "mine.zip").read_bytes())
    assert main(["evaluate", str(tmp_path / "copy.zip"), "--preset", "intersection", "--episodes", "1",
                 "--trust-model", "--no-progress"]) == 2
    assert "module 'my_net', which is not importable here" in capsys.readouterr().err


def test_more_clean_episodes_than_attacked_ones(tmp_path: Path) -> None:
    """Version 3: the clean figures come from `clean/`, while the envelope and the area compare the
    attacks with the clean cell of the same (first) episodes; a row with other counts is unofficial."""
    from zodrive.bench.bench import Protocol, bench_row

    proto = Protocol("highway-fast", 100, (0.01, 0.05), clean_episodes=300)
    cells = [_cell("none", 0.0, 10.0, 0.1), _cell("random-search", 0.01, 11.0), _cell("random-search", 0.05, 6.0, 0.3)]
    folder = _bench_folder(tmp_path / "a", cells)
    (folder / "clean").mkdir()
    (folder / "clean" / "table.json").write_text(json.dumps([_cell("none", 0.0, 8.0, 0.25)]))
    row = bench_row("m", "k", proto, folder, 100, 300)
    assert row["clean"]["return"] == 8.0 and row["clean"]["collision_rate"] == 0.25
    assert row["clean_on_attacked_episodes"] == {"return": 10.0, "collision_rate": 0.1}
    assert [p["return"] for p in row["attacked"]] == [10.0, 6.0]  # clean of the same episodes, not of 300
    assert row["robustness_area"] == pytest.approx((0.01 * 10 + 0.04 * 8) / (0.05 * 10))
    assert row["eps_collisions_pass_brake"] == 0.05  # 10 % clean on these episodes is below the brake's 20 %
    assert (row["official"], row["clean_seeds"], row["seeds"]) == (True, [100000, 100299], [100000, 100099])
    assert bench_row("m", "k", proto, folder, 100)["official"] is False  # 100 clean episodes: not the protocol


def test_a_bench_runs_the_extra_clean_episodes_on_the_same_seeds(tmp_path: Path, monkeypatch) -> None:
    """The clean cell of more episodes begins with the attacked grid's own clean episodes (copied, not run
    again), and the board's brake, run once for the scenario, is paired with it episode by episode."""
    import zodrive.evaluation.evaluate as evaluation
    from zodrive.bench.bench import Protocol, bench

    proto = Protocol("highway-fast", 1, (0.05,), clean_episodes=2)
    board = tmp_path / "highway-fast"
    seeds: dict[str, list[int]] = {}  # the clean episodes run, per policy
    real = evaluation.run_episodes
    monkeypatch.setattr(evaluation, "run_episodes", lambda job, indices, *a, **k: (
        seeds.setdefault(job.model.ref, []).extend(job.seed + i for i in indices if job.attack is None),
        real(job, indices, *a, **k))[1])
    row = bench("baseline:idle", proto, board / "idle", progress=False, envs=1)

    def returns(folder: Path) -> list[float]:
        (cell,) = (folder / "cells").glob("*-none")
        return [json.loads(line)["return"] for line in (cell / "episodes.jsonl").read_text().splitlines()]

    clean = returns(board / "idle" / "clean")
    assert len(clean) == 2 and clean[:1] == returns(board / "idle") and sorted(seeds["baseline:idle"]) == [100000, 100001]
    assert row["clean"]["return"] == pytest.approx(sum(clean) / 2)
    brake = returns(board / "brake")
    assert not (board / "idle" / "brake").exists()
    mean = sum(a - b for a, b in zip(clean, brake, strict=True)) / 2
    assert len(brake) == 2 and row["vs_brake"][0] == pytest.approx(mean)
    assert seeds["baseline:slower"] == [100000, 100001]
    other = bench("baseline:faster", proto, board / "faster", progress=False, envs=1)
    assert seeds["baseline:slower"] == [100000, 100001]  # the second row reads the same brake, run once
    assert other["brake"] == row["brake"] and not (board / "faster" / "brake").exists()


def test_the_leaderboard_refuses_rows_it_cannot_read_in_one_line(tmp_path: Path, capsys) -> None:
    """Rows come from strangers: a well-formed JSON of the wrong shape, a FIFO, a link to /dev/zero, a name that
    breaks the table: one line each, never a traceback, a hang or a MemoryError."""
    import os

    root = Path(__file__).resolve().parents[1] / "results" / "bench" / "highway-fast" / "baseline-slower" / "row.json"
    good = json.loads(root.read_text())
    cases = {"empty": {}, "list": [], "no-attacked": {k: v for k, v in good.items() if k != "attacked"},
             "many": {**good, "episodes": "many"}, "none-attacked": {**good, "attacked": []},
             "pipe-name": {**good, "policy": "a|b"}, "newline": {**good, "policy": "a\nb"},
             "ci": {**good, "clean": {**good["clean"], "ci95": "wide"}}}
    for name, row in cases.items():
        board = tmp_path / name
        (board / "highway-fast" / "x").mkdir(parents=True)
        (board / "highway-fast" / "x" / "row.json").write_text(json.dumps(row))
        assert main(["leaderboard", "--board", str(board), "--out", str(tmp_path / f"{name}.md")]) == 2, name
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "is not a bench row" in err, (name, err)
    for name, make in (("fifo", os.mkfifo), ("zero", lambda p: os.symlink("/dev/zero", p))):
        board = tmp_path / name
        (board / "highway-fast" / "x").mkdir(parents=True)
        make(board / "highway-fast" / "x" / "row.json")
        assert main(["leaderboard", "--board", str(board), "--out", str(tmp_path / f"{name}.md")]) == 2, name
        assert "not a regular file" in capsys.readouterr().err
    for bad in ("", "a|b", "a\nb", ".hidden"):
        assert main(["bench", "baseline:slower", "--scenario", "highway-fast", "--name", bad, "--board",
                     str(tmp_path / "b")]) == 2
        assert "a row's name is one folder name" in capsys.readouterr().err


def test_a_bench_says_how_long_it_has_left(capsys, monkeypatch) -> None:
    """After its clean cell and first attacked cell, a bench says what is left (a 20-minute row said nothing)."""
    import zodrive.bench.bench as bench_module

    now = iter([0.0, 10.0, 40.0, 70.0])  # start, clean cell (10 s), two attacked cells (30 s each)
    monkeypatch.setattr(bench_module.time, "perf_counter", lambda: next(now))
    clock = bench_module._Clock(100, 300)
    clock.cell(1, 5, GridCell("m"))
    assert capsys.readouterr().err == ""  # no attacked cell yet: no pace to go by
    clock.cell(2, 5, GridCell("m", "random-search", 0.01))
    clock.cell(3, 5, GridCell("m", "zo-signsgd", 0.01))
    # 2 attacked cells left at 30 s, then 200 more clean episodes of the policy and 300 of the brake at 10 s per 100
    assert capsys.readouterr().err.splitlines()[-1] == "bench: 3/5 cells of the grid in 70 s; about 2 min left"
    now = iter([0.0, 10.0, 40.0, 70.0])
    clock = bench_module._Clock(100, 300, brake_done=True)  # the board's brake has run: only the policy's 200
    for done, attack in ((1, "none"), (2, "random-search"), (3, "zo-signsgd")):
        clock.cell(done, 5, GridCell("m", attack))
    assert capsys.readouterr().err.splitlines()[-1] == "bench: 3/5 cells of the grid in 70 s; about 80 s left"


def test_a_defended_row_attacks_the_defended_system(tmp_path: Path) -> None:
    """`bench --defense`: every cell queries the defended system, the row's key and name cover the defense,
    the ensemble adds the attacks that adapt to it, and a policy that reads nothing is refused."""
    from zodrive.bench.bench import Protocol, bench, black_box_of
    from zodrive.bench.leaderboard import leaderboard_markdown
    from zodrive.errors import ZodriveError

    proto = Protocol("highway-fast", 1, (0.05,), black_box=("uniform-noise",))
    row = bench("baseline:rules", proto, tmp_path / "r", progress=False, envs=1, defense="shield@0.02")
    assert row["defense"] == "shield@0.02" and row["key"].startswith("baseline:rules+defense:shield@0.02:v")
    cells = sorted(p.name for p in (tmp_path / "r" / "cells").iterdir())
    assert cells and all("+shield@0.02-" in name for name in cells)
    summary = json.loads((tmp_path / "r" / "cells" / "baseline-rules+shield@0.02-uniform-noise-eps0.05" /
                          "summary.json").read_text())
    assert summary["defense"] == "shield@0.02"
    assert "| shield@0.02 |" in leaderboard_markdown([row])
    assert black_box_of(proto, "kinematic") == ("uniform-noise", "random-search-smooth")  # knows the filter
    with pytest.raises(ZodriveError, match="does not read the observation"):
        bench("baseline:slower", proto, tmp_path / "s", progress=False, envs=1, defense="shield@0.02")


def test_eps_past_brake_compares_with_the_brake_on_the_same_episodes(tmp_path: Path) -> None:
    """Version 3 compared a policy's first 100 episodes with the brake's 300 (another set of seeds): the
    shielded DQN's 4 % of 100 read as past the brake's 3.7 % of 300, where the brake had 4 % on the same 100."""
    from zodrive.bench.bench import Protocol, bench_row

    proto = Protocol("highway-fast", 100, (0.05,), clean_episodes=300)
    folder = _bench_folder(tmp_path / "a", [_cell("none", 0.0, 10.0, 0.1), _cell("random-search", 0.05, 9.0, 0.1)])
    (folder / "clean").mkdir()
    (folder / "clean" / "table.json").write_text(json.dumps([_cell("none", 0.0, 10.0, 0.1)]))
    crashes = [i >= 100 and i % 2 == 0 for i in range(300)]  # none in the first 100, 33 % over 300
    (GridCell("baseline:slower").folder(folder / "brake") / "episodes.jsonl").write_text("".join(
        json.dumps({"episode": i, "return": 5.0, "crashed": c}) + "\n" for i, c in enumerate(crashes)))
    assert bench_row("m", "k", proto, folder, 100, 300)["eps_collisions_pass_brake"] == 0.0  # 10 % > 0 % there


@pytest.mark.integration
def test_a_capped_protocol_caps_its_black_box_attacks_and_not_pgd(tmp_path: Path) -> None:
    """Version 4: a black-box attack of the row spends at most the protocol's queries on a step; PGD, white-box,
    runs as before (its cells are those of the earlier version, reused)."""
    from zodrive.bench.bench import Protocol, bench

    proto = Protocol("highway-fast", 1, (0.05,), black_box=("random-search",), query_budget=42, version=4)
    row = bench(str(MODEL), proto, tmp_path / "r", progress=False, envs=1)
    cells = {p.name: p for p in (tmp_path / "r" / "cells").iterdir()}
    capped = json.loads((cells["ppo-highway-fast-random-search-eps0.05-qb42"] / "summary.json").read_text())
    assert 0 < capped["queries_per_step"] <= 42 and capped["attack_config"]["query_budget"] == 42
    pgd = json.loads((cells["ppo-highway-fast-pgd-eps0.05"] / "summary.json").read_text())
    assert pgd["attack_config"]["query_budget"] is None
    assert row["query_budget"] == 42 and row["protocol"] == "highway-fast-v4"
    assert row["attacked"][0]["queries_to_crash"] is None or row["attacked"][0]["queries_to_crash"] > 0


@pytest.mark.integration
def test_a_row_of_an_earlier_version_gives_way_and_keeps_the_cells_both_share(tmp_path: Path, monkeypatch) -> None:
    from zodrive.bench.bench import Protocol, bench

    old = Protocol("highway-fast", 1, (0.05,), black_box=("uniform-noise",), version=3)
    bench("baseline:rules", old, tmp_path / "r", progress=False, envs=1)
    import zodrive.evaluation.evaluate as evaluation

    ran: list[object] = []
    original = evaluation.run_episodes
    monkeypatch.setattr(evaluation, "run_episodes", lambda job, *a, **k: ran.append(job.attack) or original(job, *a, **k))
    new = Protocol("highway-fast", 1, (0.05,), black_box=("uniform-noise",), query_budget=7, version=4)
    row = bench("baseline:rules", new, tmp_path / "r", progress=False, envs=1)
    assert row["protocol"] == "highway-fast-v4"
    names = sorted(p.name for p in (tmp_path / "r" / "cells").iterdir())
    assert names == ["baseline-rules-none", "baseline-rules-uniform-noise-eps0.05-qb7"]  # the uncapped cell is gone
    assert len(ran) == 1 and ran[0].query_budget == 7  # only the capped cell ran: clean ones were reused


def _episodes(folder: Path, returns: list[float]) -> None:
    folder.mkdir(parents=True)
    folder.joinpath("episodes.jsonl").write_text("".join(
        json.dumps({"episode": i, "return": r, "crashed": False, "queries": 1}) + "\n" for i, r in enumerate(returns)))


def test_a_defended_row_is_read_against_its_policy_undefended(tmp_path: Path) -> None:
    from zodrive.bench.leaderboard import _defended, defense_margins

    def row(name: str, key: str, defense: str | None, clean: list[float], attacked: list[float]) -> tuple:
        folder = tmp_path / name
        _episodes(GridCell(name).folder(folder), clean)
        _episodes(GridCell(name, "random-search", 0.05).folder(folder), attacked)
        (folder / "table.json").write_text(json.dumps([{**_cell("random-search", 0.05, 1.0), "model": name}]))
        r = {"protocol": "p-v1", "key": key, "policy": name, "episodes": 4, "clean_episodes": 4,
             "attacked": [{"eps": 0.05, "attack": "random-search", "attack_eps": 0.05}],
             **({"defense": defense} if defense else {})}
        return r, folder

    plain = row("m", "sha256:a", None, [10, 10, 12, 12], [2, 2, 4, 4])
    guarded = row("m+smooth", "sha256:a+defense:smooth@0.05:v1", "smooth@0.05", [9, 10, 11, 12], [8, 9, 8, 9])
    other = row("o+smooth", "sha256:b+defense:smooth@0.05:v1", "smooth@0.05", [1, 1, 1, 1], [1, 1, 1, 1])
    older = row("q", "sha256:c", None, [1, 1, 1, 1], [1, 1, 1, 1])
    older[0]["protocol"] = "p-v0"  # its policy undefended, but under an earlier protocol: no pair, said so
    newer = row("q+smooth", "sha256:c+defense:smooth@0.05:v1", "smooth@0.05", [1, 1, 1, 1], [1, 1, 1, 1])
    defense_margins([plain, guarded, other, older, newer])
    m = guarded[0]["vs_undefended"]
    assert m["policy"] == "m" and m["clean"][0] == pytest.approx(-0.5) and m["attacked"][0] == pytest.approx(5.5)
    assert m["clean"][1] <= -0.5 <= m["clean"][2]
    assert "vs_undefended" not in plain[0]
    assert other[0]["vs_undefended"]["policy"] is None and other[0]["vs_undefended"]["clean"] is None
    text = "\n".join(_defended([plain[0], guarded[0], other[0], newer[0]]))
    assert "| m+smooth | smooth@0.05 | m | -0.50 (" in text and "+5.50 (" in text
    assert "| o+smooth | smooth@0.05 | – (no row of this policy undefended) | – | – |" in text
    assert "| q+smooth | smooth@0.05 | – (q ran p-v0: bench it again to pair) | – | – |" in text


def test_the_frontier_joins_the_rows_no_other_beats_on_both() -> None:
    from zodrive.bench.leaderboard_plot import pareto

    points = [(22.0, 7.0), (20.8, 20.8), (21.5, 21.3), (21.0, 21.0), (7.0, 7.0), (22.0, 6.0)]
    assert pareto(points) == [2, 0]  # (21.5, 21.3) and (22.0, 7.0); (20.8, 20.8) and (21.0, 21.0) are beaten


def test_every_committed_cell_is_found_through_its_typed_cell() -> None:
    """A bench reads its grid only through `GridCell`: each entry of every committed table under results/bench
    (rows, their clean/, the brakes, the tracks; a packed row's made from its cells, `read_table`) gives back its
    cell's folder (a folder or packed) and its own grid entry, label and all; so a row resumes from the cells it
    has, under the names it has."""
    from zodrive.bench.bench import read_table
    from zodrive.evaluation import store

    board = Path(__file__).resolve().parents[1] / "results" / "bench"
    grids = sorted({p.parent for p in (*board.rglob("cells.jsonl.gz"), *board.rglob("table.json"))})
    assert len(grids) > 100
    for grid in grids:
        for entry in read_table(grid):
            cell = GridCell.from_entry(entry)
            assert store.exists(cell.folder(grid)), (grid, entry)
            assert cell.entry(entry["reads"]) == {k: entry[k] for k in cell.entry(entry["reads"])}, (grid, entry)
    assert GridCell("baseline:rules", "pgd", 0.05, None, "shield@0.02", white_box=True).name == \
        "baseline-rules+shield@0.02-pgd-eps0.05"
    assert GridCell.from_entry({"model": "m", "attack": "pgd (white-box)", "eps": 0.1000001, "defense": "none"}) \
        == GridCell("m", "pgd", 0.1000001, white_box=True)


def test_a_row_of_an_earlier_defense_version_says_so_on_the_board() -> None:
    """A defended row keeps the version it ran in its key; where the defense has changed since, the board
    says which version the row measured and which its command runs now (never the current name alone)."""
    from zodrive.bench.leaderboard import defense_cell
    from zodrive.defense import defense_version

    now = defense_version("shield@0.05")
    assert now is not None and now >= 2
    row = {"defense": "shield@0.05", "key": f"sha256:abc+defense:shield@0.05:v{now - 1}"}
    assert defense_cell(row) == f"shield@0.05 v{now - 1} (now v{now})"
    assert defense_cell({**row, "key": f"sha256:abc+defense:shield@0.05:v{now}"}) == "shield@0.05"
    assert defense_cell({"key": "sha256:abc"}) == "–"
