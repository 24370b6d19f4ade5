"""Evaluate a model over fixed seeds, clean or under attack, resumably and in parallel.

Episodes run with seeds S, S+1, ..., the same in every run, so two evaluations of the same
episodes can be compared pair by pair. Per-episode records (`episodes.jsonl`) and per-step
attack records (`steps.jsonl`) are appended as episodes finish; a run interrupted and
started again with the same settings skips the episodes already on disk.
"""

from __future__ import annotations

import json
import logging
import multiprocessing as mp
import os
import queue
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import numpy as np

from zodrive.attacks.base import ENGINE_VERSION
from zodrive.attacks.registry import attack_class
from zodrive.attacks.schema import removed_message, removed_settings, without_removed
from zodrive.attacks.spec import AttackSpec
from zodrive.compute import torch_threads
from zodrive.defense import defense_version, parse_defense
from zodrive.envs import make_env, scenario
from zodrive.errors import ZodriveError
from zodrive.evaluation.report import plural
from zodrive.evaluation.rollout import run_episode, run_lockstep
from zodrive.evaluation.stats import mean_ci, rate_ci, ratio_ci
from zodrive.policies.policy import Policy, resolve
from zodrive.runinfo import (LOCK_FILE, command_line, read_json, read_jsonl, run_lock, to_json, versions,
                             write_atomic, write_json)
from zodrive.seeds import EVAL_SEED
from zodrive.system import build_attacker, defense_applies, load_policy_rows, make_policy_env

log = logging.getLogger(__name__)

DEFAULT_EVAL_SEED = EVAL_SEED


@dataclass(init=False)
class EvalJob:
    """One evaluation, its values resolved once where they came in: the `Policy`, the preset (the
    scenario's config), the `AttackSpec` and the defense (its canonical name). It is written out only
    as its key (`key`: a run folder's `eval_key.json`) and, pickled, for a worker process.

    `model` is a `Policy` or anything `resolve` reads, `attack` an `AttackSpec` or a record of one (read
    by the schema): a text or a record is read here, once, and never again downstream."""

    model: Policy               # what drives
    preset: dict[str, Any]
    attack: AttackSpec | None
    seed: int
    record_steps: bool
    defense: str | None         # e.g. "kinematic": a filter between the (attacked) sensor and the policy
    trust: bool                 # read an SB3 zip with SB3's loader (same outputs; not part of the key)
    scenario_source: str | None  # where a scenario the user did not name came from (summary; not the key)

    def __init__(self, model: Any, preset: dict[str, Any], attack: AttackSpec | Mapping[str, Any] | None = None,
                 seed: int = DEFAULT_EVAL_SEED, record_steps: bool = True, defense: str | None = None,
                 trust: bool = False, scenario_source: str | None = None) -> None:
        self.model = resolve(model)
        self.preset = preset
        self.attack = (attack if attack is None or isinstance(attack, AttackSpec)
                       else AttackSpec.from_mapping(dict(attack), "the evaluation's attack"))
        self.seed, self.record_steps, self.trust, self.scenario_source = seed, record_steps, trust, scenario_source
        self.defense = None if defense is None else parse_defense(defense)  # one system, one key
        defense_applies(self.model, self.defense)  # before any folder is written

    def key(self) -> dict[str, Any]:
        """What must match for a resumed run to reuse episodes on disk: the policy (a model by
        the SHA-256 of its file, so a moved checkout still matches and a swapped file does
        not), the preset, the attack (with the version of the attack engine that ran it) and
        the first seed."""
        attack = None if self.attack is None else {**self.attack.to_dict(), "engine": ENGINE_VERSION}
        key = {"model": self.model.key(), "preset": self.preset, "attack": attack, "seed": self.seed}
        folder = None if self.attack is None else self.attack.folder_digest()
        if folder is not None:  # a refitted trained folder is another attack
            key["adversary"] = folder
        if self.defense is not None:
            key["defense"] = self.defense
            if defense_version(self.defense) is not None:
                key["defense_version"] = defense_version(self.defense)
        return key


DEFAULT_ENVS = 8
"""Episodes a process runs side by side (`--envs`): their observations are attacked in one
call per step. The records are the same for every value; only the time differs."""

_WORKER: dict[str, Any] = {}


