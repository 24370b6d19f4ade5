"""Driving a policy, clean or attacked: `evaluate`, `render`, `demo`, `certify`.

The commands import the evaluation (torch, highway-env) inside their functions: `zodrive --help`
builds these parsers without loading it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from zodrive.cli.attack import add_attack_flags, attack_spec_from_args, option_type
from zodrive.cli.common import (
    episode_count, float_above,
    MODEL_HELP, check_trust, defense_name, envs_flag, envs_of, positive_int, preset_of, progress_flag, scenario_of,
    refuse_nonempty, scenario_flags, seed_number, workers_flag,
)
from zodrive.defense import DEFENSE_NAMES
from zodrive.errors import ZodriveError

SEED_HELP = "first evaluation seed (default: 100000, the evaluation seeds; tuning uses others)"


def add_parsers(sub: Any) -> None:
    ev = sub.add_parser("evaluate", help="evaluate a model, clean or under attack")
    ev.add_argument("model", help=MODEL_HELP)
    scenario_flags(ev)
    ev.add_argument("--episodes", type=episode_count, default=100, help="episodes to run")
    ev.add_argument("--seed", type=seed_number, default=None, help=SEED_HELP)
    ev.add_argument("--out", type=Path, help="results folder (summary.json, episodes.jsonl, steps.jsonl); "
                                             "a folder of the same evaluation resumes")
    ev.add_argument("--force", action="store_true",
                    help="replace another evaluation in --out (only its own files; yours stay)")
    workers_flag(ev)
    envs_flag(ev)
    ev.add_argument("--defense", type=defense_name, metavar="|".join(DEFENSE_NAMES),
                    help="kinematic: filter between the (attacked) sensor and the policy; shield[@EPS]: the "
                         "pessimistic rules at budget EPS (default 0.02) veto unsafe actions; close-shield[@EPS]: the "
                         "same with baseline:close-rules' shorter gap; attacks query the defended system")
    add_attack_flags(ev)
    progress_flag(ev)

    render = sub.add_parser("render", help="render an episode (PNG + GIF), optionally attacked")
    render.add_argument("model", help=MODEL_HELP)
    scenario_flags(render)
    render.add_argument("--seed", type=seed_number, default=None, help="first episode seed (default: 100000)")
    render.add_argument("--out", type=Path, required=True, help="folder for episode.png, episode.gif, episode.json")
    render.add_argument("--defense", type=defense_name, metavar="|".join(DEFENSE_NAMES),
                        help="filter between the (attacked) sensor and the policy; 'perceived' is what passes it")
    render.add_argument("--force", action="store_true", help="overwrite a render already in --out")
    render.add_argument("--until-crash", type=positive_int, default=1, metavar="N",
                        help="try up to N seeds until an episode ends in a collision")
    add_attack_flags(render)
    progress_flag(render)

    demo = sub.add_parser("demo", help="attack the shipped DQN driver for a few episodes and print the result")
    demo.add_argument("--episodes", type=episode_count, default=3, help="episodes, clean and attacked")
    demo.add_argument("--model", default=None, help="model folder or zip (default: the DQN driver shipped inside "
                                                    "the package)")
    demo.add_argument("--out", type=Path, default=Path("results/demo"), help="results folder")

    cert = sub.add_parser("certify", help="share of a model's clean states where no perturbation within eps can "
                                          "change the action (interval bounds; reads the weights: white-box)")
    cert.add_argument("model", help="SB3 / sb3-contrib zip or model folder (MLP policies)")
    cert.add_argument("--eps", nargs="+", type=option_type("eps"), help="L-inf radii to certify (required without "
                                                                        "--row)")
    scenario_flags(cert, trust=False)
    cert.add_argument("--episodes", type=episode_count, default=None,
                      help="clean episodes whose states are certified (default: 5)")
    cert.add_argument("--seed", type=seed_number, default=None, help="first episode seed (default: 100000)")
    cert.add_argument("--tol", type=option_type("tol"),
                      help="continuous policies: a state counts as certified if no action dimension can move more "
                           "(default: 0.2)")
    cert.add_argument("--attack", nargs="+", default=[], metavar="NAME",
                      help="also attack every one of those states on its own (untargeted) with these attacks: their "
                           "success beside the certified share; the gap between them is unknown")
    cert.add_argument("--exact", action="store_true",
                      help="also decide every state completely (a MILP per state, HiGHS): robust, attackable (a "
                           "counterexample the float32 network confirms) or unknown; discrete ReLU MLP policies only")
    cert.add_argument("--time-limit", type=float_above(0.0, True, "a positive number of seconds"), metavar="S",
                      help="--exact: seconds per state before it counts as unknown (default: 10)")
    cert.add_argument("--min-eps", action="store_true",
                      help="--exact: also bisect each state's smallest radius that changes its action (8 more exact "
                           "checks per state at most, started from the verdicts at the --eps radii, up to the largest)")
    cert.add_argument("--out", type=Path, help="folder for certify.json")
    cert.add_argument("--row", type=Path, metavar="FOLDER",
                      help="the exact check of a bench row (results/bench/SCENARIO/NAME) for the leaderboard: its "
                           "protocol's seeds, eps grid, black-box ensemble and query cap, written to FOLDER/exact.json "
                           "(implies --exact; MODEL is the row's policy; docs/bench.md)")
    cert.add_argument("--states", type=positive_int, metavar="N",
                      help="--row: the first N clean states of the row's attacked episodes (default: 100)")
    cert.add_argument("--force", action="store_true", help="overwrite certify.json in --out (exact.json with --row)")


def _check_loss(args: argparse.Namespace, spec: Any, preset: dict[str, Any]) -> None:
    """--loss chooses between the DQN objectives of a targeted attack; elsewhere it does nothing."""
    if spec is None or getattr(args, "loss", None) is None:
        return
    from zodrive.envs import action_kind

    if action_kind(preset) != "discrete":
        raise ZodriveError("--loss chooses the objective of a targeted attack on a discrete policy; this policy "
                           "acts continuously (its objective is the paper's Eq. 6)")
    if str(spec.target).lower() in ("none", "untargeted", "worst"):
        raise ZodriveError("--loss chooses the objective of a targeted attack on a discrete policy; "
                           f"target {spec.target} has no such choice")


def cmd_evaluate(args: argparse.Namespace) -> int:
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob, evaluate
    from zodrive.evaluation.report import format_summary
    from zodrive.policies.policy import resolve
    from zodrive.system import build_attacker

    spec = attack_spec_from_args(args)  # argument mistakes first, before any model is read
    policy = resolve(args.model)  # read once: everything below asks the Policy
    preset, source = scenario_of(args, policy)
    check_trust(args, policy)
    _check_loss(args, spec, preset)
    policy.check(preset, attacked=spec is not None)
    if spec is not None:  # validate the whole attack before any episode runs
        build_attacker(spec, policy.victim(preset, trust=args.trust_model), preset)
    if args.defense is not None:
        from zodrive.defense import make_defense

        make_defense(args.defense, preset)  # the preset must be one the defense understands
    job = EvalJob(model=policy, preset=preset, attack=spec,
                  seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, defense=args.defense,
                  trust=args.trust_model, scenario_source=source)
    if args.force and args.out is None:
        raise ZodriveError("--force replaces an evaluation in --out: give --out")
    summary = evaluate(job, args.episodes, args.out, workers=args.workers, envs=envs_of(args, job),
                       progress=not args.no_progress, force=args.force)
    print(format_summary(summary))
    if args.out:
        print(f"results: {args.out}/summary.json")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED
    from zodrive.evaluation.video import record_episode, save_gif, save_mp4, save_png
    from zodrive.policies.policy import resolve
    from zodrive.runinfo import write_json
    from zodrive.system import make_policy_env

    spec = attack_spec_from_args(args)
    refuse_nonempty(args.out, args.force, "a render")
    preset = preset_of(args)
    check_trust(args)
    _check_loss(args, spec, preset)
    policy = resolve(args.model)
    if spec is not None:
        from zodrive.evaluation.evaluate import check_trained_folder

        check_trained_folder(spec, policy.ref, preset, args.defense)
    victim, env = make_policy_env(policy, preset, spec, render_mode="rgb_array", defense=args.defense,
                                  trust=args.trust_model)
    first = DEFAULT_EVAL_SEED if args.seed is None else args.seed
    for seed in range(first, first + args.until_crash):
        frames, info = record_episode(env, victim, seed, progress=not args.no_progress)
        if info["crashed"]:
            break
    if float(np.asarray(frames[0].image).max()) == 0:
        raise ZodriveError("rendered frames are black: unset SDL_VIDEODRIVER or set it to 'offscreen'")
    title = ((f"{spec.attack} eps={spec.eps} | " if spec else "clean | ")
             + (f"+{args.defense} | " if args.defense else ""))
    if not args.no_progress:
        print(f"drawing {len(frames)} frames (PNG, GIF, MP4)", file=sys.stderr, flush=True)
    save_png(frames, args.out / "episode.png", title=title)
    save_gif(frames, args.out / "episode.gif", title=title)
    mp4 = save_mp4(frames, args.out / "episode.mp4", title=title)
    write_json(args.out / "episode.json", {**info, "attack": spec.to_dict() if spec else None, "defense": args.defense})
    print(f"seed {info['seed']}: return {info['return']:.2f}, {info['length']} steps, "
          f"{'crashed' if info['crashed'] else 'left the road' if info['offroad'] else 'no collision'}"
          f" -> {args.out}/episode.png, episode.gif"
          + (", episode.mp4" if mp4 else " (MP4: pip install 'zodrive[video]')"))
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from zodrive.attacks.spec import load_attack
    from zodrive.config import demo_model
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob, evaluate
    from zodrive.evaluation.report import format_summary, plural
    from zodrive.envs import load_preset
    from zodrive.policies.policy import resolve
    from zodrive.policies.resolve import resolve_preset

    policy = resolve(args.model or str(demo_model()))
    # the shipped driver was trained on the paper's discrete preset (its zip in the package has no folder to say so)
    preset = load_preset("discrete") if args.model is None else resolve_preset(policy, None, [])
    name = "the shipped DQN driver (models/dqn-driver)" if args.model is None else policy.label
    spec = load_attack("zo-signsgd")
    results = {}
    for label, attack in (("clean", None), ("attacked", spec)):
        job = EvalJob(model=policy, preset=preset, attack=attack, seed=DEFAULT_EVAL_SEED)
        print(f"== {label}: {plural(args.episodes, 'episode')} of {name}" + (f" under {spec.attack}" if attack else ""))
        results[label] = evaluate(job, args.episodes, args.out / label, progress=True)
        print(format_summary(results[label]))
    drop = 1 - results["attacked"]["mean_return"] / results["clean"]["mean_return"]
    print(f"== the black-box attack (L-inf eps={spec.eps}) cut the mean return by {drop:.0%} "
          f"({results['clean']['mean_return']:.1f} -> {results['attacked']['mean_return']:.1f}); "
          f"results in {args.out}/")
    print("   target=auto: the paper's target action (FASTER for a DQN, [1, 0.5] for a DDPG).")
    print("   base rate: how often the clean policy already takes the target; success counts only the other steps.")
    print("   queries/step: observations the attacker sent to the policy per decision (black-box cost).")
    return 0


def cmd_certify(args: argparse.Namespace) -> int:
    from zodrive.attacks.registry import ATTACKS
    from zodrive.attacks.spec import load_attack
    from zodrive.evaluation.verify import certify_model
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED
    from zodrive.policies.policy import resolve
    from zodrive.runinfo import command_line, write_json

    policy = resolve(args.model)
    if policy.kind != "model":
        raise ZodriveError("certify bounds an SB3 zip's rebuilt network; baselines, ONNX files and Python "
                           "policies have no network zodrive can read")
    if args.row is not None:
        return _certify_row(args)
    if args.states is not None:
        raise ZodriveError("--states samples a bench row's clean states: give --row")
    if args.eps is None:
        raise ZodriveError("certify needs --eps (or --row, whose protocol says them)")
    args.episodes = 5 if args.episodes is None else args.episodes
    if args.out is not None:
        refuse_nonempty(args.out / "certify.json", args.force, "certificates")
    preset = preset_of(args)
    if args.tol is not None and policy.action_kind() == "discrete":
        raise ZodriveError("--tol applies to continuous policies; a discrete one is certified when its action "
                           "cannot change")
    tol = 0.2 if args.tol is None else args.tol
    if args.time_limit is not None and not args.exact:
        raise ZodriveError("--time-limit bounds each state's exact check: give --exact")
    if args.min_eps and not args.exact:
        raise ZodriveError("--min-eps bisects on the exact check: give --exact")
    if args.exact and policy.action_kind() != "discrete":
        raise ZodriveError("--exact decides discrete policies (DQN, QR-DQN); a continuous actor is not supported")
    for name in args.attack:
        spec = load_attack(name)  # an unknown attack is an error before any episode runs
        if spec.attack not in ATTACKS or not ATTACKS[spec.attack].search:
            raise ZodriveError(f"certify attacks every state on its own, untargeted, beside its certificate: "
                               f"{spec.attack} is no per-state search (use random-search, zo-signsgd, pgd, ...)")
    result = certify_model(policy.ref, preset, args.eps, episodes=args.episodes,
                           seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, tol=tol,
                           attacks=tuple(args.attack),
                           exact_limit=(10.0 if args.time_limit is None else args.time_limit) if args.exact else None,
                           min_eps_steps=MIN_EPS_STEPS if args.min_eps else 0)
    what = ("the action cannot change" if result["kind"] == "discrete"
            else f"no action dimension can move more than {tol}")
    print(f"{result['rows'][0]['states']} states of {args.episodes} clean episodes (seeds {result['seed']}..): "
          f"certified = {what} (CROWN or interval bounds: sound, not complete)")
    for row in result["rows"]:
        print(f"  eps {row['eps']:<8g} certified {row['certified_share']:.1%}")
        for side in row.get("attacks", []):
            label = " (white-box)" if side["white_box"] else ""
            print(f"    {side['attack']}{label}: success {side['success_share']:.1%}, unknown "
                  f"{side['unknown_share']:.1%}, {side['queries_per_state']:.0f} queries/state"
                  + (f", {side['contradictions']} CONTRADICTIONS" if side["contradictions"] else ""))
        if len(row.get("attacks", [])) > 1:
            print(f"    any of them: success {row['any_attack']['success_share']:.1%}, "
                  f"unknown {row['any_attack']['unknown_share']:.1%}")
        if "exact" in row:
            print("    " + _exact_line(row["exact"], row["states"]))
            for side in row.get("attacks", []):
                print(f"      {side['attack']}{' (white-box)' if side['white_box'] else ''}: "
                      + _gap_line(side["vs_exact"]))
            ensemble = row["exact"].get("black_box_ensemble")
            if ensemble and len(ensemble["attacks"]) > 0:
                print(f"      black-box ensemble ({', '.join(ensemble['attacks'])}): " + _gap_line(ensemble))
    if "min_eps" in result:
        print(_min_eps_text(result["min_eps"], list(args.attack)))
    if args.out is not None:
        write_json(args.out / "certify.json", {**result, "command": command_line()})
        print(f"results: {args.out}/certify.json")
    return 0


ROW_FIXES = ("eps", "episodes", "seed", "tol", "out", "preset", "env_id", "obs_bounds", "shifted")
"""What a bench row's protocol fixes for `certify --row` (or what it does not apply to): refused beside it."""


