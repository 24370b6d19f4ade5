"""Fit a surrogate of a victim from its observed behaviour (`zodrive surrogate-train`; the attack side is
`zodrive.attacks.transfer`).

The victim drives clean episodes on tuning seeds (from 50000 + 10000 * seed: never training seeds, never
evaluation seeds 100000+); the attacker watches each observation and the action taken, and fits an MLP to
those actions by cross-entropy (behaviour cloning). Watching is observation, not a query: no point is
chosen by the attacker, and the victim sees nothing it would not have seen driving. The folder records
how many decisions were watched and how often the surrogate agrees with the victim on the decisions of
held-out episodes (the last `held_out` of them, never fitted on).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from zodrive.errors import ZodriveError
from zodrive.seeds import TUNING_SEED

LEARNING_RATE, BATCH = 1e-3, 256


@dataclass(frozen=True)
class SurrogateFit:
    """How a surrogate is fitted (`zodrive surrogate-train` flags of the same names)."""

    episodes: int = 100     # clean episodes of the victim watched, the held-out ones included
    held_out: int = 20      # of them, the last ones: agreement measured there, never fitted on
    epochs: int = 200       # passes over the watched decisions
    width: int = 256        # hidden units of each of the MLP's two layers

    def check(self) -> None:
        from zodrive.attacks.transfer import MAX_WIDTH

        for name, least, most in (("episodes", 2, 10_000), ("held_out", 1, 9_999), ("epochs", 1, 10_000),
                                  ("width", 1, MAX_WIDTH)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and least <= value <= most):
                raise ZodriveError(f"surrogate {name.replace('_', '-')} must be an integer from {least} to {most}, "
                                   f"not {value!r}")
        if self.held_out >= self.episodes:
            raise ZodriveError(f"held-out episodes ({self.held_out}) leave none of {self.episodes} to fit on")


def first_seed(seed: int) -> int:
    """The first tuning seed a fit with `seed` watches: 50000 + 10000 * seed (seeds 0-4 stay below 100000)."""
    return TUNING_SEED + 10_000 * seed


def surrogate_train(model: str, preset: dict[str, Any], out: Path, fit: SurrogateFit = SurrogateFit(), *,
                    seed: int = 0, trust: bool = False, force: bool = False,
                    report: Callable[[str], None] | None = None) -> Path:
    """Fit a surrogate of `model` (a model file) on `preset` from its clean decisions, write the folder
    `out` and return it. `trust` reads an SB3 zip with SB3's own loader (it unpickles the victim's file;
    the surrogate written is plain arrays either way)."""
    import torch

    from zodrive.attacks.transfer import FORMAT, META_FILE, WEIGHTS_FILE, network, save_weights
    from zodrive.envs import action_kind, make_env, n_actions
    from zodrive.evaluation.rollout import act
    from zodrive.policies.policy import resolve
    from zodrive.runinfo import sha256, write_atomic, write_json, write_run_info
    from zodrive.system import load_policy
    from zodrive.training.amortized import adam_epochs
    from zodrive.training.recipes import check_run_folder

    fit.check()
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed <= 4):
        raise ZodriveError(f"surrogate seed must be 0-4, not {seed!r}: its episodes (50000 + 10000 * seed + ...) "
                           "stay on tuning seeds, below the evaluation seeds 100000+")
    if resolve(model).kind != "model":
        raise ZodriveError("surrogate-train watches a model file (SB3 zip or model folder): a surrogate is tied to "
                           "the file it was fitted to by its SHA-256")
    if action_kind(preset) != "discrete":
        raise ZodriveError("surrogate-train clones discrete decisions (a classifier over actions); this preset's "
                           "actions are continuous")
    check_run_folder(out, resume=False, force=force, resumable=False)
    victim = load_policy(model, preset, None, trust=trust)
    env = make_env(preset)
    assert env.observation_space.shape is not None  # a Box (presets refuse others)
    shape = tuple(env.observation_space.shape)
    actions = n_actions(preset)
    start = time.perf_counter()
    xs: list[np.ndarray] = []
    ys: list[int] = []
    episode_of: list[int] = []
    returns = []
    for e in range(fit.episodes):
        obs, _ = env.reset(seed=first_seed(seed) + e)
        done, total = False, 0.0
        while not done:
            action = act(victim, np.asarray(obs, dtype=np.float32), env.action_space)  # the victim drives: watched
            xs.append(np.asarray(obs, dtype=np.float32).reshape(-1))
            ys.append(int(action))
            episode_of.append(e)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    env.close()
    x = torch.from_numpy(np.stack(xs))
    y = torch.tensor(ys, dtype=torch.int64)
    held = torch.from_numpy(np.array(episode_of) >= fit.episodes - fit.held_out)
    torch.manual_seed(seed)
    net = network(int(np.prod(shape)), [fit.width, fit.width], actions)
    ce = torch.nn.functional.cross_entropy
    fit_x, fit_y = x[~held], y[~held]
    loss = adam_epochs(list(net.parameters()), lambda i: ce(net(fit_x[i]), fit_y[i]), len(fit_x), fit.epochs,
                       torch.Generator().manual_seed(seed), LEARNING_RATE, BATCH)
    net.eval()
    with torch.no_grad():
        agree_fit = float((net(fit_x).argmax(dim=1) == fit_y).float().mean())
        agree_held = float((net(x[held]).argmax(dim=1) == y[held]).float().mean())
    counts = np.bincount(np.array(ys), minlength=actions)
    # the floor to read agreement against: the fitted decisions' most frequent action, always
    majority = float((y[held] == int(np.bincount(fit_y.numpy(), minlength=actions).argmax())).float().mean())
    out.mkdir(parents=True, exist_ok=True)
    for stale in (WEIGHTS_FILE, META_FILE, "train.json", "CARD.md"):
        (out / stale).unlink(missing_ok=True)  # --force: nothing of an older fit is mistaken for this one's
    write_run_info(out, {"victim": str(model), "preset": preset, "fit": asdict(fit)}, seed)
    tmp = out / f".{WEIGHTS_FILE}.tmp"
    save_weights(net, tmp)
    tmp.replace(out / WEIGHTS_FILE)
    meta = {"format": FORMAT, "victim": str(model), "victim_sha256": sha256(Path(resolve(model).ref)),
            "preset": preset, "obs_shape": list(shape), "n_actions": actions, "widths": [fit.width, fit.width]}
    train = {"kind": "surrogate for transfer (behaviour cloning)", "victim": str(model), "seed": seed,
             "seeds": [first_seed(seed), first_seed(seed) + fit.episodes - 1], "fit": asdict(fit),
             "victim_decisions_watched": len(ys), "fitted_decisions": int((~held).sum()),
             "held_out_decisions": int(held.sum()), "victim_queries": 0,
             "victim_return": float(np.mean(returns)), "action_counts": counts.tolist(),
             "final_loss": loss, "agreement_fitted": agree_fit, "agreement_held_out": agree_held,
             "majority_held_out": majority, "wall_time_s": round(time.perf_counter() - start, 1)}
    write_json(out / "train.json", train)
    write_atomic(out / META_FILE, json.dumps(meta, indent=2) + "\n")
    write_atomic(out / "CARD.md", _card(out, meta, train))
    if report is not None:
        report(fit_line(train))
    return out


def fit_line(train: dict[str, Any]) -> str:
    """What a fit watched and how well it agrees, as surrogate-train prints it and the card says it."""
    first, last = train["seeds"]
    return (f"watched {train['victim_decisions_watched']} decisions of the victim's clean episodes on tuning seeds "
            f"{first}-{last} (0 victim queries); fitted on {train['fitted_decisions']}; agrees with the victim on "
            f"{train['agreement_held_out']:.1%} of the {train['held_out_decisions']} decisions of the "
            f"{train['fit']['held_out']} held-out episodes (its most frequent action alone: "
            f"{train['majority_held_out']:.1%}), on {train['agreement_fitted']:.1%} of those fitted")


def _card(out: Path, meta: dict[str, Any], train: dict[str, Any]) -> str:
    from zodrive.runinfo import command_line

    fit = train["fit"]
    return "\n".join([
        f"# Surrogate for transfer: {meta['victim']}", "",
        "An MLP fitted by behaviour cloning to the actions the victim took in its own clean episodes "
        "(`zodrive.training.surrogate`). `--attack transfer:DIR` runs PGD on it and feeds the result: "
        "0 victim queries per step.", "",
        f"- victim: `{meta['victim']}` (SHA-256 {meta['victim_sha256'][:16]}..), preset {meta['preset'].get('name')}",
        f"- made by: `{command_line()}`",
        f"- fit: seed {train['seed']}, {fit['episodes']} clean episodes ({fit['held_out']} held out), MLP "
        f"{fit['width']}x{fit['width']}, {fit['epochs']} epochs; {train['wall_time_s']} s",
        f"- {fit_line(train)}", "",
        f"Use: `zodrive evaluate {meta['victim']} --preset {meta['preset'].get('name')} --attack transfer:{out} "
        "--eps EPS` (on the preset it was fitted on: a surrogate is refused elsewhere)", "",
    ])