def lockstep_blocker(job: EvalJob) -> str | None:
    """Why `job`'s episodes cannot run side by side (None: they can). Lockstep needs a
    policy that reads nothing but the observation and keeps no state between steps (a stateful
    defense runs one filter per row: `RowFilters`)."""
    if job.attack is not None and job.attack.sparse_in_time:
        return "a frequency budget decides an episode's steps one by one"
    if job.model.reads_simulator:
        return f"{job.model.ref} reads its own simulator"
    return None


def _setup(job: EvalJob, envs: int = 1) -> None:
    """Build the policy and its environment(s): one wrapped in the attack (`envs` 1), or
    `envs` plain ones and the attack apart, for lockstep."""
    if envs <= 1:
        victim, env = make_policy_env(job.model, job.preset, job.attack, defense=job.defense, trust=job.trust)
        _WORKER.update(job=job, victim=victim, env=env)
        return
    victim, filters = load_policy_rows(job.model, job.preset, job.defense, trust=job.trust)
    attacker = build_attacker(job.attack, victim, job.preset) if job.attack is not None else None
    _WORKER.update(job=job, victim=victim, envs=[make_env(job.preset) for _ in range(envs)], attacker=attacker,
                   filters=filters)


def _release() -> None:
    """Close the environments `_setup` built in this process and let go of the policy (one in memory
    is the caller's)."""
    for env in [_WORKER.get("env"), *_WORKER.get("envs", ())]:
        if env is not None:
            env.close()
    _WORKER.clear()


def _worker_setup(job: EvalJob, envs: int = 1) -> None:
    """A worker process owns its torch setting: one thread per process. The policy and its
    environment are built by the first episode, so that a failure to build them reaches the
    caller as the error it is (an initializer's failure only breaks the pool)."""
    import torch

    torch.set_num_threads(1)
    _WORKER.clear()
    _WORKER["pending"] = (job, envs)


def _episode(index: int) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    if "pending" in _WORKER:
        _setup(*_WORKER.pop("pending"))
    job: EvalJob = _WORKER["job"]
    env = _WORKER["env"]
    seed = job.seed + index
    steps: list[dict[str, Any]] = []
    record = run_episode(
        env, _WORKER["victim"], episode=index, seed=seed,
        max_return=_max_return(job.preset),
        on_step=steps.append if job.record_steps else None, on_tick=_WORKER.get("tick"),
    )
    return record.to_dict(), steps


def _lockstep(indices: list[int], done: Any = None) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]]]]:
    """This process's episodes `indices`, side by side; (record, step records) as each ends
    (also put on the queue `done`, when a pool worker runs it)."""
    if "pending" in _WORKER:
        _setup(*_WORKER.pop("pending"))
    job: EvalJob = _WORKER["job"]
    steps: dict[int, list[dict[str, Any]]] = {i: [] for i in indices}
    on_step = (lambda row: steps[row["episode"]].append(row)) if job.record_steps else None
    tick = _WORKER.get("tick") if done is None else _Ticks(done)
    for record in run_lockstep(_WORKER["envs"], _WORKER["victim"], [(i, job.seed + i) for i in indices],
                               max_return=_max_return(job.preset), attacker=_WORKER["attacker"], on_step=on_step,
                               on_tick=tick, filters=_WORKER["filters"]):
        item = (record.to_dict(), steps.pop(record.episode))
        if done is not None:
            done.put(item)
        yield item


class _Ticks:
    """A pool worker's environment steps, sent to the parent at most twice a second (its progress bar)."""

    def __init__(self, queue_: Any) -> None:
        self.queue, self.count, self.sent = queue_, 0, time.monotonic()

    def __call__(self, n: int) -> None:
        self.count += n
        if time.monotonic() - self.sent >= 0.5:
            self.queue.put(("tick", self.count))
            self.count, self.sent = 0, time.monotonic()


def _lockstep_share(indices: list[int], done: Any) -> None:
    """A pool worker's share of the episodes, reported one by one through `done`."""
    for _ in _lockstep(indices, done):
        pass


def _max_return(preset: dict[str, Any]) -> float | None:
    return scenario(preset).max_return


