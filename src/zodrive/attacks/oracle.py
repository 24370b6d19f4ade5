"""The one place where queries to the victim are made, counted and budgeted."""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError


class QueryBudgetExhausted(Exception):
    """A query would take an environment row past its per-step budget."""


class QueryOracle:
    """Black-box access to a victim: counts every observation sent, enforces a budget.

    A step attacks `rows` environments at once (`begin_step`); every query belongs to one
    row (`owners`) and `query_budget` caps the queries of each row in one environment step
    (None = unlimited). Rows never share an allowance: a row that finishes early leaves
    nothing to the others. `episode_query_budget` caps the queries of an episode (since
    `begin_episode`; an oracle serves one environment, as in the attack wrapper). Counters: `row_queries` (per row, since `begin_step`),
    `step_queries`, `episode_queries` (since `begin_episode`), `total_queries`, and
    `calls` (victim invocations; one per batch).
    """

    def __init__(self, victim: Victim, query_budget: int | None = None,
                 episode_query_budget: int | None = None) -> None:
        if query_budget is not None and query_budget < 1:
            raise ZodriveError(f"query_budget must be >= 1, not {query_budget}")
        if episode_query_budget is not None and episode_query_budget < 1:
            raise ZodriveError(f"episode_query_budget must be >= 1, not {episode_query_budget}")
        self.victim = victim
        self.query_budget = query_budget
        self.episode_query_budget = episode_query_budget
        self.row_queries = np.zeros(1, dtype=np.int64)
        self.episode_queries = 0
        self.total_queries = 0
        self.calls = 0

    @property
    def kind(self) -> str:
        return self.victim.kind

    @property
    def step_queries(self) -> int:
        return int(self.row_queries.sum())

    def remaining(self, rows: np.ndarray) -> np.ndarray:
        """Queries each of `rows` may still make this step (inf without a budget)."""
        left = np.full(len(rows), np.inf)
        if self.query_budget is not None:
            left = (self.query_budget - self.row_queries[rows]).astype(np.float64)
        if self.episode_query_budget is not None:
            left = np.minimum(left, self.episode_query_budget - self.episode_queries)
        return left

    def begin_episode(self) -> None:
        self.episode_queries = 0

    def begin_step(self, rows: int = 1) -> None:
        """Start an environment step for `rows` environments attacked together."""
        self.row_queries = np.zeros(rows, dtype=np.int64)

    def _charge(self, owners: np.ndarray) -> None:
        counts = np.bincount(owners, minlength=len(self.row_queries))
        if len(counts) > len(self.row_queries):
            raise ZodriveError(f"query for row {owners.max()} of a step over {len(self.row_queries)} rows")
        if self.query_budget is not None and np.any(self.row_queries + counts > self.query_budget):
            over = int(np.argmax(self.row_queries + counts - self.query_budget))
            raise QueryBudgetExhausted(
                f"row {over} would spend {int(self.row_queries[over] + counts[over])} of {self.query_budget} queries"
            )
        if self.episode_query_budget is not None and self.episode_queries + len(owners) > self.episode_query_budget:
            raise QueryBudgetExhausted(f"the episode would spend {self.episode_queries + len(owners)} of "
                                       f"{self.episode_query_budget} queries")
        self.row_queries += counts

    def _owners(self, n: int, owners: np.ndarray | None) -> np.ndarray:
        if owners is None:  # one query per row, rows in order
            owners = np.arange(n)
        owners = np.asarray(owners, dtype=np.int64)
        if owners.shape != (n,):
            raise ZodriveError(f"{n} queries need {n} owners, got shape {owners.shape}")
        return owners

    def __call__(self, batch: np.ndarray, owners: np.ndarray | None = None) -> np.ndarray:
        """Send observations (B, *obs) to the victim; query b is charged to row `owners[b]`."""
        owners = self._owners(len(batch), owners)
        self._charge(owners)
        outputs = np.asarray(self.victim.query(batch))
        if not np.all(np.isfinite(outputs)):
            raise ZodriveError("victim returned NaN or infinite outputs (NaN observation?)")
        self._count(len(batch))
        return outputs

    def gradient(
        self, batch: np.ndarray, loss: Callable[[torch.Tensor], torch.Tensor], owners: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """WHITE-BOX: outputs and d(sum loss)/d(batch) through the victim's torch graph.

        Counted as one query per row like any other. Only the labelled white-box baselines
        (FGSM, PGD) may call this; black-box attacks never do.
        """
        if self.victim.differentiable is None:
            raise ZodriveError("this victim offers no gradients; white-box attacks need an SB3 model")
        owners = self._owners(len(batch), owners)
        self._charge(owners)
        x = torch.tensor(np.asarray(batch, dtype=np.float32), requires_grad=True)
        out = self.victim.differentiable(x)
        loss(out).sum().backward()
        self._count(len(batch))
        return out.detach().numpy(), x.grad.numpy()

    def _count(self, n: int) -> None:
        self.episode_queries += n
        self.total_queries += n
        self.calls += 1
