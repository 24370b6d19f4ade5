"""The attack's flags (`--attack`, `--eps`, `--n-directions`, ...), generated from THE attack
schema (`zodrive.attacks.schema.AttackOptions`): one flag per field, named after it (or the
field's `flag`), its help the field's description, its default the schema's, its value parsed
by the field's type and checked by the field's range when the command line is read. A boolean
gets `--NAME` and `--no-NAME`; an option the schema lets clear gets `--no-NAME` too.

`attack_spec_from_args` turns the flags into an `AttackSpec` (`zodrive.attacks.spec`, imported
there: it loads torch, which `zodrive --help` does not need).
"""

from __future__ import annotations

import argparse
import functools
import types
import typing
from dataclasses import dataclass
from typing import Any, Callable, Literal

from pydantic import ValidationError

from zodrive.attacks.schema import AttackOptions, range_text
from zodrive.errors import ZodriveError

FIELDS = AttackOptions.model_fields
ATTACK_FLAG = "--attack"  # names the attack (`attack`) and, as NAME:DIR, its trained folder (`adversary`)


@dataclass(frozen=True)
class AttackFlag:
    """A flag of the schema's field `field`: `flag` on the command line, `dest` in the parsed
    arguments; `clears` for a `--no-NAME` that sets the field back to none."""

    field: str
    flag: str
    dest: str
    clears: bool = False


def _extra(name: str) -> dict[str, Any]:
    extra = FIELDS[name].json_schema_extra
    return extra if isinstance(extra, dict) else {}


def flag_of(name: str) -> str:
    """The command-line flag of field `name`: `--NAME` with dashes, or the field's own `flag`."""
    return _extra(name).get("flag", "--" + name.replace("_", "-"))


def _kind(name: str) -> Any:
    """The field's type without `Optional`."""
    annotation = FIELDS[name].annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return args[0] if len(args) == 1 else typing.Union[tuple(args)]
    return annotation


def option_type(name: str) -> Callable[[str], Any]:
    """An argparse type for field `name`: its text read as the field's type and checked by the
    schema itself (`AttackOptions`, this field alone), so a bad value stops the command line
    before any work, with the field's range in the message."""
    kind = _kind(name)
    convert, what = (int, "an integer") if _is_int(kind) else (float, "a finite number") if kind is float else (str, "")
    limits = range_text(name)
    what = f"{what} {limits}".strip() if limits else what

    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            AttackOptions.model_validate({name: value})
        except ValidationError as exc:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}" if what else
                                             exc.errors()[0]["msg"].removeprefix("Value error, ")) from None
        return value

    parse.__name__ = name  # argparse names the type in some messages
    return parse


def _is_int(kind: Any) -> bool:
    return kind is int or (typing.get_origin(kind) is typing.Annotated and typing.get_args(kind)[0] is int)


def _is_bool(kind: Any) -> bool:
    return kind is bool or (typing.get_origin(kind) is typing.Annotated and typing.get_args(kind)[0] is bool)


def _names(text: str) -> list[str]:
    """A list of names, comma-separated (`none` or nothing: an empty list)."""
    return [] if text.strip() in ("", "none") else [name.strip() for name in text.split(",")]


def _shown(value: Any) -> str:
    if value is None:
        return "none"
    if isinstance(value, (tuple, list)):
        return ",".join(map(str, value)) or "none"
    return str(value)


def _build() -> tuple[AttackFlag, ...]:
    flags: list[AttackFlag] = []
    for name in FIELDS:
        flag = flag_of(name)
        flags.append(AttackFlag(name, flag, "attack" if flag == ATTACK_FLAG else flag[2:].replace("-", "_")))
        if _is_bool(_kind(name)) or "clear" in _extra(name):
            off, clears = "--no-" + flag[2:], not _is_bool(_kind(name))  # a boolean's off switch sets it False
            flags.append(AttackFlag(name, off, off[2:].replace("-", "_") if clears else name, clears))
    return tuple(flags)


FLAGS = _build()
"""Every attack flag, from the schema: one per field (`--attack` serves `attack` and `adversary`),
and the `--no-NAME` of booleans and of options that can be cleared."""
ATTACK_FLAGS = {"/".join(f.flag for f in FLAGS if f.dest == dest): dest
                for dest in dict.fromkeys(f.dest for f in FLAGS if f.flag != ATTACK_FLAG)}
"""The flags that set an attack's options (each needs an --attack), and where argparse puts them
(`--warm-start/--no-warm-start` share one)."""


