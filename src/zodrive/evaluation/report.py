"""Human-readable summaries of evaluations, and the pyplot setup every figure shares."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def format_summary(summary: dict[str, Any]) -> str:
    """A few lines a person reads: return with CI, collisions, and the attack's numbers."""
    low, high = summary["ci95"]
    lines = [
        f"episodes: {summary['episodes']} "
        + (f"(seed {summary['seed']})" if summary['episodes'] == 1
           else f"(seeds {summary['seed']}..{summary['seed'] + summary['episodes'] - 1})"),
        f"mean return: {summary['mean_return']:.2f}  "
        + (f"95% CI [{low:.2f}, {high:.2f}]  " if summary["episodes"] > 1 else "(no CI from one episode)  ")
        + (f"({summary['pct_of_max']:.2f}% of max)" if summary.get("pct_of_max") is not None else ""),
    ]
    if summary.get("mean_speed") is not None and summary["mean_speed"] == summary["mean_speed"]:  # a road
        lines.append(
            f"collision rate: {summary['collision_rate']:.2%}  ended off-road: {summary.get('offroad_rate', 0):.2%}  "
            f"on road: {or_dash(summary.get('on_road_share'), '{:.1%}')} of steps  "
            f"mean length: {summary['mean_length']:.1f}  mean speed: {summary['mean_speed']:.1f} m/s  "
            "lane changes/episode: "
            f"{or_dash(summary.get('lane_changes_per_episode'), '{:.2f}')}  path: "
            f"{or_dash(summary.get('mean_path_length'), '{:.0f}')} m  right lane: {summary['right_lane_share']:.1%}")
    else:  # not a highway-env road: no driving metrics
        lines.append(f"mean length: {summary['mean_length']:.1f} steps")
    if summary.get("defense"):
        lines.append(f"defense: {summary['defense']} (between the sensor and the policy; the attacker queries the "
                     "defended system)")
    if summary.get("attack"):
        lines.append(
            f"attack: {summary['attack']} ("
            + (f"{summary['norm']}, eps={summary['eps']}" + (f" ({summary['eps_means']})" if summary.get("eps_means")
                                                              else "") + ", budgeted" if summary.get("eps") is not None
               else "unconstrained: paper mode, no budget")
            + _goal_and_folder(summary) + ")"
            + _options(summary.get("attack_config") or {})
        )
        if summary["attack_success_rate"] is None:  # a learned adversary: no per-step goal
            lines.append(f"attack success: n/a (the adversary lowers the return over the episode, no per-step "
                         f"target); {summary['queries_per_step']:.1f} queries/step; max Linf {summary['max_linf']:.4f}")
        elif summary.get("target_base_rate", 0.0) is None:  # the clean observation was never queried
            rate, checked = f"{summary['attack_success_rate']:.1%}", summary["attack"] == "vertex-check"
            what = (f"a check confirmed the target on {rate} of steps (a vertex fed unasked is not counted: see "
                    "action_share; " if checked else f"the target taken on {rate} of steps (")
            lines.append(f"attack success: {what}the clean observation is not queried: no base rate); "
                         f"{summary['queries_per_step']:.{2 if checked else 1}f} queries/step; max Linf "
                         f"{summary['max_linf']:.4f}")
        else:
            untargeted = summary.get("target") in (None, "none")
            rate = summary["attack_success_rate"]
            if rate != rate:  # nan: no step was left to attack
                what = ("n/a (no step left to attack: " + ("none" if untargeted else
                        "the clean policy already took the target on every step") + ")")
            elif untargeted:
                what = f"{rate:.1%} of steps changed the policy's action"
            else:
                what = f"{rate:.1%} of steps where the clean policy did not already take the target"
            lines.append(
                f"attack success: {what} (base rate {_percent(summary['target_base_rate'])}); "
                f"{summary['queries_per_step']:.1f} queries/step; max Linf {summary['max_linf']:.4f}"
            )
        if summary.get("victim_rows", {}).get("referee"):  # transfer: the harness judged each step
            lines.append(f"transfer judged by the harness after each step: {summary['victim_rows']['referee']} victim "
                         "rows (the clean and the fed observation), counted apart and never seen by the attack")
        if summary.get("attacked_share") is not None:  # a frequency budget: queries/step are per attacked step
            rows = summary["victim_rows"]
            lines.append(f"attacked steps: {summary['attacked_share']:.1%} of {rows['decisions']} decisions "
                         f"(frequency budget); {rows['attack_queries']} attack queries in all")
    return "\n".join(lines)


def _percent(value: float | None) -> str:
    return "n/a" if value is None or value != value else f"{value:.1%}"


def _goal_and_folder(summary: dict[str, Any]) -> str:
    """`, target=T` for an attack with a per-step goal (`Attack.goal`), and what its trained folder holds
    (`Attack.trained`: `, picker DIR`, `, surrogate DIR`; the learned adversary, which has no goal:
    `, adversary DIR`)."""
    from zodrive.attacks.registry import attack_class
    from zodrive.errors import ZodriveError

    try:
        kind = attack_class(summary["attack"])
        goal, trained = kind.goal, kind.trained
    except ZodriveError:  # a summary of an attack this zodrive does not know
        goal, trained = True, ""
    folder = (summary.get("attack_config") or {}).get("adversary")
    held = f", {trained} {folder}" if trained and folder else ""
    return f", target={summary['target']}{held}" if goal else held


def _options(config: dict) -> str:
    """The attack's options that differ from AttackSpec's defaults (e.g. max_change=0.01)."""
    from zodrive.attacks.spec import AttackSpec

    shown = {"attack", "eps", "norm", "mode", "target", "seed", "frozen", "adversary"}
    default = AttackSpec().to_dict()
    changed = [f"{k}={v}" for k, v in config.items() if k not in shown and k in default and v != default[k]]
    return f" {', '.join(changed)}" if changed else ""


def plural(count: int, word: str) -> str:
    """'1 episode', '3 episodes'."""
    return f"{count} {word}" + ("" if count == 1 else "s")


def or_dash(value: float | None, pattern: str) -> str:
    """`value` formatted with `pattern`, or a dash where it was not measured (None)."""
    return "–" if value is None else pattern.format(value)


def headless_pyplot():
    """matplotlib's pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path, dpi: float | str = 120) -> None:
    """Lay `fig` out, write it to `path` (making its folder) and close it."""
    plt = headless_pyplot()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