def _certify_row(args: argparse.Namespace) -> int:
    """certify --row: the row's exact check, `exact.json` beside its `row.json` (`zodrive.bench.exact_row`)."""
    from zodrive.bench.exact_row import STATES, TIME_LIMIT, certify_row

    given = [name for name in ROW_FIXES if getattr(args, name, None) not in (None, False)]
    given += ["attack"] * bool(args.attack) + ["env_set"] * bool(args.env_set) + ["min_eps"] * bool(args.min_eps)
    if given:
        raise ZodriveError(f"--row takes its protocol's eps, seeds, scenario and attacks from the row: drop "
                           f"--{given[0].replace('_', '-')}")
    if not (args.row / "row.json").is_file():
        raise ZodriveError(f"--row {args.row}: no bench row there (expected {args.row}/row.json)")
    exact = certify_row(args.model, args.row, state_count=STATES if args.states is None else args.states,
                        time_limit=TIME_LIMIT if args.time_limit is None else args.time_limit, force=args.force)
    print(f"{exact['policy']} ({exact['protocol']}): the first {exact['states']} clean states of episodes "
          f"{exact['seeds'][0]}-{exact['seeds'][1]}; ensemble {', '.join(exact['black_box'])}, untargeted, each state "
          "on its own, " + (f"at most {exact['query_budget']} queries a state" if exact["query_budget"]
                            else "each attack's own query bound"))
    for row in exact["rows"]:
        print(f"  eps {row['eps']:<6g} " + _exact_line({**row, "time_limit": exact["time_limit"]}, exact["states"]))
        for name, gap in row["attacks"].items():
            print(f"    {name}: " + _gap_line(gap))
        print("    black-box ensemble: " + _gap_line(row["ensemble"]))
    print(f"results: {args.row / 'exact.json'}")
    return 0


