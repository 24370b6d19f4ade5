"""Figures of the reproduction: Fig. 2 (loss convergence), Figs. 4/5 (adversarial training)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from zodrive.policies.policy import resolve
from zodrive.attacks.spec import AttackSpec
from zodrive.envs import make_env
from zodrive.evaluation.rollout import clean_states
from zodrive.evaluation.report import headless_pyplot, save_figure
from zodrive.experiments.curves import read_monitor_csv
from zodrive.seeds import TUNING_SEED  # states come from seeds outside the evaluation range
from zodrive.system import build_attacker


def loss_trace(model: str, preset: dict[str, Any], spec: AttackSpec, *, seed: int = TUNING_SEED,
               max_states: int = 200) -> dict[str, Any]:
    """Attack clean-rollout states with early stopping off; return the trace of the first success."""
    victim = resolve(model).victim(preset)
    x0 = clean_states(make_env(preset), victim, seed, max_states)
    attack, objective, oracle = build_attacker(spec, victim, preset)
    result = attack.perturb(x0, oracle, objective, trace=True)
    hits = np.flatnonzero(result.success)
    if hits.size == 0:
        return {"found": False}
    i = int(hits[0])
    return {
        "found": True, "state": i,
        "l1": [float(r["l1"][i]) for r in result.trace],
        "l2": [float(r["l2"][i]) for r in result.trace],
        "linf": float(result.linf[i]),
    }


def plot_loss(traces: dict[str, dict[str, Any]], path: Path) -> None:
    """Fig. 2: L1 (attack loss) and L2 (distortion) per iteration, one panel per agent."""
    plt = headless_pyplot()
    fig, axes = plt.subplots(1, len(traces), figsize=(5 * len(traces), 3.4))
    for ax, (name, trace) in zip(np.atleast_1d(axes), traces.items()):
        if not trace.get("found"):
            ax.text(0.5, 0.5, "no successful step found", ha="center", transform=ax.transAxes)
            continue
        its = np.arange(1, len(trace["l1"]) + 1)
        ax.plot(its, trace["l1"], label="Loss1 (attack)")
        ax.plot(its, trace["l2"], label="Loss2 (distortion)")
        ax.set_xlabel("iteration")
        ax.set_ylabel("loss")
        ax.set_title(f"{name}: ZO-SignSGD on one step")
        ax.legend()
    save_figure(fig, path)


def plot_training_rewards(monitor_csv: Path, path: Path, title: str) -> dict[str, float]:
    """Figs. 4/5: reward per episode during adversarial training, with a moving average."""

    rewards, _ = read_monitor_csv(monitor_csv)
    plt = headless_pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.plot(np.arange(1, len(rewards) + 1), rewards, ".-", alpha=0.5, label="episode reward")
    if len(rewards) >= 5:
        k = max(3, len(rewards) // 10)
        ax.plot(np.arange(k, len(rewards) + 1), np.convolve(rewards, np.ones(k) / k, "valid"), lw=2,
                label=f"moving mean ({k})")
    ax.set_xlabel("episode")
    ax.set_ylabel("reward per episode")
    ax.set_title(title)
    ax.legend()
    save_figure(fig, path)
    return {"episodes": int(len(rewards)),
            "first_half": float(rewards[: len(rewards) // 2].mean()) if len(rewards) > 1 else float("nan"),
            "second_half": float(rewards[len(rewards) // 2 :].mean()) if len(rewards) > 1 else float("nan")}