def _read_jsonl(path: Path) -> list[dict[str, Any]]:
    """A run's records; a line cut by an interruption ends them (everything after it is redone),
    a record that is not one of an episode is a one-line error naming the file."""
    rows = read_jsonl(path, "run record", needs=("episode",), cut_ok=True)
    for number, row in enumerate(rows, start=1):
        if not isinstance(row["episode"], int) or isinstance(row["episode"], bool) or row["episode"] < 0:
            raise ZodriveError(f"run record {path} is damaged: record {number} has episode {row['episode']!r}, "
                               "not an episode index")
    return rows


def _append_jsonl(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open("a") as handle:
        for row in rows:
            handle.write(to_json(row) + "\n")
        handle.flush()
        os.fsync(handle.fileno())


def run_episodes(job: EvalJob, indices: list[int], workers: int, envs: int = 1,
                 tick: Callable[[int], None] | None = None) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]]]]:
    """Yield (episode record, step records) as episodes finish, in any order: `workers`
    processes, each running `envs` episodes side by side (when `lockstep_blocker` allows).
    `tick(n)`: n more environment steps taken (in this process, or reported by the lockstep
    workers), for a progress bar that moves within long episodes."""
    envs = 1 if lockstep_blocker(job) else min(envs, max(1, -(-len(indices) // max(workers, 1))))
    if workers <= 1 or len(indices) <= 1:
        with torch_threads(1):  # the caller's torch setting is restored afterwards
            _setup(job, envs)
            _WORKER["tick"] = tick
            try:
                if envs > 1:
                    yield from _lockstep(indices)
                else:
                    for i in indices:
                        yield _episode(i)
            finally:
                _release()
        return
    ctx = mp.get_context("forkserver")
    if envs <= 1:
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_setup,
                                 initargs=(job,)) as pool:
            yield from pool.map(_episode, indices, chunksize=1)
        return
    # each worker runs its share side by side and reports every episode as it ends
    shares = [indices[w::workers] for w in range(workers)]
    with ctx.Manager() as manager, ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                                       initializer=_worker_setup, initargs=(job, envs)) as pool:
        done = manager.Queue()
        futures = [pool.submit(_lockstep_share, share, done) for share in shares if share]
        for _ in indices:
            while True:
                try:
                    item = done.get(timeout=0.5)
                    if isinstance(item, tuple) and len(item) == 2 and item[0] == "tick":
                        if tick is not None:
                            tick(item[1])
                        continue
                    yield item
                    break
                except queue.Empty:
                    for future in futures:
                        if future.done():
                            error = future.exception()
                            if error is not None:
                                raise error


def check_trained_folder(attack: AttackSpec | None, model: str, preset: dict[str, Any],
                         defense: str | None) -> None:
    """Refuse an attack's trained folder (`Attack.trained`: a learned adversary, a picker, a surrogate) fitted
    against another model file, preset or defense: one line saying which."""
    if attack is not None:
        attack.check_folder(
            model_file=model, preset=preset, defense=defense,
            defense_version=defense_version(defense) if defense is not None else None)


RUN_FILES = ("eval_key.json", "episodes.jsonl", "steps.jsonl", "summary.json")
"""What an evaluation writes into its folder: all that `force` clears (nothing else is touched)."""


def evaluate(
    job: EvalJob,
    episodes: int,
    out: Path | None,
    *,
    workers: int = 1,
    envs: int = DEFAULT_ENVS,
    progress: bool = True,
    records: list[dict[str, Any]] | None = None,
    force: bool = False,
    label: str | None = None,
) -> dict[str, Any]:
    """Run `episodes` episodes (resuming from `out` if it holds part of this run) over
    `workers` processes, `envs` side by side in each; summarize. The episode records are
    appended to `records` in episode order, when a list is given.

    `out` is written only if it is empty, new, or holds this evaluation; a folder with files
    zodrive's evaluation did not write, another evaluation, or more episodes than asked is
    refused unless `force`, which clears the old run's files (`RUN_FILES`) and nothing else.
    The folder is locked while the run writes: a second run into it is refused at once."""
    if not isinstance(episodes, int) or episodes < 1:
        raise ZodriveError(f"episodes must be a positive integer, not {episodes}")
    if workers < 1:
        raise ZodriveError(f"workers must be >= 1, not {workers}")
    if envs < 1:
        raise ZodriveError(f"envs must be >= 1, not {envs}")
    job.model.check(job.preset, attacked=job.attack is not None)  # fail fast, in this process
    check_trained_folder(job.attack, job.model.ref, job.preset, job.defense)
    if out is None:
        return _run(job, episodes, None, {}, workers, envs, progress, records, label)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ZodriveError(f"--out {out} is a file, not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with run_lock(out, "this evaluation"):
        done = _claim(job, episodes, out, force)
        if not [i for i in range(episodes) if i not in done] and (out / "summary.json").is_file():
            summary = read_json(out / "summary.json", "summary", needs=("episodes",))
            if summary["episodes"] == episodes:  # finished before: its summary stands (step records may be gone)
                if records is not None:
                    records.extend(done[i] for i in range(episodes))
                return summary
        return _run(job, episodes, out, done, workers, envs, progress, records, label)


def _claim(job: EvalJob, episodes: int, out: Path, force: bool) -> dict[int, dict[str, Any]]:
    """Make `out` this evaluation's folder; the episodes it already holds of it."""
    key_path = out / "eval_key.json"
    wanted = json.loads(json.dumps(job.key()))
    if key_path.exists():
        on_disk = read_json(key_path, "evaluation key", needs=("model",))
        if not same_evaluation(on_disk, wanted):
            if not force:
                check_same_evaluation(on_disk, wanted, out)
            return _fresh(job, out)
        done = {r["episode"]: r for r in _read_jsonl(out / "episodes.jsonl")}
        held = len(done)
        if (out / "summary.json").is_file():  # a folder may keep its summary without its episodes (models/*/eval)
            summary = read_json(out / "summary.json", "summary", needs=("episodes",))
            held = max(held, summary["episodes"] if isinstance(summary["episodes"], int) else 0)
        if held > episodes:
            if not force:
                raise ZodriveError(f"{out} already holds {plural(held, 'episode')} of this evaluation and "
                                   f"zodrive never drops recorded episodes: ask for at least {held}, choose another "
                                   "--out, or use --force to replace them")
            return _fresh(job, out)
        _rewrite_consistent(out, done)
        return done
    foreign = sorted(p.name for p in out.iterdir() if p.name != LOCK_FILE)
    if foreign and not force:
        listed = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise ZodriveError(f"{out} holds files no zodrive evaluation wrote ({listed}); use --force to write "
                           "into it (its own files are kept), or choose another --out")
    return _fresh(job, out)


def _fresh(job: EvalJob, out: Path) -> dict[int, dict[str, Any]]:
    """Clear what an earlier run left (`RUN_FILES`), then record this evaluation's key."""
    for name in RUN_FILES:
        (out / name).unlink(missing_ok=True)
    write_json(out / "eval_key.json", job.key())
    return {}


def _run(job: EvalJob, episodes: int, out: Path | None, done: dict[int, dict[str, Any]], workers: int,
         envs: int, progress: bool, records: list[dict[str, Any]] | None, label: str | None = None) -> dict[str, Any]:
    todo = [i for i in range(episodes) if i not in done]
    if done:
        log.info("resuming: %d of %d episodes already on disk", len(done), episodes)
    bar: Any = None  # drawn with the first step or episode: a refusal while building comes first, alone
    started = time.time()
    stepped = [0, 0.0]  # environment steps so far, when the bar last showed them

    def open_bar() -> Any:
        nonlocal bar
        if bar is None:
            bar = _progress(len(todo), progress, label or ("attacked" if job.attack is not None else "clean"))
            if bar is not None:  # its clock starts with the run, not with the first episode it shows
                bar.start_t = bar.last_print_t = started
        return bar

    def tick(n: int) -> None:  # a long episode moves the bar's step count, not only its end
        stepped[0] += n
        if open_bar() is not None and time.time() - stepped[1] >= 0.5:
            bar.set_postfix_str(f"steps={stepped[0]}"
                                + (f", mean_return={np.mean([r['return'] for r in done.values()]):.1f}"
                                   if done else ""))
            stepped[1] = time.time()

    for record, steps in run_episodes(job, todo, workers, envs, tick=tick if progress else None):
        open_bar()
        done[record["episode"]] = record
        if out is not None:
            _append_jsonl(out / "steps.jsonl", steps)
            _append_jsonl(out / "episodes.jsonl", [record])
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"steps={stepped[0]}, mean_return={np.mean([r['return'] for r in done.values()]):.1f}")
    if bar is not None:
        bar.close()
    ordered = [done[i] for i in range(episodes)]
    if records is not None:
        records.extend(ordered)
    summary = summarize(ordered, job,
                        _read_jsonl(out / "steps.jsonl") if out is not None and job.attack is not None else None)
    if out is not None:
        write_json(out / "summary.json", summary)
    return summary


def _mean_of(records: list[dict[str, Any]], key: str) -> float | None:
    """The mean of `key` over records (None where a record lacks it: older records, or no road)."""
    return float(np.mean([r[key] for r in records])) if all(r.get(key) is not None for r in records) else None


def _with_later_defaults(key: dict[str, Any]) -> dict[str, Any]:
    """An attack option that a folder's key does not record was added to zodrive later: its
    default is the behaviour the folder was made with, so it counts as set to the default. One
    it records that zodrive removed since counts when it holds the behaviour left (`schema.REMOVED`)."""
    if isinstance(key.get("attack"), dict):
        key = {**key, "attack": {**AttackSpec().to_dict(), **without_removed(key["attack"])}}
    return key


def same_evaluation(on_disk: dict[str, Any], wanted: dict[str, Any]) -> bool:
    """Whether a folder's key (`eval_key.json`) describes the evaluation `wanted` (a job's key)."""
    return _with_later_defaults(on_disk) == wanted


def check_same_evaluation(on_disk: dict[str, Any], wanted: dict[str, Any], out: Path) -> None:
    """Refuse to mix episodes of two different evaluations, saying what differs."""
    on_disk = _with_later_defaults(on_disk)
    if on_disk == wanted:
        return
    if isinstance(on_disk.get("attack"), dict) and removed_settings(on_disk["attack"]):
        raise ZodriveError(f"{out} holds an evaluation made with "
                           f"{removed_message(removed_settings(on_disk['attack']))}; use --force to replace it, "
                           "or choose another --out")
    differs = [k for k in sorted(set(on_disk) | set(wanted)) if on_disk.get(k) != wanted.get(k)]
    what = {"model": "the model (its file's SHA-256 or baseline)", "preset": "the preset",
            "attack": "the attack settings or the attack engine's version", "seed": "the first seed",
            "defense_version": "the defense's version"}
    names = [what.get(k, k) for k in differs]
    listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    raise ZodriveError(f"{out} holds a different evaluation ({listed} "
                       f"{'differs' if len(names) == 1 else 'differ'}); use --force to replace it, "
                       "or choose another --out")


def _rewrite_consistent(out: Path, done: dict[int, dict[str, Any]]) -> None:
    """Drop step records of episodes that never finished (the run was cut mid-episode)."""
    steps = [s for s in _read_jsonl(out / "steps.jsonl") if s["episode"] in done]
    write_atomic(out / "steps.jsonl", "".join(to_json(s) + "\n" for s in steps))
    write_atomic(out / "episodes.jsonl", "".join(to_json(done[i]) + "\n" for i in sorted(done)))


def _progress(total: int, enabled: bool, label: str):
    if not enabled or total == 0:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=f"{label} episodes", unit="ep", dynamic_ncols=True)


