"""Transfer from a surrogate (`--attack transfer:DIR`): crafted on a copy the attacker fitted, fed unasked.

Papernot, McDaniel, Goodfellow, "Transferability in Machine Learning: from Phenomena to Black-Box Attacks
using Adversarial Samples", 2016; for RL policies, Huang et al. 2017 and Behzadan & Munir 2017. The
attacker never queries the victim while it attacks. Before, it watched the victim drive clean episodes
on tuning seeds and fitted an MLP to the actions it saw (behaviour cloning: `zodrive surrogate-train`,
`zodrive.training.surrogate`); watching is observation, not queries, and the folder records how many
decisions it watched. At each step the attack runs PGD (Madry et al., ICLR 2018) on the surrogate
(white-box: the surrogate is the attacker's own network) toward the objective, every iterate projected
into the threat model, and feeds the result. Whether it transferred is judged after the attack has
returned, by the harness (`zodrive.system.referee`), never seen by the attack.

Why PGD on the surrogate and not a black-box search on it: the surrogate is the attacker's, so its
gradient costs nothing, and a query-based search on it would only estimate that gradient. The margin
`kappa` is how far past the surrogate's boundary the attack goes (the surrogate's logits are log-odds of
the victim's action: a perturbation that barely flips the surrogate transfers less often).

The folder holds `surrogate.json` (what it was fitted against, its shape) and `surrogate.npz` (the MLP's
weights, read with `numpy.load(allow_pickle=False)`: nothing is unpickled).

Queries per environment step: 0.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError

NAME = "transfer"
META_FILE = "surrogate.json"
WEIGHTS_FILE = "surrogate.npz"
FORMAT = 1
KEYS = ("format", "victim", "victim_sha256", "preset", "obs_shape", "n_actions", "widths")
MAX_WIDTH, MAX_LAYERS = 4096, 8  # a stranger's description cannot make the loader allocate more
LAYER = re.compile(r"^(weight|bias)_(\d)$")


def network(inputs: int, widths: list[int], outputs: int) -> torch.nn.Sequential:
    """The surrogate's MLP: the flattened observation -> one logit per action (ReLU between layers)."""
    layers: list[torch.nn.Module] = []
    for width in widths:
        layers += [torch.nn.Linear(inputs, width), torch.nn.ReLU()]
        inputs = width
    return torch.nn.Sequential(*layers, torch.nn.Linear(inputs, outputs))


def linears(net: torch.nn.Sequential) -> list[torch.nn.Linear]:
    return [m for m in net if isinstance(m, torch.nn.Linear)]


def save_weights(net: torch.nn.Sequential, path: Path) -> None:
    """The MLP's weights as plain float32 arrays (`weight_i`, `bias_i`) in an .npz: no pickle to write or read."""
    arrays: dict[str, Any] = {}
    for i, layer in enumerate(linears(net)):
        arrays[f"weight_{i}"] = layer.weight.detach().numpy().astype(np.float32)
        arrays[f"bias_{i}"] = layer.bias.detach().numpy().astype(np.float32)
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)


def load_surrogate(folder: str | Path) -> tuple[torch.nn.Sequential, dict[str, Any]]:
    """The surrogate in `folder` (in eval mode) and its description, or a one-line error; the weights are
    read with `allow_pickle=False`, so an .npz holding objects is refused, not unpickled."""
    meta = read_meta(folder)
    net = network(int(np.prod(meta["obs_shape"])), list(meta["widths"]), int(meta["n_actions"]))
    path = Path(folder) / WEIGHTS_FILE
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.asarray(data[name]) for name in data.files}
    except Exception as exc:  # truncated, not an npz, or object arrays (which would need pickle)
        raise ZodriveError(f"{path} is not a surrogate's weights ({type(exc).__name__})") from None
    layers = linears(net)
    expected = {f"{kind}_{i}" for i in range(len(layers)) for kind in ("weight", "bias")}
    if set(arrays) != expected:
        raise ZodriveError(f"{path} does not fit the network {META_FILE} describes")
    for i, layer in enumerate(layers):
        for kind in ("weight", "bias"):
            array = arrays[f"{kind}_{i}"]
            target = getattr(layer, kind)
            if array.dtype != np.float32 or array.shape != tuple(target.shape) or not np.all(np.isfinite(array)):
                raise ZodriveError(f"{path} does not fit the network {META_FILE} describes")
            with torch.no_grad():
                target.copy_(torch.from_numpy(array))
    return net.eval(), meta


def read_meta(folder: str | Path) -> dict[str, Any]:
    """A surrogate's `surrogate.json`, typed and bounded, or a one-line error saying what is missing."""
    from zodrive.attacks.learned import read_description

    meta = read_description(folder, (META_FILE, WEIGHTS_FILE), KEYS, FORMAT, kind="surrogate", being="a surrogate",
                            how="fit one with `zodrive surrogate-train`")
    if not _well_typed(meta):
        raise ZodriveError(f"{Path(folder) / META_FILE} holds a value of the wrong type or out of range")
    return meta


