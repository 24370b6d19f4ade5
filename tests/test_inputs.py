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
