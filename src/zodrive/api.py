"""zodrive from Python: three calls for a notebook or a script.

- `evaluate(policy, scenario, attack=None, ...)` drives episodes, clean or attacked, and returns a
  `Result` (summary, per-episode records, a plot);
- `attack(policy, observations, scenario, ...)` attacks a batch of observations once;
- `AttackWrapper(env, policy, attack="random-search", eps=0.05)` attacks what an agent observes
  in any gymnasium environment, reading features, bounds and actions from the environment (the
  engine's own wrapper, `zodrive.system.AttackWrapper`, re-exported here).

`policy` is anything `zodrive.policies.policy.resolve` reads: a model path, `baseline:NAME`,
`FILE.py:NAME`, a stable-baselines3 model, a torch module or a numpy callable. Attack options are
the fields of `AttackSpec` (`eps`, `steps`, `n_directions`, `target`, ...), given as keywords.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from zodrive.attacks.base import AttackResult
from zodrive.attacks.spec import AttackSpec
from zodrive.envs import scenario as scenario_of
from zodrive.errors import ZodriveError
from zodrive.evaluation.evaluate import EvalJob, evaluate as run_evaluation
from zodrive.policies.policy import Policy, resolve
from zodrive.policies.resolve import refuse_unused_shift, resolve_scenario
from zodrive.seeds import EVAL_SEED, MAX_EPISODES
from zodrive.system import AttackWrapper, attack_observations, build_attacker, spec_for

__all__ = ["AttackWrapper", "Result", "attack", "evaluate"]


@dataclass
class Result:
    """What `evaluate` measured: `summary` (as in `summary.json`: mean return with its 95 % CI,
    collision rate, speed, and the attack's success and queries per step) and `episodes` (one
    record per episode, as in `episodes.jsonl`)."""

    summary: dict[str, Any]
    episodes: list[dict[str, Any]] = field(repr=False)

    def __repr__(self) -> str:
        s = self.summary
        attack = f", {s['attack']} eps {s['eps']:g}" if s.get("attack") and s.get("eps") is not None else ""
        return (f"Result({s['model']} on {s['preset']}{attack}: return {s['mean_return']:.2f} "
                f"(95% CI {s['ci95'][0]:.2f}-{s['ci95'][1]:.2f}), collisions {100 * s['collision_rate']:.0f}%, "
                f"{s['episodes']} episodes)")

    def plot(self, path: str | Path | None = None, ax: Any = None) -> Any:
        """Each episode's return, crashes marked, with the mean and its 95 % CI; saved to `path`
        if given. Returns the matplotlib axes."""
        import matplotlib

        if ax is None and path is not None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 3.2))
        returns = np.array([r["return"] for r in self.episodes])
        crashed = np.array([bool(r["crashed"]) for r in self.episodes])
        index = np.arange(len(returns))
        ax.bar(index[~crashed], returns[~crashed], color="tab:blue", label="episode")
        ax.bar(index[crashed], returns[crashed], color="tab:red", label="episode (crashed)")
        low, high = self.summary["ci95"]
        ax.axhspan(low, high, color="0.5", alpha=0.25, label="mean, 95% CI")
        ax.axhline(self.summary["mean_return"], color="0.2", lw=1)
        ax.set_xlabel("episode")
        ax.set_ylabel("episode return")
        import textwrap

        ax.set_title("\n".join(textwrap.wrap(repr(self).removeprefix("Result(").removesuffix(")"), 70)), fontsize=8)
        ax.legend(fontsize=7, loc="lower right")
        if path is not None:
            ax.figure.tight_layout()
            ax.figure.savefig(path, dpi=120)
        return ax


def _scenario(policy: Policy, scenario: str | dict[str, Any] | None, env_id: str | None,
              shifted: bool) -> tuple[dict[str, Any], str | None]:
    """Where `policy` drives, by the CLI's rules (`resolve_scenario`): the scenario named, else
    where its files (or the environment an SB3 model holds) say it was trained; a named scenario
    that differs from that is refused unless `shifted`."""
    found = resolve_scenario(policy, scenario, None, env_id, shifted=shifted)
    if shifted:
        refuse_unused_shift([found[1]], "shifted=True")
    return found


def _check_counts(*, episodes: int, seed: int, envs: int) -> None:
    """The API's numbers, checked as the CLI's flags are, before anything is built or allocated."""
    for name, value, least, most in (("episodes", episodes, 1, MAX_EPISODES), ("seed", seed, 0, 2**63 - 1),
                                     ("envs", envs, 1, 1024)):
        if not isinstance(value, int) or isinstance(value, bool) or not least <= value <= most:
            raise ZodriveError(f"{name} must be an integer in [{least:,}, {most:,}], not {value!r}")


def evaluate(policy: Any, scenario: str | dict[str, Any] | None = None, attack: str | AttackSpec | None = None, *,
             defense: str | None = None, episodes: int = 10, seed: int = EVAL_SEED, envs: int = 1,
             env_id: str | None = None, out: str | Path | None = None, force: bool = False,
             trust_model: bool = False, progress: bool = False, shifted: bool = False, **options: Any) -> Result:
    """Drive `episodes` episodes from seeds `seed`, `seed + 1`, ..., clean or under `attack`.

    :param policy: a model path, `baseline:NAME`, `FILE.py:NAME`, an SB3 model, a torch module or a callable.
    :param scenario: a preset name (`zodrive env` lists them) or a preset mapping; default: where the model's
        files (or the environment an SB3 model holds) say it was trained.
    :param attack: an attack name (`random-search`, `zo-signsgd`, ...), a config name or an `AttackSpec`.
    :param defense: a runtime defense (`shield`, `shield@0.05`, `kinematic`).
    :param episodes: how many episodes.
    :param seed: the first episode's seed.
    :param envs: episodes driven side by side (their observations attacked in one call); same numbers.
    :param env_id: any gymnasium id instead of `scenario`.
    :param out: a run folder (resumable; policies on disk only).
    :param force: replace another evaluation in `out` (only its own files).
    :param trust_model: read an SB3 zip with SB3's own loader (unpickles: only for files you trust).
    :param progress: show a progress bar.
    :param shifted: measure the policy on `scenario` although its files say it was trained on another one.
    :param options: the attack's options (`eps=0.05`, `steps=50`, ...).
    :returns: the `Result`.
    """
    _check_counts(episodes=episodes, seed=seed, envs=envs)
    resolved = resolve(policy)
    if trust_model and resolved.kind != "model":
        raise ZodriveError(f"trust_model applies to stable-baselines3 zips; {resolved.label} is read without it")
    preset, source = _scenario(resolved, scenario, env_id, shifted)
    spec = spec_for(attack, scenario_of(preset), options)
    if resolved.in_memory and out is not None:
        raise ZodriveError(f"{resolved.label} lives in memory: a run folder is keyed on a model's content; "
                           "save the model and pass its path to write and resume a run folder")
    job = EvalJob(resolved, preset, spec, seed=seed, defense=defense, trust=trust_model, scenario_source=source)
    records: list[dict[str, Any]] = []
    summary = run_evaluation(job, episodes, Path(out) if out is not None else None, envs=envs, progress=progress,
                             records=records, force=force)
    return Result(summary, records)


def attack(policy: Any, observations: np.ndarray, scenario: str | dict[str, Any] | None = None,
           attack: str | AttackSpec = "random-search", *, env_id: str | None = None, seed: int = 0,
           shifted: bool = False, **options: Any) -> AttackResult:
    """Attack a batch of clean observations once (each row its own problem, as one environment
    step of `observations.shape[0]` environments).

    :param policy: anything `evaluate` takes.
    :param observations: clean observations, shape (N, *observation shape) or one observation.
    :param scenario: the preset they come from (its features, bounds and actions define the threat model).
    :param attack: the attack's name or `AttackSpec`.
    :param env_id: any gymnasium id instead of `scenario`.
    :param seed: the attack's random stream.
    :param shifted: as in `evaluate`.
    :param options: the attack's options (`eps=0.05`, ...).
    :returns: `AttackResult`: `x_adv` (what the policy would see), per-row `success`, `queries`, `linf`, ...
    """
    resolved = resolve(policy)
    preset, _ = _scenario(resolved, scenario, env_id, shifted)
    where = scenario_of(preset)
    obs = np.asarray(observations, dtype=np.float32)
    if obs.shape == where.obs_shape:
        obs = obs[None]
    if obs.shape[1:] != where.obs_shape:
        raise ZodriveError(f"observations of shape {obs.shape[1:]} per row; {where.name} gives {where.obs_shape}")
    spec = spec_for(attack, where, {"seed": seed, **options})
    assert spec is not None  # an attack is named
    if spec.sparse_in_time:
        raise ZodriveError("a frequency budget (attack_share, when) chooses steps of an episode; attack() attacks one "
                           "batch of states: use evaluate or AttackWrapper")
    attacker, objective, oracle = build_attacker(spec, resolved.victim(preset), preset)
    attacker.reseed([seed * 1_000_003 + row for row in range(len(obs))])
    result, _ = attack_observations(obs, attacker, objective, oracle)
    return result
