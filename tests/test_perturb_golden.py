"""`Attack.perturb` returns what it returned when these records were made: every registered attack on
a toy victim (`toys.portable_victim`), over a few seeds, with the options that change the driver's
path (early stop, patience, warm start, the max-change box, per-row budgets, the L2 term, white-box
gradients, vertex hold's picker and vertex check's `check_below`).

A refactoring of the driver must leave every record as it is. A change of behaviour that is meant
(and bumps `ENGINE_VERSION`) records them again: `python tests/test_perturb_golden.py` rewrites
`golden/perturb.json`.

The records hold on any x86 CPU, not only the one that made them. Torch's float32 kernels round
differently per instruction set (AVX2, AVX-512; its randn too), so a digest of float bits held on one
machine and failed on the next. What each step returns is split in two: the counts (success,
iterations, queries: a digest, bit for bit) and the floats (each row's sum of the perturbed input, its
L-inf and L2 size, the sums of its outputs, and the trace; compared to `TOLERANCE`, absolute). The
victim's outputs are the same bits everywhere (`portable_victim`), so a run follows the same path on
every CPU. The one float the engine computes in torch is SPSA's Adam step (`torch.optim.Adam`), whose
kernels round differently per instruction set; its last-bit differences carry through 18 chained Adam
iterations (3 steps of 6) and the victim: between the Intel (AVX-512) machine that made the records and
an AMD EPYC (Zen 3, AVX2) they reach 3.05e-5 (every other attack: 0, bit for bit). `TOLERANCE` is 1e-4,
three times that, and `test_the_tolerance_still_sees_a_small_change` shows it below what a small change
of behaviour moves: Adam's beta2 from 0.999 to 0.998 moves spsa/continuous by 8.4e-4."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from toys import blind_picker, context, observations, portable_victim, readable
from zodrive.attacks import ATTACKS, AttackSpec
from zodrive.attacks.base import AttackResult
from zodrive.attacks.picker import Picker
from zodrive.compute import one_torch_thread

GOLDEN = Path(__file__).parent / "golden" / "perturb.json"
SEEDS = (0, 1, 2)
ROWS = 4  # environment rows attacked side by side
STEPS = 3  # consecutive environment steps of one episode (warm start and max_change carry state)

SEARCH_OPTIONS: dict[str, dict[str, Any]] = {
    "default": {},
    "continuous": {"kind": "continuous"},
    "untargeted": {"target": "none"},
    "fallback-l2": {"target": "FASTER,not:SLOWER", "norm": "l2", "eps": 0.3},
    "full-trace": {"early_stop": False, "l2_weight": 0.5, "trace": True},
    "patience": {"patience": 2, "steps": 12},
    "budget": {"query_budget": 17},
    "warm-box": {"warm_start": True, "max_change": 0.03},
    "box-budget": {"max_change": 0.02, "query_budget": 13, "early_stop": False},
    "paper": {"mode": "paper", "loss": "paper"},
}
HOLD_OPTIONS: dict[str, dict[str, Any]] = {
    "vertex-hold": {"attack": "vertex-hold"},
    "vertex-hold-budget": {"attack": "vertex-hold", "query_budget": 1},
    "vertex-hold-picker": {"attack": "vertex-hold", "picker": 8},
    "vertex-check-picker": {"attack": "vertex-check", "picker": 8},
    "vertex-check-below": {"attack": "vertex-check", "picker": 8, "check_below": 0.6},
}


def cases() -> dict[str, dict[str, Any]]:
    found = {f"{name}/{label}": {"attack": name, **options}
             for name, cls in ATTACKS.items() if cls.search for label, options in SEARCH_OPTIONS.items()}
    return {**found, **HOLD_OPTIONS}


COUNTS = ("success", "already", "iterations", "queries")  # compared bit for bit
FLOATS = ("x_adv", "linf", "l2", "adv_outputs", "clean_outputs")  # compared to TOLERANCE, per row
TOLERANCE = 1e-4  # absolute; the values are sums of magnitude < 10 (float32 ulp there < 1e-6)


def toy_picker(candidates: int) -> Picker:
    """A fixed small MLP (seeded, drawn by numpy): what it rates does not matter, only that it is the same
    every run and on every CPU."""
    rng = np.random.default_rng(11)
    net = torch.nn.Sequential(torch.nn.Linear(25, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.from_numpy(rng.standard_normal(tuple(p.shape)).astype(np.float32)))
    return Picker(net, candidates=candidates, switch=0.2)


def _record(digest: Any, floats: list[float], result: AttackResult) -> None:
    """Add one step's counts (and every field's dtype and shape) to `digest`, its floats to `floats`."""
    for name in COUNTS + FLOATS:
        value = np.ascontiguousarray(getattr(result, name))
        digest.update(f"{name}{value.dtype}{value.shape}".encode())
        if name in COUNTS:
            digest.update(value.tobytes())
        else:  # one number per row
            floats.extend(value.reshape(len(value), -1).astype(np.float64).sum(axis=1).tolist())
    for record in result.trace:
        for key in sorted(record):
            digest.update(key.encode())
            floats.append(float(np.asarray(record[key], dtype=np.float64).sum()))


@one_torch_thread  # the toys' tiny matmuls: threads only wait for each other on a busy machine
def run(case: dict[str, Any], seed: int) -> dict[str, Any]:
    """The record of `STEPS` consecutive attacked steps of `ROWS` rows (one seed per row): the digest of
    their counts and their floats."""
    options = dict(case)
    kind, trace = options.pop("kind", "discrete"), options.pop("trace", False)
    picker, check_below = options.pop("picker", None), options.pop("check_below", None)
    # rows are never mixed in a victim call (no calibration copy): what one-row runs get, and no per-case
    # calibration queries (the driver's logic is what is pinned here, not the oracle's batching)
    victim = dataclasses.replace(portable_victim(seed=3, kind=kind), calibrate=None)
    steps = {} if options["attack"] in ("vertex-hold", "vertex-check") else {"steps": 6, "n_directions": 4}
    folder = {"adversary": blind_picker(0.1)} if options["attack"] == "vertex-check" else {}
    spec = AttackSpec(**{"eps": 0.1, **readable(options["attack"], **{**steps, **options}), **folder})
    attack, objective, oracle = spec.build(victim, **context(kind))
    if picker is not None:  # a picker held in memory (a folder's is an MLP fitted by picker-train)
        attack.use_picker(toy_picker(picker), {"target": 3, "tol": None})
    if check_below is not None:
        attack.check_below = check_below
    attack.reseed([seed * 100 + r for r in range(ROWS)])
    digest, floats = hashlib.sha256(), []
    for t in range(STEPS):
        x0 = observations(ROWS, seed=seed * 10 + t)
        _record(digest, floats, attack.perturb(x0, oracle, objective, trace=trace))
    return {"counts": digest.hexdigest(), "floats": [float(f"{v:.9g}") for v in floats]}


def _all() -> dict[str, dict[str, Any]]:
    return {f"{name}@{seed}": run(case, seed) for name, case in cases().items() for seed in SEEDS}


@pytest.mark.parametrize("name", list(cases()))
def test_perturb_returns_what_it_returned(name: str) -> None:
    golden = json.loads(GOLDEN.read_text())
    for seed in SEEDS:
        got, want = run(cases()[name], seed), golden[f"{name}@{seed}"]
        assert got["counts"] == want["counts"], f"{name} seed {seed}: success, iterations or queries differ"
        assert len(got["floats"]) == len(want["floats"]), f"{name} seed {seed}: another number of values"
        np.testing.assert_allclose(got["floats"], want["floats"], rtol=0, atol=TOLERANCE,
                                   err_msg=f"{name} seed {seed}")


def test_the_tolerance_still_sees_a_small_change(monkeypatch: pytest.MonkeyPatch) -> None:
    """Cross-CPU drift is below `TOLERANCE`; a small change of SPSA's Adam (beta2 0.999 -> 0.998) is not."""
    from zodrive.attacks.spsa import SPSA

    start = SPSA.start

    def changed(self: SPSA, x0: np.ndarray) -> None:
        start(self, x0)
        self._adam.param_groups[0]["betas"] = (0.9, 0.998)

    monkeypatch.setattr(SPSA, "start", changed)
    golden = json.loads(GOLDEN.read_text())
    moved = max(np.max(np.abs(np.subtract(run(cases()["spsa/continuous"], seed)["floats"],
                                          golden[f"spsa/continuous@{seed}"]["floats"]))) for seed in SEEDS)
    assert moved > 3 * TOLERANCE


def test_every_registered_attack_has_golden_digests() -> None:
    golden = json.loads(GOLDEN.read_text())
    assert set(golden) == {f"{name}@{seed}" for name in cases() for seed in SEEDS}
    assert {case["attack"] for case in cases().values()} == set(ATTACKS)


if __name__ == "__main__":  # record the digests again (a meant change of behaviour only)
    sys.path.insert(0, str(Path(__file__).parent))
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(_all(), sort_keys=True).replace('}, "', '},\n "') + "\n")
    print(f"wrote {GOLDEN}")
