"""Per-state certificates: where no perturbation inside the threat model can change the action.

The threat model's box around a state (L-inf radius eps on the free features, clipped to the
observation box, never moving a clean value; an L2 ball lies inside the same box) is bounded
through the policy network the safe loader rebuilds, in float64:

- ReLU networks (DQN, QR-DQN, DDPG, TD3, SAC by default): CROWN (Zhang et al., "Efficient
  Neural Network Robustness Certification with General Activation Functions", NeurIPS 2018):
  linear bounds propagated backwards through each ReLU's linear relaxation, layer by layer,
  with adaptive lower slopes; the specification (score differences, or each action dimension)
  is bounded directly, not from intervals of the outputs.
- other monotone activations (PPO's Tanh): interval bound propagation (IBP; Gowal et al. 2018),
  looser, with the last affine map applied to the score differences.

What is certified:

- discrete policies: the action a* on the clean state is certified when, for every other
  action j, the lower bound of score(a*) - score(j) over the box exceeds `SLACK` (which
  covers the float32 rounding of the network itself);
- continuous policies: a bound on how far each action dimension can move from the clean action.

Sound, not complete: a state that is not certified may still be robust. With the attack's
success rate from above and the certified share from below, the truth is sandwiched; the gap
is what neither knows. No queries: this reads the weights (a white-box tool, labelled so).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from zodrive.errors import ZodriveError
from zodrive.system import build_attacker

SLACK = 1e-4  # a certified margin must exceed this: the float32 network rounds, the bound does not
MONOTONE = (nn.ReLU, nn.Tanh, nn.Sigmoid, nn.ELU, nn.LeakyReLU, nn.Softplus, nn.SELU)


@dataclass(frozen=True)
class Certificate:
    certified: np.ndarray      # (N,) bool: discrete: the action cannot change; continuous: moves <= tol
    bound: np.ndarray          # (N,) discrete: the certified margin lower bound; continuous: max |change|


def threat_box(x0: np.ndarray, eps: float | np.ndarray, mask: np.ndarray, low: float,
               high: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate bounds (N, dim) of every point the threat model allows around x0 (N, dim); `eps` one
    radius, or one per state (N, 1)."""
    delta = eps * mask[None]
    lo = np.maximum(x0 - delta, np.minimum(low, x0))
    hi = np.minimum(x0 + delta, np.maximum(high, x0))
    return lo, hi


def _layers(net: nn.Module) -> tuple[list[nn.Module], str, Any]:
    """The network as a list of layers and what follows its last affine map (see ActingNetwork)."""
    from zodrive.policies.safe_load import ActingNetwork

    post, owner = "none", None
    if isinstance(net, ActingNetwork):
        post, owner, net = net.post, net, net.body
    if not isinstance(net, nn.Sequential):
        raise ZodriveError("certificates need the rebuilt MLP of an SB3 zip (Linear layers and activations)")
    layers = list(net)
    for layer in layers:
        if not isinstance(layer, (nn.Linear, *MONOTONE, nn.Flatten)):
            raise ZodriveError(f"cannot bound through {type(layer).__name__}: certificates cover Linear layers "
                               "and monotone activations")
    return layers, post, owner