def _exact_line(exact: dict[str, Any], states: int) -> str:
    """One row of `certify --exact`: the verdicts' counts, their time and any contradiction."""
    close = exact["unknown"] - exact["timed_out"]
    timed = f" ({exact['timed_out']} timed out, {close} too close to call)" if exact["unknown"] else ""
    return (f"exact (MILP, {exact['time_limit']:g} s/state): CROWN-certified {exact['crown_certified']}/{states}, "
            f"robust {exact['robust']}, attackable {exact['attackable']}, unknown {exact['unknown']}{timed}; "
            f"s/state median {exact['seconds_median']:.3f}, max {exact['seconds_max']:.2f}"
            + (f", {exact['contradictions']} CONTRADICTIONS" if exact["contradictions"] else ""))


def _gap_line(gap: dict[str, Any]) -> str:
    """An attack against the exact verdicts: what it found of the attackable states, what it missed."""
    rate = "n/a" if gap["miss_rate"] is None else f"{gap['miss_rate']:.1%}"
    return (f"found {gap['found']}/{gap['attackable']} exactly attackable, missed {gap['missed']} (miss rate {rate})"
            + (f", won {gap['won_unknown']} the exact check left unknown" if gap["won_unknown"] else "")
            + (f", {gap['won_robust']} CONTRADICTIONS (won where exact says robust)" if gap["won_robust"] else ""))


