"""`zodrive env` (the presets) and `zodrive baselines` (the built-in policies): what there is."""

from __future__ import annotations

import argparse
from typing import Any

import yaml

from zodrive.cli.common import Parser


def add_parsers(sub: Any) -> None:
    env = sub.add_parser("env", help="environment presets: list them, or print one's resolved config")
    env_sub = env.add_subparsers(dest="env_command", required=True, parser_class=Parser)
    show = env_sub.add_parser("show", help="print a preset's resolved config")
    show.add_argument("preset", help="preset name or YAML file (`zodrive env list`)")
    show.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override (deep merge), e.g. highway.lanes_count=3 (repeatable)")
    env_sub.add_parser("list", help="list the presets, one line each")

    sub.add_parser("baselines", help="list the built-in baseline policies (baseline:NAME)")


def cmd_env(args: argparse.Namespace) -> int:
    from zodrive.envs import load_preset, preset_names

    if args.env_command == "list":
        from zodrive.envs import preset_summary

        names = preset_names()
        width = max(map(len, names))
        for name in names:
            print(f"{name:{width}}  {preset_summary(name)}")
        print("any other gymnasium environment with a Box observation: --env-id ID [--obs-bounds LOW,HIGH]")
        return 0
    print(yaml.safe_dump(load_preset(args.preset, args.set), sort_keys=False), end="")
    return 0


def cmd_baselines(args: argparse.Namespace) -> int:
    from zodrive.drivers.baselines import BASELINES, PREFIX

    for b in BASELINES.values():
        print(f"{PREFIX + b.name:22} {'/'.join(b.kinds):20} reads {b.reads:10} {b.description}")
    return 0


COMMANDS = {"env": cmd_env, "baselines": cmd_baselines}
