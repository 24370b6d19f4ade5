"""Fit a picker for vertex hold (`zodrive picker-train`; the attack side is `zodrive.attacks.picker`).

The picker is a classifier of "the victim takes the target on this observation", fitted from counted
queries in rounds on the states the attack itself leads to (DAgger's remedy; docs/attacks.md, "With a
picker"). Training episodes use environment seeds 10000 * seed + 1000 * round + episode, below 50000 for
seeds 0-4: zodrive's training range (`zodrive.seeds`), apart from tuning and evaluation seeds.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from zodrive.errors import ZodriveError

if TYPE_CHECKING:
    import torch

HELD_OUT = 0.05  # the share of labelled vertices kept out of the fit to report its accuracy
BATCH, LEARNING_RATE = 4096, 1e-3


@dataclass(frozen=True)
class PickerFit:
    """How a picker is fitted (`zodrive picker-train` flags of the same names). The defaults are the
    settings chosen on models/dqn-close at eps 0.02, tuning seeds 900000-900029
    (results/learned-adversary/pilots/one-query)."""

    rounds: int = 3         # rounds of driving, querying and refitting
    episodes: int = 20      # training episodes driven per round
    probes: int = 512       # random vertices queried at every state met
    epochs: int = 10        # passes over all labelled vertices per round
    width: int = 512        # hidden units of each of the MLP's two layers
    candidates: int = 64    # random vertices ranked at attack time when a vertex is needed
    switch: float = 0.3     # a held vertex rated below this at the new state is replaced

    def check(self) -> None:
        from zodrive.attacks.picker import MAX_CANDIDATES, MAX_WIDTH

        for name, most in (("rounds", 10), ("episodes", 1000), ("probes", 1_000_000), ("epochs", 1000),
                           ("width", MAX_WIDTH), ("candidates", MAX_CANDIDATES)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= most):
                raise ZodriveError(f"picker {name} must be an integer from 1 to {most}, not {value!r}")
        if not (isinstance(self.switch, (int, float)) and not isinstance(self.switch, bool) and 0 <= self.switch < 1):
            raise ZodriveError(f"picker switch must be a probability in [0, 1), not {self.switch!r}")


def _fit(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, held: torch.Tensor, epochs: int) -> float:
    """Binary cross-entropy on the rows not `held` out, in shuffled batches; returns the accuracy on the
    held-out rows. (A listwise term per state, `--loss rank`, changed nothing on dqn-close and was removed:
    results/vertex-hold/picker/README.md.)"""
    import torch

    from zodrive.training.amortized import adam_epochs

    bce = torch.nn.functional.binary_cross_entropy_with_logits
    net.train()
    fit_x, fit_y = x[~held], y[~held]
    adam_epochs(list(net.parameters()), lambda i: bce(net(fit_x[i]).squeeze(1), fit_y[i]), len(fit_x), epochs, None,
                LEARNING_RATE, BATCH)
    net.eval()
    with torch.no_grad():
        right = (net(x[held]).squeeze(1) > 0) == (y[held] > 0.5)
    return float(right.float().mean()) if len(right) else float("nan")


def picker_train(model: str, preset: dict[str, Any], eps: float, out: Path, fit: PickerFit = PickerFit(), *,
                 seed: int = 0, force: bool = False, report: Callable[[str], None] | None = None) -> Path:
    """Fit a picker against `model` (a model file) at L-inf `eps` for the search attacks' default target
    (auto: FASTER / [1, 0.5]), write the folder `out` and return it. `report` receives a line per round."""
    import torch

    from zodrive.attacks.picker import FORMAT, META_FILE, WEIGHTS_FILE, Picker, network, objective_target
    from zodrive.policies.policy import resolve
    from zodrive.system import load_policy
    from zodrive.training.recipes import check_run_folder
    from zodrive.attacks.spec import AttackSpec
    from zodrive.envs import attack_context, make_env
    from zodrive.evaluation.rollout import to_action
    from zodrive.runinfo import sha256, write_atomic, write_json, write_run_info

    fit.check()
    if not (isinstance(seed, int) and 0 <= seed <= 4):
        raise ZodriveError(f"picker seed must be 0-4, not {seed!r}: its training episodes (10000 * seed + ...) "
                           "stay below 50000, apart from tuning and evaluation seeds")
    if not (isinstance(eps, float) and np.isfinite(eps) and eps > 0):
        raise ZodriveError(f"eps must be > 0, not {eps}")
    if resolve(model).kind != "model":
        raise ZodriveError("picker-train attacks a model file (SB3 zip or model folder): a picker is tied to the "
                           "file it was fitted against by its SHA-256")
    check_run_folder(out, resume=False, force=force, resumable=False)
    victim = load_policy(model, preset, None)  # the safe loader
    context = attack_context(preset)
    spec = AttackSpec(attack="vertex-hold", eps=eps, seed=seed)
    attack, objective, oracle = spec.build(victim, context["features"], context["bounds"], context["n_actions"],
                                           context.get("action_names"), context.get("action_bounds"))
    threat = attack.threat
    env = make_env(preset)
    assert env.observation_space.shape is not None  # a Box (presets refuse others)
    shape = tuple(env.observation_space.shape)
    mask = threat.mask(shape)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = network(int(np.prod(shape)), fit.width)
    signs = np.array([-eps, eps], dtype=np.float32)
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    held: list[np.ndarray] = []  # each labelled vertex is held out, or not, once: when it is labelled
    rounds: list[dict[str, Any]] = []
    start = time.perf_counter()
    for r in range(fit.rounds):
        returns, steps, taken = [], 0, 0
        for e in range(fit.episodes):
            episode_seed = 10_000 * seed + 1000 * r + e
            obs, _ = env.reset(seed=episode_seed)
            attack.reseed(episode_seed)
            oracle.begin_episode()
            done, total = False, 0.0
            while not done:
                x = np.asarray(obs, dtype=np.float32)[None]
                result = attack.perturb(x, oracle, objective)
                taken += int(result.success[0])
                probes = threat.project(x + rng.choice(signs, size=(fit.probes, *shape)) * mask,
                                        np.repeat(x, fit.probes, axis=0)).astype(np.float32)
                answers = torch.from_numpy(np.asarray(oracle(probes, np.zeros(fit.probes, dtype=np.int64)),
                                                      dtype=np.float32))
                xs.append(probes.reshape(fit.probes, -1))
                ys.append(objective.success(answers[None], answers[:1])[0].numpy())
                obs, reward, terminated, truncated, _ = env.step(to_action(victim, result.adv_outputs,
                                                                           env.action_space))
                total += float(reward)
                steps += 1
                done = terminated or truncated
            returns.append(total)
        x_all = torch.from_numpy(np.concatenate(xs))
        y_all = torch.from_numpy(np.concatenate(ys).astype(np.float32))
        held.append(rng.random(len(y_all) - sum(map(len, held))) < HELD_OUT)
        accuracy = _fit(net, x_all, y_all, torch.from_numpy(np.concatenate(held)), fit.epochs)
        attack.use_picker(Picker(net, fit.candidates, float(fit.switch)), objective_target(objective))  # type: ignore[attr-defined]
        rounds.append({"round": r, "episodes": fit.episodes, "steps": steps, "victim_return": float(np.mean(returns)),
                       "target_share": taken / max(steps, 1), "labelled": len(y_all),
                       "label_share": float(y_all.mean()), "held_out_accuracy": accuracy,
                       "queries": int(oracle.total_queries)})
        if report is not None:
            report(round_line(rounds[-1]))
    env.close()
    out.mkdir(parents=True, exist_ok=True)
    for stale in (WEIGHTS_FILE, META_FILE, "train.json", "CARD.md"):
        (out / stale).unlink(missing_ok=True)  # --force: nothing of an older run is mistaken for this one's
    write_run_info(out, {"victim": str(model), "preset": preset, "eps": eps, "fit": asdict(fit)}, seed)
    tmp = out / f".{WEIGHTS_FILE}.tmp"
    torch.save(net.state_dict(), tmp)
    tmp.replace(out / WEIGHTS_FILE)
    meta = {"format": FORMAT, "victim": str(model), "victim_sha256": sha256(Path(resolve(model).ref)),
            "preset": preset, "eps": eps, "norm": threat.norm, "frozen": list(threat.frozen),
            **objective_target(objective), "obs_shape": list(shape), "width": fit.width,
            "candidates": fit.candidates, "switch": float(fit.switch)}
    train = {"kind": "picker for vertex hold", "victim": str(model), "eps": eps, "seed": seed, "target": spec.target,
             "fit": asdict(fit),
             "rounds": rounds, "victim_queries": int(oracle.total_queries),
             "wall_time_s": round(time.perf_counter() - start, 1)}
    write_json(out / "train.json", train)
    write_atomic(out / META_FILE, json.dumps(meta, indent=2) + "\n")
    write_atomic(out / "CARD.md", _card(out, meta, train))
    return out


def round_line(r: dict[str, Any]) -> str:
    """One round of a fit, as picker-train prints it and the card lists it."""
    return (f"round {r['round']}: {r['steps']} steps under vertex hold{' with the picker' if r['round'] else ''}, "
            f"victim return {r['victim_return']:.2f}, target taken on {r['target_share']:.1%} of steps; "
            f"{r['labelled']} labelled vertices ({r['label_share']:.1%} take the target), picker right on "
            f"{r['held_out_accuracy']:.1%} of {HELD_OUT:.0%} held out; {r['queries']} queries so far")


def _card(out: Path, meta: dict[str, Any], train: dict[str, Any]) -> str:
    fit = train["fit"]
    return "\n".join([
        f"# Picker for vertex hold: {meta['victim']} at L-inf eps {meta['eps']:g}", "",
        "A classifier of whether the victim takes the target "
        f"({meta['target']!r}) on an observation, fitted from counted victim queries "
        "(`zodrive.training.picker`). `--attack vertex-hold:DIR` feeds the best-rated of "
        f"{fit['candidates']} random vertices where it needs a new one, and it replaces a held vertex rated below "
        f"{fit['switch']:g}. That is still one victim query per step.", "",
        f"- victim: `{meta['victim']}` (SHA-256 {meta['victim_sha256'][:16]}..), preset {meta['preset'].get('name')}",
        f"- fit: seed {train['seed']}, {fit['rounds']} rounds of {fit['episodes']} training episodes, "
        f"{fit['probes']} random vertices queried per state, MLP {fit['width']}x{fit['width']}, "
        f"{fit['epochs']} epochs per round; {train['victim_queries']} victim queries, {train['wall_time_s']} s",
        *[f"  - {round_line(r)}" for r in train["rounds"]], "",
        f"Use: `zodrive evaluate {meta['victim']} --attack vertex-hold:{out} --eps {meta['eps']:g}` on the preset "
        "it was fitted on (config.yaml: a picker is refused elsewhere)", "",
    ])
