"""`zodrive certify`: a model's clean states bounded from below (CROWN certificates, `certify`), from
above (attacks, `certify.sandwich`) and, on request, decided (`exact`): the one place the three meet, so
that neither the bounds nor the exact check depends on the other's module."""

from __future__ import annotations

from typing import Any

import numpy as np

from zodrive.evaluation import certify as bounds  # its functions looked up when called (tests replace the episodes)
from zodrive.evaluation.certify import certify, sandwich
from zodrive.evaluation.exact import attack_gap, exact_network, exact_summary, min_eps, min_eps_summary


def certify_model(model: str, preset: dict[str, Any], eps_values: list[float], *, episodes: int, seed: int,
                  tol: float = 0.2, attacks: tuple[str, ...] = (), exact_limit: float | None = None,
                  min_eps_steps: int = 0, state_count: int | None = None,
                  query_budget: int | None = None) -> dict[str, Any]:
    """The certified share of a model's clean states at each eps (see `certify`; the states of
    `episodes` clean episodes, or with `state_count` only the first that many), for each of `attacks` its
    success on the same states (`sandwich`, at most `query_budget` queries a state), and with `exact_limit` (seconds per
    state) the complete verdicts of `exact.exact` on them: then each attack's distance from optimal
    (`exact.attack_gap`: its misses among the exactly attackable states, alone and for the union of
    the black-box attacks), per-state verdicts and wins as strings (`per_state`), and with
    `min_eps_steps` > 0 each state's smallest radius that changes its action (`exact.min_eps`)."""
    from zodrive.attacks.spec import AttackSpec
    from zodrive.envs import scenario
    from zodrive.policies.loading import load_network, raw_network_only
    from zodrive.policies.victims import network_victim

    raw_network_only(model, "certify")
    network = load_network(model, preset)  # rebuilt from plain data; nothing unpickled
    if exact_limit is not None:
        exact_network(network.net, network.kind)  # a network --exact cannot decide is refused before any episode
    env = scenario(preset)
    victim = network_victim(network.net, network.kind, network.obs_shape)
    if state_count is None:
        states = bounds.episode_states(preset, victim, seed, episodes)
    else:  # the first `state_count` observations; `episodes`: how many episodes they span
        states, episodes = bounds.first_states(preset, victim, seed, episodes, state_count)
    mask = AttackSpec(eps=max(eps_values)).threat(env.features, env.bounds).mask(states.shape[1:])  # no eps in it
    wins: dict[str, list[np.ndarray]]
    rows, verdicts, wins = [], [], {name: [] for name in attacks}
    for eps in eps_values:
        cert = certify(network.net, network.kind, states, eps, mask, *env.bounds, tol=tol)
        row: dict[str, Any] = {"eps": eps, "certified_share": float(cert.certified.mean()),
                               "states": len(states), "mean_bound": float(np.mean(cert.bound))}
        if attacks:  # from above: each attack, and the states any of them won
            sides = [sandwich(states, cert.certified, name, eps, victim, preset, seed, tol, query_budget)
                     for name in attacks]
            row["attacks"] = [side for side, _ in sides]
            anyone = np.any([won for _, won in sides], axis=0)
            row["any_attack"] = {"success_share": float(anyone.mean()),
                                 "unknown_share": 1.0 - float(anyone.mean()) - row["certified_share"]}
            for name, (_, won) in zip(attacks, sides):
                wins[name].append(won)
        if exact_limit is not None:
            row["exact"], result = exact_summary(network.net, network.kind, states, eps, mask, env.bounds, exact_limit,
                                                 cert.certified, anyone if attacks else None)
            verdicts.append(result.verdict)
            row["per_state"] = {"crown": _bits(cert.certified),
                                "exact": "".join(str(v)[0] for v in result.verdict)}  # r / a / u
            if attacks:
                black = [won for side, won in sides if not side["white_box"]]
                for side, won in sides:
                    side["vs_exact"] = attack_gap(result.verdict, won)
                    row["per_state"][side["attack"]] = _bits(won)
                row["exact"]["black_box_ensemble"] = {
                    "attacks": [side["attack"] for side, _ in sides if not side["white_box"]],
                    **(attack_gap(result.verdict, np.any(black, axis=0)) if black else {})}
        rows.append(row)
    out = {"model": model, "preset": preset.get("name"), "kind": network.kind, "seed": seed, "episodes": episodes,
           "method": "CROWN (Zhang et al. 2018) on ReLU networks, interval bounds (Gowal et al. 2018) otherwise",
           "exact_method": None if exact_limit is None else (
               "MILP per state (Tjeng et al. 2019: big-M on CROWN's bounds, HiGHS) after a gradient search; "
               "every counterexample confirmed by the float32 network"),
           "tol": tol if network.kind == "continuous" else None, "query_budget": query_budget, "rows": rows}
    if exact_limit is not None and min_eps_steps > 0:
        found = min_eps(network.net, network.kind, states, eps_values, verdicts, mask, env.bounds, exact_limit,
                        steps=min_eps_steps)
        out["min_eps"] = min_eps_summary(found, eps_values, verdicts,
                                         {name: np.stack(won) for name, won in wins.items()}, min_eps_steps)
    return out


def _bits(flags: np.ndarray) -> str:
    """A per-state bool array as a string of 0 and 1 (state i is character i)."""
    return "".join("1" if f else "0" for f in flags)
