"""The command line's help and the attack schema it is generated from: every option says what it
does, every attack option has its flag and every attack flag its option."""

from __future__ import annotations

import argparse

import pytest

from zodrive.attacks.schema import AttackOptions
from zodrive.cli import build_parser
from zodrive.cli.attack import FLAGS, flag_of

ATTACKED = ("evaluate", "render")  # the commands that take the attack flags


def _subparsers(parser: argparse.ArgumentParser, path: str = "zodrive"):
    """Every (name, parser) below `parser`, nested ones (`env show`) included."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, child in action.choices.items():
                assert helps.get(name), f"{path} {name} has no help line"
                yield from _subparsers(child, f"{path} {name}")


def _attack_group(command: str) -> argparse._ArgumentGroup:
    parser = dict(_subparsers(build_parser()))[f"zodrive {command}"]
    (group,) = [g for g in parser._action_groups if g.title and g.title.startswith("attack")]
    return group


def test_every_option_of_every_command_has_help() -> None:
    missing = [f"{path}: {action.option_strings or action.dest}"
               for path, parser in _subparsers(build_parser()) for action in parser._actions
               if not isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)) and not action.help]
    assert missing == []


def test_help_shows_defaults_once_and_never_for_a_switch() -> None:
    from zodrive.cli.common import Help

    for path, parser in _subparsers(build_parser()):
        for action in parser._actions:
            text = Help(path)._get_help_string(action)
            assert text.count("(default") <= 1, (path, text)  # not "(default 100000) (default: None)"
            for wrong in ("(default: True)", "(default: False)", "(default: None)", "(default: [])"):
                assert wrong not in text, (path, action.option_strings, text)
    evaluate = dict(_subparsers(build_parser()))["zodrive evaluate"].format_help()
    assert "(default: 100)" in " ".join(evaluate.split())  # --episodes
    assert "--no-warm-start start each step's search at the clean observation (default)" in " ".join(evaluate.split())


def test_every_attack_option_has_a_flag_a_description_and_every_flag_an_option() -> None:
    fields = AttackOptions.model_fields
    assert all(info.description and "\n" not in info.description for info in fields.values())
    generated = {f.flag for f in FLAGS}
    assert {flag_of(name) for name in fields} <= generated
    assert {f.field for f in FLAGS} == set(fields)
    for command in ATTACKED:
        flags = {s for action in _attack_group(command)._group_actions for s in action.option_strings}
        assert flags == generated, command  # no flag by hand, none missing


def test_a_flag_is_read_and_checked_by_its_option_s_type_and_range() -> None:
    from zodrive.errors import ZodriveError

    parse = build_parser().parse_args
    args = parse(["evaluate", "m.zip", "--attack", "nes", "--n-directions", "7", "--max-change", "0.5", "--frozen", "none"])
    assert (args.n_directions, args.max_change, args.frozen) == (7, 0.5, [])
    assert parse(["evaluate", "m.zip", "--attack", "nes", "--frozen", "presence,x"]).frozen == ["presence", "x"]
    for flag, value in (("--n-directions", "0"), ("--max-change", "0"), ("--eps", "inf"), ("--steps", "1.5"),
                        ("--attack-seed", "-1"), ("--check-below", "2")):
        with pytest.raises(ZodriveError, match=f"argument {flag}: expected"):
            parse(["evaluate", "m.zip", "--attack", "nes", flag, value])
