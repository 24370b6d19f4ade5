"""A learned optimal adversary: an RL policy that maps the observation to the perturbation.

Zhang, Chen, Boning, Hsieh. "Robust Deep Reinforcement Learning against Adversarial
Perturbations on State Observations" (SA-MDP, NeurIPS 2020) and "Robust Reinforcement
Learning on State Observations with Learned Optimal Adversary" (SA-RL, ICLR 2021); cf. PA-AD
(Sun et al., ICLR 2022). The attacker is itself an agent, trained (`zodrive attack-train`,
`zodrive.training.adversary`) to minimize the victim's return over the whole episode instead
of pushing it toward one action now: its action a in [-1, 1]^d becomes the perturbation
delta = eps * a on the d perturbable coordinates, projected by the same `ThreatModel` as
every other attack (mask, eps-ball, observation box).

At attack time the adversary's deterministic action (its Gaussian mean, clipped to [-1, 1],
rebuilt by the safe loader: nothing in the folder is unpickled) is computed row by row, so N
episodes in lockstep get bit for bit what N one-episode runs get. It keeps no state.

Queries per environment step: 0. It has no per-step goal (it maximizes the victim's loss over the
episode), so no per-step success is reported: judge it by the return.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, ClassVar

import numpy as np
import torch

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError

NAME = "learned"
META_FILE = "adversary.json"
FORMAT = 1  # bumped if what adversary.json means changes



def free_coordinates(threat: ThreatModel, obs_shape: tuple[int, ...]) -> np.ndarray:
    """Indices of the flattened observation the attacker may write (the threat model's mask)."""
    return np.flatnonzero(threat.mask(obs_shape).reshape(-1) > 0)


def apply_action(threat: ThreatModel, x0: np.ndarray, action: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Observations (N, *obs) fed to the victim for adversary actions (N, len(free)): delta =
    eps * clip(action, -1, 1) on the free coordinates, then the threat model's projection (so
    the result is inside the eps-ball, the mask and the box whatever the action)."""
    n = len(x0)
    flat0 = np.asarray(x0, dtype=np.float32).reshape(n, -1)
    delta = np.zeros_like(flat0)
    delta[:, free] = np.float32(threat.eps) * np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)
    return threat.project((flat0 + delta).reshape(x0.shape), np.asarray(x0))


def read_description(folder: str | Path, files: tuple[str, str], keys: tuple[str, ...], fmt: int, *, kind: str,
                     being: str, how: str) -> dict[str, Any]:
    """A trained folder's JSON description (`files`: it, then the weights beside it) with every key of
    `keys` and format `fmt`, or a one-line error saying what is missing: "`kind` folder not found",
    "... is not `being` (no ...; `how`)", e.g. kind "picker", being "a picker", how "fit one with ..."."""
    path = Path(folder)
    if not path.is_dir():
        raise ZodriveError(f"{kind} folder not found: {path} ({how})")
    for name in files:
        if not (path / name).is_file():
            raise ZodriveError(f"{path} is not {being} (no {name}; {how})")
    try:
        meta = json.loads((path / files[0]).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ZodriveError(f"{path / files[0]} is not valid JSON") from None
    if not isinstance(meta, dict) or any(k not in meta for k in keys) or meta["format"] != fmt:
        raise ZodriveError(f"{path / files[0]} is not {'an' if kind[0] in 'aeiou' else 'a'} {kind} description "
                           f"zodrive {fmt} reads")
    return meta


def read_meta(folder: str | Path) -> dict[str, Any]:
    """A trained adversary's `adversary.json`, or a one-line error saying what is missing."""
    keys = ("format", "eps", "norm", "frozen", "kind", "obs_shape", "action_dim", "victim_sha256", "preset", "defense")
    meta = read_description(folder, (META_FILE, "model.zip"), keys, FORMAT, kind="adversary",
                            being="a trained adversary", how="train one with `zodrive attack-train`")
    if meta.get("victim_action", False) is not False:  # written before it was removed: false then meant what is left
        raise ZodriveError(f"adversary {folder} observes the victim's clean action (attack-train --victim-action): "
                           "removed from zodrive (docs/attacks.md, section \"Removed options\")")
    return meta


def check_fitted_against(meta: dict[str, Any], what: str, verb: str, *, model_file: str,
                         preset: dict[str, Any]) -> None:
    """Refuse a trained folder (its description `meta`) made against another model file (by SHA-256) or
    preset: one line, "`what` against ..., not ...: `verb` one against this model"."""
    from zodrive.runinfo import sha256

    if not Path(model_file).is_file() or sha256(Path(model_file)) != meta["victim_sha256"]:
        raise ZodriveError(f"{what} against {meta.get('victim', '?')} (SHA-256 {meta['victim_sha256'][:12]}..), "
                           f"not {model_file}: {verb} one against this model")
    if meta["preset"] != preset:
        raise ZodriveError(f"{what} on preset {meta['preset'].get('name')!r} with other settings than this "
                           f"evaluation's: {verb} one for this preset")


def check_adversary(folder: str | Path, *, model_file: str, preset: dict[str, Any], defense: str | None,
                    defense_version: int | None = None) -> None:
    """Refuse to run an adversary against another system than the one it was trained on
    (another model file, preset, defense or defense version): one line saying which."""
    meta = read_meta(folder)
    check_fitted_against(meta, f"adversary {folder} was trained", "train", model_file=model_file, preset=preset)
    if meta["defense"] != defense:
        raise ZodriveError(f"adversary {folder} was trained against the victim with defense "
                           f"{meta['defense'] or 'none'}, not {defense or 'none'}: train one against this system")
    if defense is not None and meta.get("defense_version") != defense_version:
        raise ZodriveError(f"adversary {folder} was trained against {defense} version "
                           f"{meta.get('defense_version') or 'before versions'}, this zodrive's is version "
                           f"{defense_version}: train one against this system")


class LearnedAdversary(Attack):
    """SA-RL's learned optimal adversary (Zhang et al., ICLR 2021) read from a trained folder.

    Queries per environment step: 0."""

    name = NAME
    search = False
    no_search = "the adversary was trained to lower the victim's return; it has no per-step objective or search"
    reads: ClassVar[frozenset[str]] = frozenset()
    reference = "Zhang et al., SA-RL (learned optimal adversary), ICLR 2021"
    trained = "adversary"
    goal = False

    @classmethod
    def check_folder(cls, folder: str | None, *, model_file: str, preset: dict[str, Any], defense: str | None,
                     defense_version: int | None = None) -> None:
        if folder is None:
            raise ZodriveError("attack learned needs a trained adversary: --attack learned:DIR")
        check_adversary(folder, model_file=model_file, preset=preset, defense=defense, defense_version=defense_version)

    @classmethod
    def folder_digest(cls, folder: str) -> str:
        from zodrive.runinfo import sha256

        return "sha256:" + sha256(Path(folder) / "model.zip")

    def __init__(self, threat: ThreatModel, *, adversary: str | None = None,
                 load_network: Callable[[str], Any] | None = None, **kwargs: Any) -> None:
        """`load_network(folder)` reads the adversary's network (the composition point passes the
        safe loader, `zodrive.policies.loading.load_network`); without it only the folder's
        description is checked (an options check before any episode)."""
        super().__init__(threat, **kwargs)
        if adversary is None:
            raise ZodriveError("attack learned needs a trained adversary: --attack learned:DIR "
                               "(a folder written by `zodrive attack-train`)")
        self.folder = str(adversary)
        self.meta = read_meta(self.folder)
        if threat.mode != "budgeted":
            raise ZodriveError("attack learned: mode paper has no budget; the adversary acts inside the eps-ball "
                               "it was trained with")
        if float(threat.eps) != float(self.meta["eps"]) or threat.norm != self.meta["norm"]:
            raise ZodriveError(f"adversary {self.folder} was trained at {self.meta['norm']} eps "
                               f"{self.meta['eps']:g}, not {threat.norm} eps {threat.eps:g}: pass --eps "
                               f"{self.meta['eps']:g} or train one at this eps")
        self.net = None
        if load_network is None:
            return
        network = load_network(self.folder)  # the safe loader: rebuilt from plain data, nothing unpickled
        if network.kind != "continuous" or network.n_outputs != int(self.meta["action_dim"]):
            raise ZodriveError(f"{self.folder}/model.zip is not the adversary its {META_FILE} describes")
        self.net = network.net

    def check_mask(self, threat: ThreatModel) -> None:
        """The features it may write are the ones it was trained to write."""
        if list(threat.frozen) != list(self.meta["frozen"]):
            raise ZodriveError(f"adversary {self.folder} was trained with frozen features "
                               f"{self.meta['frozen'] or 'none'}, not {list(threat.frozen) or 'none'}")

    def queries_per_run(self, steps: int | None = None) -> int:
        return 0

    def first_iteration_cost(self) -> int:
        return 0

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        raise AssertionError("a learned adversary takes no search step")  # perturb is its own

    def actions(self, inputs: np.ndarray) -> np.ndarray:
        """The adversary's deterministic actions (N, d), one row per forward pass (a row's
        action does not depend on the batch it came in)."""
        if self.net is None:
            raise ZodriveError("attack learned was built without its network: build it through "
                               "zodrive.system.build_attacker, which reads the folder with the safe loader")
        with torch.no_grad():
            return np.concatenate([self.net(torch.from_numpy(row[None])).numpy() for row in inputs]).astype(np.float32)

    def perturb(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
                ) -> AttackResult:
        """delta = eps * pi(observation) on the free coordinates, projected."""
        n, shape = len(x0), tuple(x0.shape[1:])
        if tuple(self.meta["obs_shape"]) != shape:
            raise ZodriveError(f"adversary {self.folder} was trained on observations of shape "
                               f"{tuple(self.meta['obs_shape'])}, not {shape}")
        free = free_coordinates(self.threat, shape)
        if len(free) != int(self.meta["action_dim"]):
            raise ZodriveError(f"adversary {self.folder} perturbs {self.meta['action_dim']} coordinates; this "
                               f"threat model frees {len(free)}")
        oracle.begin_step(rows=n)
        x0 = np.asarray(x0, dtype=np.float32)
        x_adv = apply_action(self.threat, x0, self.actions(x0.reshape(n, -1)), free)
        linf, l2 = distortion(x_adv, x0)
        nothing = np.full((n, 0), np.nan, dtype=np.float32)  # no victim output is asked
        return AttackResult(x_adv=x_adv, success=np.zeros(n, dtype=bool), already=np.ones(n, dtype=bool),  # no goal
                            iterations=np.ones(n, dtype=np.int64), queries=oracle.row_queries.copy(), linf=linf, l2=l2,
                            adv_outputs=nothing, clean_outputs=nothing.copy())