def _min_eps_text(found: dict[str, Any], attacks: list[str]) -> str:
    """The smallest radius that changes each state's action: its quartiles, bracketed by the bisection."""
    def show(v: float | None) -> str:
        return f"> {max(found['grid']):g}" if v is None else f"{v:.4g}"

    bracket = ", ".join(f"{name} [{show(a)}, {show(b)}]" for name, a, b in
                        zip(("q25", "median", "q75"), found["quartiles_lower"], found["quartiles_upper"]))
    lines = [f"  smallest eps that changes the action (exact, bisection: {found['steps']} halvings from the grid "
             f"bracket; {found['checks']} checks, {found['seconds']:.0f} s): {bracket}; no counterexample up to "
             f"{max(found['grid']):g}: {found['beyond_grid']} ({found['unknown_at_max']} of them unknown there), "
             f"bisections stopped by an unknown: {found['stopped']}"
             + (f", {found['broken']} CONTRADICTIONS (robust at a larger eps than attackable)"
                if found["broken"] else "")]
    for name in ["exact", *attacks]:
        q = found["on_grid"][name]
        lines.append(f"    on the grid only, smallest eps {name} changed the action at: q25 {show(q[0])}, median "
                     f"{show(q[1])}, q75 {show(q[2])}")
    return "\n".join(lines)


MIN_EPS_STEPS = 8  # bisection halvings per state for --min-eps: bracket / 256 from the grid's


COMMANDS = {"evaluate": cmd_evaluate, "render": cmd_render, "demo": cmd_demo, "certify": cmd_certify}