@functools.lru_cache(maxsize=1)
def _config_values() -> dict[str, dict[str, list[str]]]:
    """Per option, the shipped attack configs that set it, by the value they set (shown value -> names)."""
    import yaml

    from zodrive.config import available, resolve_path

    found: dict[str, dict[str, list[str]]] = {}
    for name in available("attacks"):
        data = yaml.safe_load(resolve_path(name, "attacks").read_text(encoding="utf-8")) or {}
        for key, value in data.items() if isinstance(data, dict) else ():
            if key in FIELDS and key != "attack":
                found.setdefault(key, {}).setdefault(_shown(value), []).append(name)
    return found


def _default_text(field: str, default: Any) -> str:
    """"(default: X)", and the configs that run with another value (`--patience`: none in the schema, 10 in the
    zo-signsgd config), so that the help never hides what an --attack NAME runs with."""
    other = {value: names for value, names in _config_values().get(field, {}).items() if value != _shown(default)}
    text = f"default: {_shown(default)}" + "".join(
        f"; {value} in the {', '.join(names)} config{'s' if len(names) > 1 else ''}" for value, names in other.items())
    return f"({text})"


def add_attack_flags(parser: argparse.ArgumentParser) -> None:
    """`--attack` and one flag per option of the attack schema."""
    group = parser.add_argument_group(
        "attack (black-box unless the name says otherwise)",
        "options left unset keep the values of the --attack config: the schema's defaults, and where a shipped config "
        "sets another, that config's")
    group.add_argument(ATTACK_FLAG, metavar=_extra("attack").get("metavar"), help=FIELDS["attack"].description)
    for f in FLAGS:
        if f.flag == ATTACK_FLAG:
            continue
        info, kind, extra = FIELDS[f.field], _kind(f.field), _extra(f.field)
        default = info.default
        if _is_bool(kind):
            on = not f.flag.startswith("--no-")
            text = info.description if on else extra["off"]
            assert text is not None  # every option has a description (`option`)
            group.add_argument(f.flag, dest=f.dest, action="store_true" if on else "store_false", default=None,
                               help=text + (" (default)" if default == on else ""))
        elif f.clears:
            group.add_argument(f.flag, dest=f.dest, action="store_true", default=None,
                               help=extra["clear"] + (" (default)" if default is None else ""))
        elif typing.get_origin(kind) is Literal:
            group.add_argument(f.flag, dest=f.dest, choices=typing.get_args(kind), default=None,
                               help=f"{info.description} {_default_text(f.field, default)}")
        elif typing.get_origin(kind) is tuple and typing.get_args(kind) == (str, Ellipsis):
            group.add_argument(f.flag, dest=f.dest, type=_names, default=None,
                               metavar=f"{extra.get('metavar', 'NAME')},...",
                               help=f"{info.description} {_default_text(f.field, default)}")
        else:
            group.add_argument(f.flag, dest=f.dest, type=option_type(f.field), default=None,
                               metavar=extra.get("metavar"),
                               help=f"{info.description} {_default_text(f.field, default)}")


def attack_spec_from_args(args: argparse.Namespace) -> Any:
    """The AttackSpec named by --attack with the CLI's flags on top (None without --attack)."""
    from zodrive.attacks.spec import load_attack

    if args.attack is not None and not args.attack.strip():
        raise ZodriveError("--attack '' names no attack: give one (zodrive evaluate --help lists them), or drop "
                           "--attack for a clean run")
    if not args.attack:
        given = [flag for flag, dest in ATTACK_FLAGS.items() if getattr(args, dest, None) is not None]
        if given:
            raise ZodriveError(f"{', '.join(given)} set an attack's options, but no --attack was given")
        return None
    cleared = [f for f in FLAGS if f.clears and getattr(args, f.dest)]
    for off in cleared:
        on = flag_of(off.field)
        if getattr(args, next(f.dest for f in FLAGS if f.flag == on)) is not None:
            raise ZodriveError(f"{on} {_extra(off.field).get('metavar', 'VALUE')} and {off.flag} contradict each "
                               "other: give one")
    values = {f.field: getattr(args, f.dest) for f in FLAGS
              if f.flag != ATTACK_FLAG and not f.flag.startswith("--no-")}
    spec = load_attack(args.attack).with_overrides(**values)
    return spec.with_overrides(clear=[f.field for f in cleared]) if cleared else spec
