"""Making models: `train`, `adv-train`, `robust-train`, `attack-train`, `picker-train`, `surrogate-train`,
`select`, `export`.

The commands import the training code (torch, stable-baselines3, highway-env) inside their
functions: `zodrive --help` builds these parsers without loading it.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from zodrive.cli.attack import option_type
from zodrive.cli.common import (
    episode_count,
    defense_name, env_set_flag, nonnegative_float, nonnegative_int, positive_float, positive_int, preset_of,
    probability_below_one, progress_flag, refuse_nonempty, scenario_flags, seed_number, trust_flag, workers_flag,
)
from zodrive.errors import ZodriveError
from zodrive.training.picker import PickerFit  # torch-free
from zodrive.training.surrogate import SurrogateFit  # torch-free

VICTIM_HELP = "SB3 zip or model folder: the victim (fixed)"
PRESET_HELP = ("preset the model trains on (default: where its run folder or rl-zoo3 / Hugging Face files say it was "
               "trained; a model that says nothing needs it)")


def add_parsers(sub: Any) -> None:
    train = sub.add_parser("train", help="train a DQN, DDPG or TD3 agent")
    train.add_argument("--algo", choices=["dqn", "ddpg", "td3"], required=True, help="the algorithm")
    train.add_argument("--recipe", help="recipe name or YAML (default: the tuned recipe of --algo)")
    train.add_argument("--seed", type=seed_number, help="training seed (default: the recipe's)")
    train.add_argument("--steps", type=positive_int, help="total timesteps (default: the recipe's budget)")
    train.add_argument("--out", type=Path, required=True, help="run folder")
    train.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                       help="recipe override, e.g. hyperparameters.gamma=0.9 (repeatable)")
    env_set_flag(train)
    train.add_argument("--tensorboard", action="store_true", help="also log to TensorBoard (OUT/tb)")
    train.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    train.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    train.add_argument("--trust-model", action="store_true",
                       help="with --resume: unpickle checkpoints this machine did not sign (a run folder from "
                            "elsewhere; can run code from the files)")
    progress_flag(train)

    adv = sub.add_parser("adv-train", help="adversarial training (paper Algorithm 2)")
    adv.add_argument("model", help="SB3 zip or model folder to continue training")
    adv.add_argument("--attack", help="attack config name/YAML or registry name (default: zo-signsgd)")
    adv.add_argument("--no-attack", action="store_true",
                     help="the control run: the same continued training on clean observations")
    adv.add_argument("--attack-set", action="append", default=[], metavar="KEY=VALUE",
                     help="attack override, e.g. steps=50 (T) or eps=0.1 (repeatable)")
    adv.add_argument("--steps", type=positive_int, required=True, help="training timesteps to add")
    adv.add_argument("--out", type=Path, required=True, help="run folder")
    adv.add_argument("--preset", help=PRESET_HELP)
    env_set_flag(adv)
    adv.add_argument("--seed", type=seed_number, default=1, help="seed of the adversarial phase")
    adv.add_argument("--warmup", type=nonnegative_int, default=1000,
                     help="steps the (attacked) policy acts to fill the empty replay buffer before updates start; "
                          "0 = update from the first step (degrades the policy even without attack)")
    adv.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    trust_flag(adv)
    progress_flag(adv)

    rob = sub.add_parser("robust-train", help="make a trained agent robust (sa: SA-DQN / SA-DDPG, at: Algorithm 2, "
                                              "distill: robust distillation)")
    rob.add_argument("model", help="SB3 zip or model folder to make robust")
    rob.add_argument("--method", choices=["sa", "at", "distill"], required=True,
                     help="sa: SA-DQN / SA-DDPG regularizer; at: Algorithm 2; distill: robust distillation of its own "
                          "(or --teacher's) decisions")
    rob.add_argument("--eps", type=positive_float,
                     help="L-inf radius the agent is trained to withstand (not with distill --kappa 0: plain cloning)")
    rob.add_argument("--steps", type=positive_int, required=True, help="training timesteps to add")
    rob.add_argument("--out", type=Path, required=True, help="run folder")
    rob.add_argument("--kappa", type=nonnegative_float,
                     help="sa, distill: weight of the robustness term "
                          "(SA regularizer; distill: the adversarial CE) (default: 0.5)")
    rob.add_argument("--pgd-steps", type=positive_int, help="sa, distill: PGD steps for the inner max (default: 5)")
    rob.add_argument("--seed", type=seed_number, default=1, help="training seed")
    rob.add_argument("--warmup", type=nonnegative_int, help="sa, at: steps acting before updates start (default: 1000)")
    rob.add_argument("--preset", help=PRESET_HELP)
    env_set_flag(rob)
    rob.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    trust_flag(rob)
    rob.add_argument("--epochs", type=positive_int, help="distill: passes over the collected states (default: 20)")
    rob.add_argument("--teacher", metavar="baseline:NAME",
                     help="distill: an observation-reading baseline that drives and labels "
                          "(default: the model itself); with --dagger also the simulator-reading "
                          "baseline:idm-mobil (a DDPG/TD3 actor's teacher) or baseline:planner (a DQN's)")
    rob.add_argument("--dagger", type=nonnegative_int, metavar="ROUNDS",
                     help="distill: behaviour cloning with DAgger (Ross et al. 2011): "
                          "after the teacher's --steps states, ROUNDS rounds of --steps states the student "
                          "drives into (a DDPG/TD3 student: with the teacher's action with probability "
                          "0.5 ** round), labelled by the teacher; --epochs per refit")
    progress_flag(rob)

    atk = sub.add_parser("attack-train", help="train a learned optimal adversary (SA-RL, Zhang et al. ICLR 2021) "
                                              "against a model; use it with --attack learned:DIR")
    atk.add_argument("model", help=VICTIM_HELP)
    atk.add_argument("--eps", type=option_type("eps"), required=True, help="L-inf radius of the perturbation")
    atk.add_argument("--steps", type=nonnegative_int, required=True,
                     help="environment steps of PPO training (0: the fitted start of --pretrain-rounds alone)")
    atk.add_argument("--pretrain-rounds", type=positive_int,
                     help="first fit the adversary as an amortized transfer attack: rounds of driving under it, "
                          "distilling a surrogate from counted victim queries, fitting the mean action to make the "
                          "surrogate take the target action (zodrive.training.amortized)")
    atk.add_argument("--pretrain-episodes", type=positive_int, help="episodes driven per round (default: 10)")
    atk.add_argument("--pretrain-probes", type=nonnegative_int,
                     help="random points queried per visited state, uniform in the eps-ball, for the surrogate (fitted "
                          "by MSE on the victim's outputs; default: 4)")
    atk.add_argument("--pretrain-margin", type=nonnegative_float,
                     help="the target action must win on the surrogate by this many of the victim's median decision "
                          "gaps (default: 1)")
    atk.add_argument("--target", default="auto", help="with --pretrain-rounds: the per-step target the start is "
                                                      "fitted to, as evaluate's --target (default: auto, FASTER / "
                                                      "'1,0.5'); e.g. FASTER,not:SLOWER")
    atk.add_argument("--explore-std", type=positive_float,
                     help="PPO's exploration: a Gaussian of this std per action dimension (in units of eps), "
                          "redrawn every step, instead of the default gSDE noise (whose std on the highway "
                          "presets is about 1.3-1.9: the eps-box's corners, whatever the mean)")
    atk.add_argument("--critic-warmup", type=positive_int,
                     help="the first N of --steps train PPO's value function only, the actor frozen (keeps a "
                          "fitted start while the critic learns its returns)")
    atk.add_argument("--out", type=Path, required=True, help="the adversary's model folder")
    atk.add_argument("--seed", type=seed_number, default=0, help="training seed (PPO and the environment)")
    atk.add_argument("--defense", type=defense_name, metavar="shield[@EPS]|close-shield[@EPS]",
                     help="train against the defended system (stateless defenses only)")
    atk.add_argument("--reward", choices=["minus", "horizon"], default="minus",
                     help="minus: -(victim's reward); horizon: 1 - reward per step and the steps a crash cuts off "
                          "at once (the same objective, credited when the crash happens)")
    scenario_flags(atk, trust=False)
    atk.add_argument("--force", action="store_true", help="overwrite an adversary already in --out")
    progress_flag(atk)

    pick = sub.add_parser("picker-train", help="fit a picker for vertex hold from counted victim queries: which "
                                                "random vertex to feed; use it with --attack vertex-hold:DIR or "
                                                "vertex-check:DIR")
    pick.add_argument("model", help=VICTIM_HELP)
    pick.add_argument("--eps", type=option_type("eps"), required=True, help="L-inf radius of the perturbation")
    pick.add_argument("--out", type=Path, required=True, help="the picker's folder")
    pick.add_argument("--seed", type=seed_number, default=0, help="fit seed: training episodes 10000*seed + "
                                                                  "1000*round + i")
    for flag, kind, what in (("rounds", positive_int, "rounds of driving under vertex hold, querying, refitting"),
                             ("episodes", positive_int, "training episodes driven per round"),
                             ("probes", positive_int, "random vertices queried at every state met"),
                             ("epochs", positive_int, "passes over the labelled vertices per round"),
                             ("width", positive_int, "hidden units of each of the MLP's two layers"),
                             ("candidates", positive_int, "random vertices ranked at attack time when one is needed"),
                             ("switch", probability_below_one, "a held vertex the picker rates below this is replaced "
                                                               "(0: never)")):
        pick.add_argument(f"--{flag}", type=kind, help=f"{what} (default: {getattr(PickerFit, flag)})")
    scenario_flags(pick, trust=False)
    pick.add_argument("--force", action="store_true", help="overwrite a picker already in --out")

    sur = sub.add_parser("surrogate-train", help="fit a surrogate of a model from its clean decisions on tuning seeds "
                                                  "(watched, not queried); use it with --attack transfer:DIR")
    sur.add_argument("model", help=VICTIM_HELP)
    sur.add_argument("--out", type=Path, required=True, help="the surrogate's folder")
    sur.add_argument("--seed", type=seed_number, default=0, help="fit seed: clean episodes on tuning seeds "
                                                                 "50000 + 10000*seed + i")
    for flag, what in (("episodes", "clean episodes of the victim watched, the held-out ones included"),
                       ("held_out", "of them, the last ones, never fitted on: the agreement is measured there"),
                       ("epochs", "passes over the watched decisions"),
                       ("width", "hidden units of each of the MLP's two layers")):
        sur.add_argument(f"--{flag.replace('_', '-')}", type=positive_int,
                         help=f"{what} (default: {getattr(SurrogateFit, flag)})")
    scenario_flags(sur)
    sur.add_argument("--force", action="store_true", help="overwrite a surrogate already in --out")

    sel = sub.add_parser("select",
                         help="pick a training run's best checkpoint on tuning seeds (never evaluation seeds)")
    sel.add_argument("run", type=Path, help="training run folder (with checkpoints/)")
    sel.add_argument("--episodes", type=episode_count, default=20, help="tuning episodes per checkpoint")
    sel.add_argument("--from-step", type=nonnegative_int, default=0, help="ignore checkpoints before this step")
    workers_flag(sel)
    sel.add_argument("--force", action="store_true", help="replace a selection already in RUN/selected.json")
    progress_flag(sel)

    exp = sub.add_parser("export", help="write a model's acting network as ONNX (a victim format with no pickle)")
    exp.add_argument("model", help="SB3 zip or model folder")
    exp.add_argument("--format", choices=["onnx"], default="onnx", help="the file format")
    exp.add_argument("--out", type=Path, required=True, help="the .onnx file to write")
    exp.add_argument("--force", action="store_true", help="overwrite an existing --out file")


def cmd_train(args: argparse.Namespace) -> int:
    from zodrive.training.recipes import load_recipe, train

    if args.resume and args.force:
        raise ZodriveError("--resume continues the run in --out, --force replaces it: give one of them")
    if args.trust_model and not args.resume:
        raise ZodriveError("--trust-model applies with --resume (a new run unpickles nothing)")
    overrides = list(args.set)
    if args.steps:
        if any(o.strip().startswith("total_timesteps=") for o in overrides):
            raise ZodriveError("--steps and --set total_timesteps=... both set the step budget: give one")
        overrides.append(f"total_timesteps={args.steps}")
    recipe = load_recipe(args.recipe or args.algo, overrides)
    if recipe["algo"] != args.algo:
        raise ZodriveError(f"recipe {args.recipe!r} trains {recipe['algo']}, not {args.algo}")
    path = train(recipe, args.out, seed=args.seed, preset_overrides=args.env_set,
                 progress_bar=not args.no_progress, tensorboard=args.tensorboard,
                 resume=args.resume, force=args.force, trust=args.trust_model)
    print(f"saved {path}")
    return 0


def cmd_adv_train(args: argparse.Namespace) -> int:
    from zodrive.attacks.spec import load_attack
    from zodrive.policies.loading import require_trust
    from zodrive.training.adversarial import adversarial_train

    require_trust(args.model, args.trust_model)  # continued training unpickles: refused before anything is said
    preset = preset_of(args)
    if args.no_attack and (args.attack_set or args.attack):
        raise ZodriveError(f"{'--attack-set' if args.attack_set else '--attack'} has no effect with --no-attack")
    spec = None if args.no_attack else load_attack(args.attack or "zo-signsgd", args.attack_set)
    path = adversarial_train(args.model, preset, spec, args.steps, args.out, seed=args.seed,
                             warmup=args.warmup, progress_bar=not args.no_progress, trust=args.trust_model,
                             force=args.force)
    print(f"saved {path}")
    return 0


def cmd_robust_train(args: argparse.Namespace) -> int:
    from zodrive.training.robust import robust_train

    uses = {"sa": {"kappa", "pgd_steps", "warmup", "trust_model"}, "at": {"warmup", "trust_model"},
            "distill": {"kappa", "pgd_steps", "epochs", "teacher", "dagger"}}[args.method]
    for option in ("kappa", "pgd_steps", "warmup", "epochs", "teacher", "trust_model", "dagger"):
        if getattr(args, option) not in (None, False) and option not in uses:
            raise ZodriveError(f"--{option.replace('_', '-')} has no effect with --method {args.method}")
    kappa = 0.5 if args.kappa is None else args.kappa
    if args.method == "distill" and kappa == 0 and (args.eps is not None or args.pgd_steps is not None):
        raise ZodriveError(f"--{'eps' if args.eps is not None else 'pgd-steps'} has no effect with --kappa 0 "
                           "(plain cloning: no adversarial term)")
    preset = preset_of(args)
    path = robust_train(args.model, preset, args.method, args.eps, args.steps, args.out, seed=args.seed,
                        warmup=1000 if args.warmup is None else args.warmup, kappa=kappa,
                        pgd_steps=args.pgd_steps or 5, progress_bar=not args.no_progress, trust=args.trust_model,
                        force=args.force, teacher=args.teacher, epochs=args.epochs or 20, dagger=args.dagger)
    print(f"saved {path}")
    return 0


def cmd_attack_train(args: argparse.Namespace) -> int:
    from zodrive.training.adversary import attack_train
    from zodrive.training.amortized import Pretrain, surrogate_fit

    preset = preset_of(args)
    given = {name: value for name, value in (("episodes", args.pretrain_episodes), ("margin", args.pretrain_margin),
                                            ("probes", args.pretrain_probes))
             if value is not None}
    pretrain = Pretrain(rounds=args.pretrain_rounds, **given) if args.pretrain_rounds else None
    if pretrain is None and given:
        raise ZodriveError(f"--pretrain-{next(iter(given))} applies with --pretrain-rounds")
    if pretrain is None and args.steps == 0:
        raise ZodriveError("--steps 0 trains nothing: give PPO steps, or a fitted start with --pretrain-rounds")
    path = attack_train(str(args.model), preset, args.eps, args.steps, args.out, seed=args.seed, defense=args.defense,
                        reward=args.reward, pretrain=pretrain,
                        target=args.target, explore_std=args.explore_std,
                        critic_warmup=args.critic_warmup or 0, force=args.force, progress_bar=not args.no_progress)
    train = json.loads((path / "train.json").read_text())
    for r in (train["pretrain"] or {}).get("rounds", []):
        print(f"pretrain round {r['round']}: {r['steps']} steps, victim return {r['victim_return']:.2f}, target action "
              f"on {r['target_share']:.1%} of steps, {r['queries']} queries so far, {surrogate_fit(r)}; fitted: "
              f"target on the surrogate on {r['surrogate_target_share']:.1%} of visited states")
    if train["total_timesteps"]:
        print(f"{train['total_timesteps']} steps, {train['episodes']} episodes in {train['wall_time_s']} s; victim "
              f"queries {train['victim_queries']} ({train['queries_per_step']:.2f}/step); victim return over the "
              f"first / last 10 training episodes: {train['victim_return_first10']} / {train['victim_return_last10']}")
    print(f"saved {path} (use: --attack learned:{path} --eps {args.eps:g})")
    return 0


def cmd_picker_train(args: argparse.Namespace) -> int:
    from zodrive.training.picker import picker_train

    given = {f.name: getattr(args, f.name) for f in fields(PickerFit) if getattr(args, f.name) is not None}
    path = picker_train(str(args.model), preset_of(args), args.eps, args.out, replace(PickerFit(), **given),
                        seed=args.seed, force=args.force, report=lambda line: print(line, flush=True))
    scenario = "".join([f" --preset {args.preset}" if args.preset else "",
                        *(f" --env-set {item}" for item in args.env_set),
                        f" --env-id {args.env_id}" if args.env_id else "",
                        f" --obs-bounds {args.obs_bounds[0]:g},{args.obs_bounds[1]:g}" if args.obs_bounds else ""])
    print(f"saved {path} (use: --attack vertex-hold:{path} --eps {args.eps:g}{scenario})")
    return 0


def cmd_surrogate_train(args: argparse.Namespace) -> int:
    from zodrive.training.surrogate import surrogate_train

    given = {f.name: getattr(args, f.name) for f in fields(SurrogateFit) if getattr(args, f.name) is not None}
    path = surrogate_train(str(args.model), preset_of(args), args.out, replace(SurrogateFit(), **given),
                           seed=args.seed, trust=args.trust_model, force=args.force,
                           report=lambda line: print(line, flush=True))
    scenario = f" --preset {args.preset}" if args.preset else ""
    print(f"saved {path} (use: --attack transfer:{path} --eps EPS{scenario})")
    return 0


def cmd_select(args: argparse.Namespace) -> int:
    from zodrive.experiments.select import select_checkpoint, selection_markdown

    refuse_nonempty(args.run / "selected.json", args.force, "a selection", "")
    choice = select_checkpoint(args.run, args.episodes, from_step=args.from_step, workers=args.workers,
                               progress=not args.no_progress)
    print(selection_markdown(choice), end="")
    print(f"selected: {choice['selected']['model']} ({choice['criterion']}); written to {args.run / 'selected.json'}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from zodrive.policies.onnx_policy import export_onnx

    refuse_nonempty(args.out, args.force, "a file")
    print(f"wrote {export_onnx(args.model, args.out)}")
    return 0


COMMANDS = {"train": cmd_train, "adv-train": cmd_adv_train, "robust-train": cmd_robust_train,
            "attack-train": cmd_attack_train, "picker-train": cmd_picker_train,
            "surrogate-train": cmd_surrogate_train, "select": cmd_select,
            "export": cmd_export}
