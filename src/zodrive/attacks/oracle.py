"""The one place where queries to the victim are made and counted."""

from __future__ import annotations

import numpy as np
import torch
from typing import Callable

from zodrive.agents.victims import Victim
from zodrive.errors import ZodriveError


class QueryBudgetExhausted(Exception):
    """Raised inside an attack when the per-step query budget is spent."""


class QueryOracle:
    """Black-box access to a victim: counts every observation sent, enforces a budget.

    `query_budget` caps the queries per environment step and per environment (None =
    unlimited); a step over `rows` environments at once may spend `rows * query_budget`. Counters:
    `step_queries` (since `begin_step`), `episode_queries` (since `begin_episode`),
    `total_queries` and `calls` (victim invocations; one per batch).
    """

    def __init__(self, victim: Victim, query_budget: int | None = None) -> None:
        if query_budget is not None and query_budget < 1:
            raise ZodriveError(f"query_budget must be >= 1, not {query_budget}")
        self.victim = victim
        self.query_budget = query_budget
        self.step_queries = 0
        self.episode_queries = 0
        self.total_queries = 0
        self.calls = 0
        self._allowance = float("inf") if query_budget is None else query_budget

    @property
    def kind(self) -> str:
        return self.victim.kind

    def remaining(self) -> float:
        """Queries left this step (inf without a budget)."""
        return self._allowance - self.step_queries

    def begin_episode(self) -> None:
        self.episode_queries = 0

    def begin_step(self, rows: int = 1) -> None:
        """Start an environment step for `rows` environments attacked together."""
        self.step_queries = 0
        if self.query_budget is not None:
            self._allowance = self.query_budget * rows

    def __call__(self, batch: np.ndarray) -> np.ndarray:
        """Send one batch of observations (B, *obs) to the victim; count B queries."""
        n = len(batch)
        if n > self.remaining():
            raise QueryBudgetExhausted(f"{n} queries asked, {self.remaining()} left")
        outputs = np.asarray(self.victim.query(batch))
        if not np.all(np.isfinite(outputs)):
            raise ZodriveError("victim returned NaN or infinite outputs (NaN observation?)")
        self.step_queries += n
        self.episode_queries += n
        self.total_queries += n
        self.calls += 1
        return outputs

    def gradient(
        self, batch: np.ndarray, loss: Callable[[torch.Tensor], torch.Tensor]
    ) -> tuple[np.ndarray, np.ndarray]:
        """WHITE-BOX: outputs and d(sum loss)/d(batch) through the victim's torch graph.

        Counted as one query per row like any other. Only the labelled white-box baselines
        (FGSM, PGD) may call this; black-box attacks never do.
        """
        if self.victim.differentiable is None:
            raise ZodriveError("this victim offers no gradients; white-box attacks need an SB3 model")
        n = len(batch)
        if n > self.remaining():
            raise QueryBudgetExhausted(f"{n} queries asked, {self.remaining()} left")
        x = torch.tensor(np.asarray(batch, dtype=np.float32), requires_grad=True)
        out = self.victim.differentiable(x)
        loss(out).sum().backward()
        self.step_queries += n
        self.episode_queries += n
        self.total_queries += n
        self.calls += 1
        return out.detach().numpy(), x.grad.numpy()