def _interval(layers: list[nn.Module], lo: torch.Tensor, hi: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    for layer in layers:
        if isinstance(layer, nn.Flatten):
            continue
        if isinstance(layer, nn.Linear):
            w, b = layer.weight.double(), layer.bias.double()
            mid, rad = (hi + lo) / 2, (hi - lo) / 2
            center, radius = mid @ w.T + b, rad @ w.abs().T
            lo, hi = center - radius, center + radius
        else:  # monotone non-decreasing and parameter-free: the bounds map to bounds
            lo, hi = layer(lo), layer(hi)
    return lo, hi


def _relu_mlp(layers: list[nn.Module]) -> list[tuple[torch.Tensor, torch.Tensor]] | None:
    """(W, b) of each Linear layer if the network is Linear (ReLU Linear)*, else None."""
    body = [layer for layer in layers if not isinstance(layer, nn.Flatten)]
    linears = body[0::2]
    if not all(isinstance(layer, nn.Linear) for layer in linears) or not all(
            isinstance(layer, nn.ReLU) for layer in body[1::2]) or len(body) != 2 * len(linears) - 1:
        return None
    return [(layer.weight.double(), layer.bias.double()) for layer in cast(list[nn.Linear], linears)]


def _crown_lower(spec: torch.Tensor, top: int, affine: list[tuple[torch.Tensor, torch.Tensor]],
                 pre: list[tuple[torch.Tensor, torch.Tensor]], lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Lower bound (N, m) of spec @ z_top over the input box, where z_top is the pre-activation of
    layer `top` (spec (N, m, n_top)); `pre` holds the bounds of the pre-activations below it."""
    w, b = affine[top]
    a = spec @ w                                           # (N, m, n_{top-1})
    const = spec @ b
    for j in range(top - 1, -1, -1):                       # through ReLU j and Linear j
        lj, uj = pre[j]
        unstable = (lj < 0) & (uj > 0)
        up_slope = torch.where(uj <= 0, 0.0, torch.where(lj >= 0, 1.0, uj / (uj - lj).clamp(min=1e-12)))
        up_shift = torch.where(unstable, -up_slope * lj, 0.0)
        low_slope = torch.where(uj <= 0, 0.0, torch.where(lj >= 0, 1.0, (uj > -lj).double()))
        pos, neg = a.clamp(min=0), a.clamp(max=0)
        a = pos * low_slope[:, None] + neg * up_slope[:, None]
        const = const + (neg * up_shift[:, None]).sum(-1)
        w, b = affine[j]
        const = const + a @ b
        a = a @ w
    mid, rad = (hi + lo) / 2, (hi - lo) / 2
    return (a @ mid[:, :, None])[..., 0] - (a.abs() @ rad[:, :, None])[..., 0] + const


def crown_pre(affine: list[tuple[torch.Tensor, torch.Tensor]], lo: torch.Tensor,
              hi: torch.Tensor) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """CROWN bounds (lower, upper), each (N, n_k), of every hidden pre-activation of a ReLU MLP
    over the box [lo, hi] (N, dim), layer by layer (each layer's bounds use those below it)."""
    pre: list[tuple[torch.Tensor, torch.Tensor]] = []
    for k in range(len(affine) - 1):
        eye = torch.eye(affine[k][0].shape[0], dtype=torch.float64).expand(len(lo), -1, -1)
        lower = _crown_lower(eye, k, affine, pre, lo, hi)
        upper = -_crown_lower(-eye, k, affine, pre, lo, hi)
        pre.append((lower, upper))
    return pre


def _crown(affine: list[tuple[torch.Tensor, torch.Tensor]], spec: torch.Tensor, lo: torch.Tensor,
           hi: torch.Tensor, pre: list[tuple[torch.Tensor, torch.Tensor]] | None = None) -> torch.Tensor:
    """Lower bound (N, m) of spec @ f(x) for a ReLU MLP f over the box [lo, hi] (N, dim)."""
    pre = crown_pre(affine, lo, hi) if pre is None else pre
    return _crown_lower(spec, len(affine) - 1, affine, pre, lo, hi)


def score_head(layers: list[nn.Module], post: str, owner: Any) -> tuple[int, torch.Tensor, torch.Tensor]:
    """Index of a discrete policy's last Linear layer and its (W, b) in float64, giving the scores
    (QR-DQN: the mean over quantiles is linear, folded into W and b)."""
    last = max(i for i, layer in enumerate(layers) if isinstance(layer, nn.Linear))
    if any(isinstance(layer, MONOTONE) for layer in layers[last + 1:]):
        raise ZodriveError("a discrete policy's scores must come out of a Linear layer")
    head = cast(nn.Linear, layers[last])
    w, b = head.weight.double(), head.bias.double()
    if post == "quantiles":
        q = owner.n_quantiles
        w = w.view(q, -1, w.shape[1]).mean(dim=0)
        b = b.view(q, -1).mean(dim=0)
    return last, w, b


def relu_scores(net: nn.Module) -> list[tuple[torch.Tensor, torch.Tensor]] | None:
    """(W, b) in float64 of each Linear layer of a discrete policy that is a ReLU MLP, the last one
    giving the scores (see `score_head`); None if the network is not Linear (ReLU Linear)*."""
    layers, post, owner = _layers(net)
    affine = _relu_mlp(layers)
    if affine is None:
        return None
    _, w, b = score_head(layers, post, owner)
    return affine[:-1] + [(w, b)]


def box_of(x0: np.ndarray, eps: float | np.ndarray, mask: np.ndarray, low: float,
           high: float) -> tuple[torch.Tensor, ...]:
    """The flattened states (N, dim) and their threat boxes' bounds, as float64 tensors."""
    flat = torch.as_tensor(np.asarray(x0, dtype=np.float64).reshape(len(x0), -1))
    lo, hi = threat_box(flat.numpy(), eps, np.asarray(mask, dtype=np.float64).reshape(-1), low, high)
    return flat, torch.as_tensor(lo), torch.as_tensor(hi)


def certify(net: nn.Module, kind: str, x0: np.ndarray, eps: float, mask: np.ndarray, low: float, high: float,
            *, tol: float = 0.2, chunk: int = 64) -> Certificate:
    """Certificates for the clean states `x0` (N, ...); see the module docstring. States are
    bounded `chunk` at a time (CROWN holds an (n, n) matrix per state and layer)."""
    if len(x0) > chunk:
        parts = [certify(net, kind, x0[i:i + chunk], eps, mask, low, high, tol=tol, chunk=chunk)
                 for i in range(0, len(x0), chunk)]
        return Certificate(np.concatenate([p.certified for p in parts]), np.concatenate([p.bound for p in parts]))
    layers, post, owner = _layers(net)
    flat, lo, hi = box_of(x0, eps, mask, low, high)
    with torch.no_grad():
        clean = net(flat.float()).double()
        if kind == "discrete":
            action = clean.argmax(dim=1)
            lower = margins(net, action, lo, hi)
            margin = lower.min(dim=1).values
            return Certificate(certified=(margin > SLACK).numpy(), bound=margin.numpy())
        squash = isinstance(layers[-1], nn.Tanh) and _relu_mlp(layers[:-1]) is not None
        affine = _relu_mlp(layers[:-1] if squash else layers)
        if affine is not None:  # CROWN on each output (before the final tanh, which is monotone)
            eye = torch.eye(affine[-1][1].shape[0], dtype=torch.float64).expand(len(lo), -1, -1)
            out_lo, out_hi = _crown(affine, eye, lo, hi), -_crown(affine, -eye, lo, hi)
            if squash:
                out_lo, out_hi = torch.tanh(out_lo), torch.tanh(out_hi)
        else:
            out_lo, out_hi = _interval(layers, lo, hi)
        if post in ("unscale", "clip"):  # monotone in each output: the bounds map to bounds
            low_a, high_a = owner.low.double(), owner.high.double()
            if post == "unscale":
                out_lo, out_hi = (low_a + 0.5 * (v + 1.0) * (high_a - low_a) for v in (out_lo, out_hi))
            else:
                out_lo, out_hi = torch.clamp(out_lo, low_a, high_a), torch.clamp(out_hi, low_a, high_a)
        change = torch.maximum(out_hi - clean, clean - out_lo).amax(dim=1) + SLACK
        return Certificate(certified=(change <= tol).numpy(), bound=change.numpy())


def margins(net: nn.Module, action: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor,
            pre: list[tuple[torch.Tensor, torch.Tensor]] | None = None) -> torch.Tensor:
    """Lower bounds (N, k) of score(a*) - score(j) over each box [lo, hi] (N, dim) for a discrete
    policy, a* = `action` (N,) (+inf at j = a*): CROWN on a ReLU MLP (reusing the hidden layers'
    bounds `pre` if given), interval bounds through the body otherwise."""
    with torch.no_grad():
        affine = relu_scores(net)
        if affine is not None:  # CROWN on the score differences
            eye = torch.eye(affine[-1][1].shape[0], dtype=torch.float64)
            lower = _crown(affine, eye[action][:, None, :] - eye[None], lo, hi, pre)
        else:
            layers, post, owner = _layers(net)
            last, w, b = score_head(layers, post, owner)
            h_lo, h_hi = _interval(layers[:last], lo, hi)
            diff_w = w[action][:, None, :] - w[None]          # (N, k, hidden): score(a*) - score(j)
            diff_b = b[action][:, None] - b[None]
            mid, rad = (h_hi + h_lo) / 2, (h_hi - h_lo) / 2
            lower = (diff_w @ mid[:, :, None])[..., 0] - (diff_w.abs() @ rad[:, :, None])[..., 0] + diff_b
        lower[torch.arange(len(lower)), action] = float("inf")  # a* against itself
    return lower


def episode_states(preset: dict[str, Any], victim: Any, seed: int, episodes: int) -> np.ndarray:
    """Every observation of `episodes` clean episodes from seeds seed, seed + 1, ..."""
    return first_states(preset, victim, seed, episodes)[0]


def first_states(preset: dict[str, Any], victim: Any, seed: int, episodes: int,
                 limit: int | None = None) -> tuple[np.ndarray, int]:
    """The observations of clean episodes from seeds seed, seed + 1, ... (at most `episodes` episodes),
    only the first `limit` of them if given, and how many episodes they span."""
    from zodrive.envs import make_env
    from zodrive.evaluation.rollout import act

    env = make_env(preset)
    states: list[np.ndarray] = []
    driven = 0
    while driven < episodes and (limit is None or len(states) < limit):
        obs, _ = env.reset(seed=seed + driven)
        driven += 1
        done = False
        while not done and (limit is None or len(states) < limit):
            states.append(obs)
            obs, _, terminated, truncated, _ = env.step(act(victim, obs, env.action_space))
            done = terminated or truncated
    env.close()
    return np.stack(states), driven


PER_EPISODE = ("warm_start", "max_change", "check_below", "min_gap")
"""Attack settings about an episode's sequence of steps (and the frequency budget, `attack_share` and `when`);
the sandwich attacks each state on its own."""

CHUNK = 512  # states attacked per call


def sandwich(states: np.ndarray, certified: np.ndarray, attack: str, eps: float, victim: Any,
             preset: dict[str, Any], seed: int, tol: float,
             query_budget: int | None = None) -> tuple[dict[str, Any], np.ndarray]:
    """Attack every state on its own with `attack` (untargeted: any other action, or an action
    moved by >= `tol`; its config otherwise, minus what is about episodes, `PER_EPISODE`; at most
    `query_budget` queries a state, as a bench protocol caps a step) at `eps`, beside the certified
    share on the same states. success + certified <= 1 whenever
    the certificate is sound: a state both won and certified is a contradiction (counted, and
    it must be 0); `unknown` = 1 - success - certified is what neither side decides. Returns the
    summary and which states the attack won."""
    from zodrive.attacks.spec import load_attack

    base = load_attack(attack)
    spec = base.with_overrides(eps=eps, target="none", tol=tol, warm_start=False, query_budget=query_budget,
                               attack_share=1.0, when="every",
                               clear=[k for k in PER_EPISODE[1:] if getattr(base, k) is not None])
    attacker, objective, oracle = build_attacker(spec, victim, preset)
    won = np.zeros(len(states), dtype=bool)
    queries = 0
    for start in range(0, len(states), CHUNK):
        rows = np.arange(start, min(start + CHUNK, len(states)))
        attacker.reseed([seed + int(r) for r in rows])  # a state's attack does not depend on the chunking
        result = attacker.perturb(states[rows], oracle, objective)
        won[rows] = result.success | result.already
        queries += int(result.queries.sum())
    success = float(won.mean())
    return {"attack": attack, "white_box": not attacker.black_box, "success_share": success,
            "unknown_share": 1.0 - success - float(certified.mean()),
            "contradictions": int((won & certified).sum()), "queries_per_state": queries / len(states)}, won