def _count(value: Any, most: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= most


def _well_typed(meta: dict[str, Any]) -> bool:
    """Every field a surrogate's description gives has the type and range zodrive writes."""
    shape, widths = meta["obs_shape"], meta["widths"]
    return (isinstance(meta["victim"], str) and isinstance(meta["victim_sha256"], str)
            and isinstance(meta["preset"], dict)
            and isinstance(shape, list) and len(shape) >= 1 and all(_count(d, 10_000) for d in shape)
            and _count(int(np.prod(shape)), 1_000_000) and _count(meta["n_actions"], 10_000)
            and isinstance(widths, list) and 1 <= len(widths) <= MAX_LAYERS
            and all(_count(w, MAX_WIDTH) for w in widths))


def check_surrogate(folder: str | Path, *, model_file: str, preset: dict[str, Any], defense: str | None) -> None:
    """Refuse a surrogate fitted to another model file or preset, or run behind a defense (one line)."""
    from zodrive.attacks.learned import check_fitted_against

    check_fitted_against(read_meta(folder), f"surrogate {folder} was fitted", "fit", model_file=model_file,
                         preset=preset)
    if defense is not None:
        raise ZodriveError("a surrogate is fitted to the undefended model's decisions: drop --defense")


def digest(folder: str | Path) -> str:
    """The SHA-256 of a surrogate's weights and description together: what an evaluation's key records (a
    refitted surrogate is another attack)."""
    from zodrive.runinfo import sha256

    return "sha256:" + sha256(Path(folder) / WEIGHTS_FILE) + "+" + sha256(Path(folder) / META_FILE)


class Transfer(Attack):
    """PGD on a surrogate fitted from the victim's observed decisions; the point is fed unasked.

    Queries per environment step: 0."""

    name = NAME
    search = False
    refereed = True  # it never asks the victim: the harness judges each step after it (so a base rate is known)
    no_search = "transfer runs PGD on its surrogate and never queries the victim"
    reads: ClassVar[frozenset[str]] = frozenset({"steps", "step_size", "kappa", "target"})
    reference = "Papernot et al., transferability of adversarial samples, 2016; PGD (Madry et al., ICLR 2018)"
    trained = "surrogate"

    @classmethod
    def check_folder(cls, folder: str | None, *, model_file: str, preset: dict[str, Any], defense: str | None,
                     defense_version: int | None = None) -> None:
        if folder is not None:  # (none: building the attack says that it needs one)
            check_surrogate(folder, model_file=model_file, preset=preset, defense=defense)

    @classmethod
    def folder_digest(cls, folder: str) -> str:
        return digest(folder)

    def __init__(self, threat: ThreatModel, *, adversary: str | None = None, **kwargs: Any) -> None:
        """`adversary`: the surrogate's folder (`transfer:DIR`, written by `zodrive surrogate-train`)."""
        super().__init__(threat, **kwargs)
        if adversary is None:
            raise ZodriveError("attack transfer needs a surrogate: --attack transfer:DIR (a folder written by "
                               "`zodrive surrogate-train`)")
        if threat.mode != "budgeted":
            raise ZodriveError("attack transfer: mode paper has no budget; the surrogate's PGD projects onto the "
                               "eps-ball")
        self.folder = str(adversary)
        self.net, self.meta = load_surrogate(self.folder)
        for p in self.net.parameters():
            p.requires_grad_(False)

    def queries_per_run(self, steps: int | None = None) -> int:
        return 0

    def first_iteration_cost(self) -> int:
        return 0

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        raise AssertionError("transfer takes no search step")  # perturb is its own

    def logits(self, flat: torch.Tensor) -> torch.Tensor:
        """The surrogate's logits (N, actions) of flattened observations, row by row (a row's logits do not
        depend on the batch it came in: lockstep = one-row runs)."""
        return torch.cat([self.net(flat[i:i + 1]) for i in range(len(flat))])

    def perturb(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
                ) -> AttackResult:
        """T signed-gradient steps of size `step_size` on the objective over the surrogate's logits, from the
        clean point, each iterate projected into the threat model; the iterate with the lowest surrogate loss
        is fed (the first, on a tie). No victim query."""
        n, shape = len(x0), tuple(x0.shape[1:])
        if tuple(self.meta["obs_shape"]) != shape:
            raise ZodriveError(f"surrogate {self.folder} was fitted on observations of shape "
                               f"{tuple(self.meta['obs_shape'])}, not {shape}")
        oracle.begin_step(rows=n)
        x0 = np.asarray(x0, dtype=np.float32)
        flat0 = x0.reshape(n, -1)
        around = self.threat.around(flat0, shape, integer=np.issubdtype(x0.dtype, np.integer))
        mask = torch.from_numpy(self.threat.mask(shape).reshape(-1))
        everyone = np.arange(n)
        with torch.no_grad():
            clean = self.logits(torch.from_numpy(flat0))
        x = flat0.copy()
        best_x, best_f = x.copy(), np.full(n, np.inf)
        iterations = np.zeros(n, dtype=np.int64)
        for _ in range(self.steps):
            point = torch.from_numpy(x).requires_grad_(True)
            loss = objective.loss(self.logits(point)[:, None], clean)[:, 0]
            loss.sum().backward()
            assert point.grad is not None  # the loss is computed from the point
            f = loss.detach().numpy().astype(np.float64)
            better = f < best_f
            best_x[better], best_f[better] = x[better], f[better]
            iterations += 1
            if np.all(f <= 0):  # every row past the surrogate's boundary by kappa: the gradient is zero
                break
            step = (torch.sign(point.grad) * mask).numpy()
            x = around((x - self.step_size * step)[:, None], everyone)[:, 0].astype(np.float32)
        else:
            with torch.no_grad():
                f = objective.loss(self.logits(torch.from_numpy(x))[:, None], clean)[:, 0].numpy()
            better = f < best_f
            best_x[better] = x[better]
        x_adv = best_x.reshape(x0.shape)
        linf, l2 = distortion(x_adv, x0)
        nothing = np.full((n, 0), np.nan, dtype=np.float32)  # no victim output is asked; the referee judges
        return AttackResult(x_adv=x_adv, success=np.zeros(n, dtype=bool), already=np.zeros(n, dtype=bool),
                            iterations=iterations, queries=oracle.row_queries.copy(), linf=linf, l2=l2,
                            adv_outputs=nothing, clean_outputs=nothing.copy())
