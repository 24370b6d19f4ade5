"""A picker for vertex hold (`--attack vertex-hold:DIR`): which random vertex to feed when one is needed.

Vertex hold feeds a random vertex of the L-inf ball after every step on which the victim did not take
the target, and holds one that works. A picker is a small MLP fitted offline, from counted training
queries (`zodrive picker-train`, `zodrive.training.picker`), to the probability that the victim takes
the target on an observation; at attack time it ranks `candidates` random vertices by that
probability and the best one is fed. It also drops a held vertex that it rates below `switch` at the
new state. Scoring is local: the attack still makes one victim query per step. The surrogate only ranks random vertices
and is never optimized against, unlike the fitted adversary's (`zodrive.training.amortized`). That
optimization finds the surrogate's errors on models/dqn-close (results/learned-adversary).

The folder holds `picker.json` (what it was fitted against, its settings) and `picker.pt` (the MLP's
weights: a dict of tensors read with `torch.load(weights_only=True)`, so nothing is unpickled).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import torch

from zodrive.attacks.objectives import AVOID, DiscreteAvoid
from zodrive.errors import ZodriveError

META_FILE = "picker.json"
WEIGHTS_FILE = "picker.pt"
FORMAT = 1
KEYS = ("format", "victim", "victim_sha256", "preset", "eps", "norm", "frozen", "target", "tol", "obs_shape", "width",
        "candidates", "switch")
MAX_WIDTH, MAX_CANDIDATES = 4096, 4096  # a stranger's description cannot make the loader allocate more


def network(inputs: int, width: int) -> torch.nn.Sequential:
    """The picker's MLP: the flattened fed observation -> the logit of "the victim takes the target"."""
    return torch.nn.Sequential(torch.nn.Linear(inputs, width), torch.nn.ReLU(), torch.nn.Linear(width, width),
                               torch.nn.ReLU(), torch.nn.Linear(width, 1))


class Picker:
    """Ranks fed observations by the fitted probability that the victim takes the target."""

    def __init__(self, net: torch.nn.Sequential, candidates: int, switch: float) -> None:
        self.net, self.candidates, self.switch = net.eval(), int(candidates), float(switch)

    def scores(self, fed: np.ndarray) -> np.ndarray:
        """(N, *obs) observations -> (N,) probabilities, in one network call: a row's score depends on
        the batch it is in (floating point), so callers that need lockstep = one-row runs call this
        once per environment row (`VertexHold`)."""
        flat = torch.from_numpy(np.ascontiguousarray(fed, dtype=np.float32).reshape(len(fed), -1))
        if flat.shape[1] != self.net[0].in_features:
            raise ZodriveError(f"the picker reads observations of {self.net[0].in_features} values, not "
                               f"{flat.shape[1]}: fit one for this observation")
        with torch.no_grad():
            return torch.sigmoid(self.net(flat)).squeeze(1).numpy()

    @classmethod
    def load(cls, folder: str | Path) -> tuple["Picker", dict[str, Any]]:
        """The picker in `folder` and its description, or a one-line error."""
        meta = read_meta(folder)
        try:
            state = torch.load(Path(folder) / WEIGHTS_FILE, map_location="cpu", weights_only=True)
        except Exception as exc:  # a truncated or foreign file; weights_only refuses anything but tensors
            raise ZodriveError(f"{Path(folder) / WEIGHTS_FILE} is not a picker's weights "
                               f"({type(exc).__name__})") from None
        net = network(int(np.prod(meta["obs_shape"])), int(meta["width"]))
        try:
            net.load_state_dict(state)
        except (RuntimeError, TypeError, AttributeError):
            raise ZodriveError(f"{Path(folder) / WEIGHTS_FILE} does not fit the network "
                               f"{META_FILE} describes") from None
        return cls(net, meta["candidates"], meta["switch"]), meta


def read_meta(folder: str | Path) -> dict[str, Any]:
    """A picker's `picker.json`, typed and bounded, or a one-line error saying what is missing."""
    from zodrive.attacks.learned import read_description

    meta = read_description(folder, (META_FILE, WEIGHTS_FILE), KEYS, FORMAT, kind="picker", being="a picker",
                            how="fit one with `zodrive picker-train`")
    if not _well_typed(meta):
        raise ZodriveError(f"{Path(folder) / META_FILE} holds a value of the wrong type or out of range")
    return meta


def _count(value: Any, most: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= most


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _well_typed(meta: dict[str, Any]) -> bool:
    """Every field a picker's description gives has the type and range zodrive writes."""
    target = meta["target"]
    return (isinstance(meta["victim"], str) and isinstance(meta["victim_sha256"], str)
            and isinstance(meta["preset"], dict)
            and _number(meta["eps"]) and meta["eps"] > 0 and meta["norm"] == "linf"
            and isinstance(meta["frozen"], list) and all(isinstance(f, str) for f in meta["frozen"])
            and (_count(target, 10_000) or target == 0 or (isinstance(target, list) and all(_number(v) for v in target))
                 or (isinstance(target, str) and re.fullmatch(AVOID + r"\d{1,4}", target) is not None))
            and (meta["tol"] is None or (_number(meta["tol"]) and meta["tol"] >= 0))
            and isinstance(meta["obs_shape"], list) and all(_count(d, 10_000) for d in meta["obs_shape"])
            and _count(int(np.prod(meta["obs_shape"])) if meta["obs_shape"] else 0, 1_000_000)
            and _count(meta["width"], MAX_WIDTH) and _count(meta["candidates"], MAX_CANDIDATES)
            and _number(meta["switch"]) and 0 <= meta["switch"] < 1)


def check_picker(folder: str | Path, *, model_file: str, preset: dict[str, Any], defense: str | None) -> None:
    """Refuse a picker fitted against another model file or preset, or run behind a defense (one line;
    the budget and the target are checked where the attack is built, `VertexHold`)."""
    from zodrive.attacks.learned import check_fitted_against

    check_fitted_against(read_meta(folder), f"picker {folder} was fitted", "fit", model_file=model_file, preset=preset)
    if defense is not None:
        raise ZodriveError("a picker is fitted against the undefended model: drop --defense or use vertex-hold")


def digest(folder: str | Path) -> str:
    """The SHA-256 of a picker's weights and description together: what an evaluation's key records (a
    refitted picker, or one with other `candidates` or `switch`, is another attack)."""
    from zodrive.runinfo import sha256

    return "sha256:" + sha256(Path(folder) / WEIGHTS_FILE) + "+" + sha256(Path(folder) / META_FILE)


def objective_target(objective: Any) -> dict[str, Any]:
    """What a picker records of its objective's goal: the target (the action index, "not:INDEX" for an
    action to avoid, or the action as a list) and, for a continuous target, the tolerance within which
    it counts as taken."""
    if isinstance(objective, DiscreteAvoid):
        return {"target": f"{AVOID}{objective.avoid}", "tol": None}
    target = getattr(objective, "target", None)
    if isinstance(target, (tuple, list, np.ndarray)):
        return {"target": [float(v) for v in target], "tol": float(objective.tol)}
    return {"target": target, "tol": None}
