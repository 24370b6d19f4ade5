"""What an attack may see of a policy: a query function over numpy observations.

A `Victim` is a callable (observation batch -> outputs) plus how outputs map to the action
taken. The attack library needs nothing else; adapters for SB3 models and torch networks
live in `zodrive.policies.victims`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Literal

import numpy as np

ActionKind = Literal["discrete", "continuous"]
"""A policy's actions: scores per discrete action (the argmax is taken), or the continuous action."""

QueryFn = Callable[[np.ndarray], np.ndarray]
"""Observation batch (B, *obs_shape) -> outputs (B, k): Q-values or actions."""


@dataclass(frozen=True)
class Victim:
    """A query function and what its outputs are.

    `kind="discrete"`: outputs are per-action scores (e.g. Q-values); the action taken is
    their argmax. `kind="continuous"`: outputs are the action itself.
    """

    query: QueryFn
    kind: ActionKind
    obs_shape: tuple[int, ...]
    differentiable: Callable[[Any], Any] | None = None
    """White-box access (torch forward with gradients); only the FGSM/PGD baselines use it."""
    reads: Literal["observation", "nothing", "simulator"] = "observation"
    """What the decisions depend on: built-in baselines read nothing or the simulator."""
    decisions_only: bool = False
    """Discrete outputs that are the decision alone (one-hot: the rules, a callable that returns actions):
    no score margin for a gradient-estimating attack to follow."""
    calibrate: QueryFn | None = None
    """A copy of the network that zodrive built itself (from a model file), for the harness's own
    calls (which batch sizes give a row the same outputs). None: the harness never calls the
    victim for itself, and rows are never mixed in one call (a user's callable, ONNX session or
    remote victim sees only attack queries and the policy's own decisions)."""

    def actions(self, outputs: np.ndarray) -> np.ndarray:
        """The action(s) the victim takes given its outputs."""
        return outputs.argmax(axis=-1) if self.kind == "discrete" else outputs