def eps_means(preset: dict[str, Any], eps: float) -> str:
    """What `eps` is on `preset`'s observation, in the road's units: eps=0.05 moves a normalized
    highway-fast x by 10 m, an unnormalized one by 5 cm."""
    from zodrive.envs import scenario

    where = scenario(preset)
    if where.road and where.normalized and where.feature_ranges:
        unit = {"x": "m", "y": "m", "vx": "m/s", "vy": "m/s"}
        return "normalized to [-1, 1]: up to " + ", ".join(
            f"{name} {eps * (high - low) / 2:.3g} {unit.get(name, '')}".rstrip()
            for name, (low, high) in where.feature_ranges.items())
    if where.road:
        return f"not normalized: up to {eps:g} m on positions, {eps:g} m/s on velocities"
    return "in the observation's own units"


def summarize(
    records: list[dict[str, Any]], job: EvalJob, steps: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """The `summary.json` of an evaluation: return with CI, collision rate, attack stats."""
    returns = np.array([r["return"] for r in records])
    crashes = int(sum(r["crashed"] for r in records))
    max_return = _max_return(job.preset)
    low, high = mean_ci(returns, seed=job.seed)
    summary: dict[str, Any] = {
        "model": job.model.ref,
        "preset": job.preset.get("name"),
        **({"scenario_source": job.scenario_source} if job.scenario_source else {}),
        "episodes": len(records),
        "seed": job.seed,
        "mean_return": float(returns.mean()),
        "ci95": [low, high],
        "std_return": float(returns.std(ddof=1)) if len(returns) > 1 else 0.0,
        "pct_of_max": float(100.0 * returns.mean() / max_return) if max_return else None,
        "collision_rate": crashes / len(records),
        "collision_ci95": list(rate_ci(crashes, len(records))),
        "offroad_rate": sum(bool(r.get("offroad")) for r in records) / len(records),
        "mean_length": float(np.mean([r["length"] for r in records])),
        "mean_speed": float(np.mean([r["mean_speed"] for r in records])),
        "right_lane_share": float(np.mean([r["right_lane_share"] for r in records])),
        # None where episodes were recorded before the metric existed (not 0: it was not measured)
        "lane_changes_per_episode": _mean_of(records, "lane_changes"),
        "mean_distance": _mean_of(records, "distance"),
        "mean_path_length": _mean_of(records, "path_length"),
        "on_road_share": _mean_of(records, "on_road_share"),
        "attack": None,
        "defense": job.defense,
    }
    counts = [r["action_counts"] for r in records if r.get("action_counts")]
    if counts:
        total = np.sum(counts, axis=0)
        summary["action_share"] = (total / total.sum()).round(4).tolist()
    if job.attack is not None:
        config = job.attack.to_dict()  # what the summary records of the attack
        steps_total = sum(r["attacked_steps"] for r in records)
        applicable = sum(r["applicable"] for r in records)
        successes = sum(r["successes"] for r in records)
        kind = attack_class(job.attack.attack)
        learned = not kind.goal  # no per-step goal: no success rate, no base rate
        blind = not kind.queries_clean
        summary.update(
            attack=config["attack"],
            # paper mode is unconstrained: eps sets no budget (it only sizes random starting points)
            eps=config["eps"] if config["mode"] == "budgeted" else None,
            norm=config["norm"],
            mode=config["mode"],
            target=config["target"],
            attack_success_rate=None if learned else successes / applicable if applicable else float("nan"),
            attack_success_ci95=None if learned else list(ratio_ci([r["successes"] for r in records],
                                                                   [r["applicable"] for r in records])),
            # an attack that never asks about the clean observation knows no base rate: its success is
            # the share of all attacked steps on which the victim took the target
            target_base_rate=(None if learned or blind
                              else 1.0 - applicable / steps_total if steps_total else float("nan")),
            queries_per_step=sum(r["queries"] for r in records) / max(steps_total, 1),
            # every row the victim received: the attack's queries and the policy's own decisions
            # (one a step); the harness sends it none (it calibrates on its own copy of a network)
            victim_rows={"attack_queries": int(sum(r["queries"] for r in records)),
                         "decisions": int(sum(r["length"] for r in records)),
                         # a transfer attack's steps judged by the harness (clean and fed), never seen by it
                         **({"referee": int(sum(r.get("referee_queries", 0) for r in records))}
                            if any(r.get("referee_queries") for r in records) else {})},
            max_linf=float(max(r["max_linf"] for r in records)),
            attack_config=config,
        )
        if summary["eps"] is not None:
            summary["eps_means"] = eps_means(job.preset, summary["eps"])
        if job.attack.sparse_in_time:  # a frequency budget: how much of it was spent
            summary["attacked_share"] = steps_total / max(summary["victim_rows"]["decisions"], 1)
        attacked = [s for s in steps or () if s.get("attacked", True)]  # the per-step figures of attacked steps
        if attacked:
            summary.update(
                mean_linf=float(np.mean([s["linf"] for s in attacked])),
                mean_l2=float(np.mean([s["l2"] for s in attacked])),
                iterations_per_step=float(np.mean([s["iterations"] for s in attacked])),
                attack_ms_per_step=float(1000 * np.mean([s["wall_time"] for s in attacked])),
            )
    summary["command"] = command_line()
    summary["versions"] = versions()
    return summary
