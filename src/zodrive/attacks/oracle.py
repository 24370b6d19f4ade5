"""The one place where queries to the victim are made, counted and budgeted, and what they return
(`access`: the victim's outputs, or its decision alone)."""

from __future__ import annotations

from typing import Callable, Literal

import numpy as np
import torch

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

Access = Literal["score", "decision"]
ACCESS = ("score", "decision")
Front = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(queries, owners) -> what the victim receives for them: row by row, what stands in front of the victim."""


def decision_view(victim: Victim) -> Victim:
    """A discrete `victim` as a decision-only attacker sees it: each query returns the one-hot vector of
    the action taken (the argmax, ties to the first as `Victim.actions`), never the scores; no gradient
    (`differentiable`) and no calibration copy (`calibrate`), the two other ways to its network."""
    if victim.kind != "discrete":
        raise ZodriveError("decision access applies to a discrete victim: a continuous victim's output is its action "
                           "(the decision) already")
    query = victim.query

    def decide(batch: np.ndarray) -> np.ndarray:
        out = np.asarray(query(batch))
        return np.eye(out.shape[-1], dtype=np.float32)[out.argmax(axis=-1)]

    return Victim(query=decide, kind="discrete", obs_shape=victim.obs_shape, reads=victim.reads, decisions_only=True)


class QueryBudgetExhausted(Exception):
    """A query would take an environment row past its per-step budget."""


class QueryOracle:
    """Black-box access to a victim: counts every observation sent, enforces a budget.

    A step attacks `rows` environments at once (`begin_step`); every query belongs to one
    row (`owners`) and `query_budget` caps the queries of each row in one environment step
    (None = unlimited). Rows never share an allowance: a row that finishes early leaves
    nothing to the others (a row is one environment: one in the attack wrapper, N when
    episodes run in lockstep). Counters: `row_queries` (per row, since `begin_step`),
    `row_episode_queries` (per row, since `begin_episode`), `step_queries`,
    `episode_queries` (their sums), `total_queries`, and `calls` (oracle calls).

    A row's outputs never depend on which other rows share a call. BLAS libraries pick
    another kernel for small batches (on this machine's torch, a batch of 1-3 rows rounds
    the last bits differently from a batch of 4 or more), so the first call that mixes rows
    measures, once, from which batch size the victim's outputs stop depending on it
    (`stable_batch`, on random inputs that are not observations and whose outputs reach no
    attack, sent to zodrive's own copy of the network, `Victim.calibrate`, never to a user's
    callable; counted apart, in `calibration_queries`); a row whose share of a call is smaller is
    sent on its own, as a one-row run would send it. That is what makes N episodes in lockstep equal N one-episode runs.

    `access="decision"` (a discrete victim only): every query returns the one-hot vector of the action
    taken, and the victim the oracle holds (`victim`) is that decision-only view (`decision_view`), so
    neither a query, nor `gradient`, nor the victim attribute gives an attack the scores. The network's
    calibration copy stays private to the oracle (batch sizes are measured on the scores, a stricter test
    than on the decisions), and its outputs reach no attack.

    `front` (None: nothing) stands between every query and the victim, row by row: in lockstep, a stateful
    defense keeps one filter per episode row (`zodrive.defense.wrappers.RowFilters`), and each query is seen
    through the filter of the row it is charged to, as one environment's attacker sees its defended system
    (`defended_victim`). Gradients pass it by BPDA, as there.
    """

    def __init__(self, victim: Victim, query_budget: int | None = None, access: Access = "score") -> None:
        if query_budget is not None and query_budget < 1:
            raise ZodriveError(f"query_budget must be >= 1, not {query_budget}")
        if access not in ACCESS:
            raise ZodriveError(f"access must be score or decision, not {access!r}")
        self.access = access
        self._calibrate = victim.calibrate
        self.victim = decision_view(victim) if access == "decision" else victim
        self.query_budget = query_budget
        self.row_queries = np.zeros(1, dtype=np.int64)
        self.row_episode_queries = np.zeros(1, dtype=np.int64)
        self.total_queries = 0
        self.calls = 0
        self.stable_batch: int | None = None  # measured when first needed
        self.calibration_queries = 0
        self.referee_queries = 0
        self.front: Front | None = None

    @property
    def episode_queries(self) -> int:
        return int(self.row_episode_queries.sum())

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
        return left

    def begin_episode(self, row: int | None = None) -> None:
        """A new episode for every row, or (lockstep) for row `row` only."""
        if row is None:
            self.row_episode_queries[:] = 0
        else:
            self.row_episode_queries[row] = 0

    def keep_rows(self, rows: np.ndarray) -> None:
        """Only `rows` go on (lockstep episodes that ended without a successor are dropped)."""
        self.row_episode_queries = self.row_episode_queries[rows]

    def begin_step(self, rows: int = 1) -> None:
        """Start an environment step for `rows` environments attacked together (a different
        number of rows than the episode counters hold: new rows, new episodes)."""
        self.row_queries = np.zeros(rows, dtype=np.int64)
        if len(self.row_episode_queries) != rows:
            self.row_episode_queries = np.zeros(rows, dtype=np.int64)

    def _charge(self, owners: np.ndarray) -> None:
        counts = np.bincount(owners, minlength=len(self.row_queries))
        if len(counts) > len(self.row_queries):
            raise ZodriveError(f"query for row {owners.max()} of a step over {len(self.row_queries)} rows")
        if self.query_budget is not None and np.any(self.row_queries + counts > self.query_budget):
            over = int(np.argmax(self.row_queries + counts - self.query_budget))
            raise QueryBudgetExhausted(
                f"row {over} would spend {int(self.row_queries[over] + counts[over])} of {self.query_budget} queries"
            )
        self.row_queries += counts
        self.row_episode_queries += counts

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
        if self.front is not None:
            batch = self.front(batch, owners)
        calls = self._calls(owners)
        if len(calls) == 1:
            outputs = np.asarray(self.victim.query(batch))
        else:
            parts = [np.asarray(self.victim.query(batch[part])) for part in calls]
            outputs = np.empty((len(batch), *parts[0].shape[1:]), dtype=parts[0].dtype)
            for part, out in zip(calls, parts):
                outputs[part] = out
        if not np.all(np.isfinite(outputs)):
            raise ZodriveError("victim returned NaN or infinite outputs (NaN observation?)")
        self._count(len(batch))
        return outputs

    def referee(self, batch: np.ndarray, owners: np.ndarray | None = None) -> np.ndarray:
        """The HARNESS's look, not an attack's: the victim's outputs on observations (B, *obs) of rows `owners`
        (default: one each, in order), one row per call as the policy acts, to judge a step of an attack that
        makes no query (`Attack.refereed`: was the target taken on the fed point, and on the clean one?).
        Called after the attack has returned, its outputs never reach it; counted apart (`referee_queries`),
        outside every row's budget."""
        if self.front is not None:
            batch = self.front(batch, self._owners(len(batch), owners))
        outputs = np.concatenate([np.asarray(self.victim.query(batch[i:i + 1])) for i in range(len(batch))])
        if not np.all(np.isfinite(outputs)):
            raise ZodriveError("victim returned NaN or infinite outputs (NaN observation?)")
        self.referee_queries += len(batch)
        return outputs

    def gradient(
        self, batch: np.ndarray, loss: Callable[[torch.Tensor], torch.Tensor], owners: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """WHITE-BOX: outputs and d(sum loss)/d(batch) through the victim's torch graph.

        Counted as one query per row like any other. Only the labelled white-box baselines
        (FGSM, PGD) may call this; black-box attacks never do.
        """
        if self.access == "decision":
            raise ZodriveError("decision access gives no gradients (the attacker sees only the action taken)")
        if self.victim.differentiable is None:
            raise ZodriveError("this victim offers no gradients; white-box attacks need a torch network "
                               "(an SB3 model or a torch module)")
        owners = self._owners(len(batch), owners)
        self._charge(owners)
        points = np.asarray(batch, dtype=np.float32)
        x = torch.tensor(points, requires_grad=True)
        fed = x  # BPDA through a front: its value forward, the identity backward
        if self.front is not None:
            fed = x + (x.new_tensor(self.front(points, owners)) - x).detach()
        calls = self._calls(owners)
        if len(calls) == 1:
            out = self.victim.differentiable(fed)
        else:  # each call its own graph (its own kernels), the outputs put back in order
            order = torch.from_numpy(np.argsort(np.concatenate(calls), kind="stable"))
            out = torch.cat([self.victim.differentiable(fed[torch.from_numpy(part)]) for part in calls])[order]
        loss(out).sum().backward()
        self._count(len(batch))
        assert x.grad is not None  # the outputs are computed from x
        return out.detach().numpy(), x.grad.numpy()

    def _count(self, n: int) -> None:
        self.total_queries += n
        self.calls += 1

    def _calls(self, owners: np.ndarray) -> list[np.ndarray]:
        """The victim calls a batch is sent in (index arrays into it): one, unless some row's
        share is below `stable_batch` and other rows share the batch; then that row's queries
        go on their own and the rest together."""
        if len(owners) == 0 or owners.min() == owners.max():
            return [np.arange(len(owners))]
        if self.stable_batch is None and self._calibrate is None:
            self.stable_batch = NEVER_MIX  # not our network: no calls of our own, each row alone
        if self.stable_batch is None:
            assert self._calibrate is not None  # without it, NEVER_MIX was set just above
            self.stable_batch, self.calibration_queries = stable_batch(self._calibrate, self.victim.obs_shape)
        share = np.bincount(owners)[owners]
        alone = share < self.stable_batch
        if not alone.any():
            return [np.arange(len(owners))]
        calls = [np.flatnonzero(owners == row) for row in np.unique(owners[alone])]
        if not alone.all():
            calls.append(np.flatnonzero(~alone))
        return calls


NEVER_MIX = 1 << 62
"""`stable_batch` of a victim zodrive may not call for itself: rows go alone whenever they differ."""
PROBE_SIZES = (*range(1, 17), 24, 32, 48, 64, 128, 256, 512, 1024, 2048)


OFFSETS = range(1, 17)  # where a row's block may sit in a shared call (kernels tile rows by up to 16)


def stable_batch(query: Callable[[np.ndarray], np.ndarray], obs_shape: tuple[int, ...]) -> tuple[int, int]:
    """The smallest batch size from which `query`'s output for a row is the same in every
    larger batch (of `PROBE_SIZES`) wherever the row sits in it, measured on random inputs;
    beyond the largest size probed if none qualifies (then rows are never mixed); and the
    rows queried to find it. Where a row sits matters for some kernels (on this machine a
    2-thread DDPG actor rounds a block of 8 rows differently at some offsets of a larger
    batch; from 12 rows on, nowhere): each size is compared at offsets 0-16 of the
    reference batch."""
    rng = np.random.default_rng(0)
    batch = rng.uniform(-1.0, 1.0, size=(PROBE_SIZES[-1] + OFFSETS[-1], *obs_shape)).astype(np.float32)
    reference = np.asarray(query(batch))
    floor, spent = PROBE_SIZES[-1] + 1, len(batch)
    for size in reversed(PROBE_SIZES[:-1]):
        for offset in (0, *OFFSETS):
            spent += size
            if not np.array_equal(np.asarray(query(batch[offset:offset + size])), reference[offset:offset + size]):
                return floor, spent
        floor = size
    return floor, spent
