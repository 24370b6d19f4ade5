"""Table 1 and the reproduction report (Markdown and a self-contained HTML page)."""

from __future__ import annotations

import base64
import csv
import html
import io
from pathlib import Path
from typing import Any

from zodrive.drivers.baselines import get_baseline
from zodrive.evaluation import store
from zodrive.evaluation.report import or_dash
from zodrive.evaluation.stats import paired_difference_ci
from zodrive.experiments.paper import ROWS, TABLE1, TABLE1_PCT
from zodrive.runinfo import write_atomic, write_json
from zodrive.seeds import EVAL_SEED


def _returns(out: Path, algo: str, row: str) -> list[float]:
    rows = store.episodes(out / "cells" / f"{algo}-{row}", needs=("episode", "return"), missing_ok=True)
    return [r["return"] for r in sorted(rows, key=lambda r: r["episode"])]


def build_table(summaries: dict[str, dict[str, dict[str, Any]]], out: Path) -> dict[str, Any]:
    """Table 1 as data, and as table1.{json,csv,md} in `out`."""
    records = []
    for algo in ("dqn", "ddpg"):
        clean = _returns(out, algo, "initial")
        baselines = [row for row in summaries[algo] if row.startswith("baseline-")]
        for row in [*ROWS, *baselines]:
            s = summaries[algo][row]
            label = ROWS.get(row) or _baseline_label(row)
            rec = {
                "algo": algo.upper(), "row": label, "mean_return": s["mean_return"],
                "ci95_low": s["ci95"][0], "ci95_high": s["ci95"][1], "pct_of_max": s["pct_of_max"],
                "collision_rate": s["collision_rate"], "episodes": s["episodes"],
                "attack_success_rate": s.get("attack_success_rate"),
                "target_base_rate": s.get("target_base_rate"),
                "queries_per_step": s.get("queries_per_step"), "max_linf": s.get("max_linf"),
                "paper_return": TABLE1[algo].get(row), "paper_pct": TABLE1_PCT[algo].get(row),
                "offroad_rate": s.get("offroad_rate"), "mean_speed": s.get("mean_speed"),
                "lane_changes_per_episode": s.get("lane_changes_per_episode"),
            }
            if row != "initial":
                mine = _returns(out, algo, row)
                if len(mine) == len(clean) and clean:
                    diff, low, high = paired_difference_ci(mine, clean)
                    rec.update(change_vs_initial=diff, change_ci95_low=low, change_ci95_high=high)
            records.append(rec)
    write_json(out / "table1.json", records)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(records[0].keys())
                            + ["change_vs_initial", "change_ci95_low", "change_ci95_high"],
                            extrasaction="ignore")
    writer.writeheader()
    writer.writerows(records)
    write_atomic(out / "table1.csv", buf.getvalue())
    write_atomic(out / "table1.md", table_markdown(records))
    return {"rows": records}


def _baseline_label(row: str) -> str:
    """`baseline-slower` -> `Baseline: always SLOWER` for the table."""
    baseline = get_baseline("baseline:" + row[len("baseline-"):])
    return f"Baseline: {baseline.label}"


def _success(r: dict[str, Any]) -> str:
    rate = r.get("attack_success_rate")
    if rate is None:
        return "–"
    shown = "n/a" if rate != rate else f"{rate:.1%}"  # NaN: the clean policy always chose the target
    return f"{shown} ({or_dash(r['target_base_rate'], '{:.1%}')})"  # no base rate: the clean observation unasked


def table_markdown(records: list[dict[str, Any]]) -> str:
    lines = [
        "| Policy | Scenario | zodrive return (95% CI) | % of 450 | Paper | Paper % | Collisions | Off-road | "
        "Speed (m/s) | Lane changes/ep | Attack success (base rate) | Queries/step | max L∞ |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        success = _success(r)
        lines.append(
            f"| {r['algo']} | {r['row']} | {r['mean_return']:.2f} ({r['ci95_low']:.2f}–{r['ci95_high']:.2f}) | "
            f"{r['pct_of_max']:.2f}% | {or_dash(r['paper_return'], '{:.2f}')} | {or_dash(r['paper_pct'], '{:.2f}%')} | "
            f"{r['collision_rate']:.0%} | {or_dash(r.get('offroad_rate'), '{:.0%}')} | "
            f"{or_dash(r.get('mean_speed'), '{:.1f}')} | "
            f"{or_dash(r.get('lane_changes_per_episode'), '{:.1f}')} | {success} | "
            f"{or_dash(r['queries_per_step'], '{:.0f}')} | "
            f"{or_dash(r['max_linf'], '{:.3f}')} |"
        )
    return "\n".join(lines) + "\n"


FIGURES = [
    ("fig2_loss.png", "Fig. 2 — Loss1 (attack) and Loss2 (distortion) over ZO-SignSGD iterations on a step "
                      "the attack won (early stopping off, L2 weight 0.1)."),
    ("fig3_attacked_episode.png", "Fig. 3 — The attacked DQN at its collision: simulator (left), what it "
                                  "perceived (red outlines) over what was there (green), right."),
    ("fig3_attacked_episode.gif", "Fig. 3 (animated) — the last decisions before the collision."),
    ("fig4_ddpg_adversarial_training.png", "Fig. 4 — DDPG reward per episode during adversarial training."),
    ("fig5_dqn_adversarial_training.png", "Fig. 5 — DQN reward per episode during adversarial training."),
]


def robustness_section(out: Path, episodes: int) -> tuple[str, str, Path | None]:
    """The robustness section's intro, its Markdown table and figure (from out/robustness)."""
    folder = out / "robustness"
    if not episodes or not (folder / "robustness.md").is_file():
        return "", "", None
    intro = (f"Return under the strongest attack inside each ε-ball, at that ε or a smaller one, so that it never "
             f"rises with ε ({_episodes(episodes)}): black-box random search, its defense-aware form that "
             "carries the perturbation and moves it by at most 0.01 per step (random-search-smooth), and white-box "
             "PGD for the networks (through the kinematic filter by BPDA). In brackets: the attack that hurt most "
             "(and its ε where smaller), and the speed. dqn-robust and ddpg-robust are the defended agents, "
             "dqn-sa (SA-DQN) and dqn-at (Algorithm 2) the other training defenses (their cards say how each was "
             "made); baseline:robust-rules@0.02 is the observation rules made pessimistic for ε 0.02; the constant "
             "SLOWER and the constant brake ignore their input and are the floor a defense must beat. "
             "Cells: robustness/table.md.")
    figure = folder / "robustness.png"
    return intro, (folder / "robustness.md").read_text(), figure if figure.is_file() else None


def write_report(out: Path, table: dict[str, Any], figures: dict[str, Any], timings: dict[str, float], *,
                 episodes: int, retrain: bool, quick: bool, robustness_episodes: int = 0) -> None:
    """report.md (figures linked) and report.html (figures embedded, one file)."""
    md_table = table_markdown(table["rows"])
    rob_intro, rob_table, rob_figure = robustness_section(out, robustness_episodes)
    intro = (
        f"Reproduction of Table 1 with {_episodes(episodes)}, "
        f"{'models retrained by this run' if retrain else 'the shipped models in models/'}"
        f"{' (quick mode: not the full study)' if quick else ''}. Attack: ZO-SignSGD, L∞ ε = 0.2, budgeted, "
        "T = 100, q = 20, target FASTER (DQN) / [1, 0.5] (DDPG). Paired changes vs. Initial Training are in "
        "table1.json. The baseline rows are policies that ignore their observation (one constant action; "
        "no observation attack can change them) or read the simulator (IDM + MOBIL): a number that one of them "
        "also reaches is not a result."
    )
    timing_lines = TIMINGS + "\n\n" + "\n".join(f"- {k}: {v:.0f} s" for k, v in timings.items())
    md = ["# zodrive reproduction of Table 1", "", intro, "", md_table]
    if rob_table:
        md += ["## Robustness: return against ε under the strongest attack", "", rob_intro, "", rob_table]
        if rob_figure is not None:
            md += ["![Return against ε, each policy under its strongest attack](robustness/robustness.png)", ""]
    md += ["## Figures", ""]
    for name, caption in FIGURES:
        if (out / "figures" / name).is_file():
            md += [f"![{caption}](figures/{name})", "", f"*{caption}*", ""]
    md += ["## Timings", "", timing_lines, ""]
    write_atomic(out / "report.md", "\n".join(md))

    parts = [f"<h1>zodrive reproduction of Table 1</h1><p>{html.escape(intro)}</p>", _html_table(table["rows"])]
    if rob_table:
        parts += ["<h2>Robustness: return against ε under the strongest attack</h2>",
                  f"<p>{html.escape(rob_intro)}</p>", _html_from_markdown_table(rob_table)]
        if rob_figure is not None:
            parts.append('<figure><img src="data:image/png;base64,'
                         f'{base64.b64encode(rob_figure.read_bytes()).decode()}" '
                         'style="max-width:100%"></figure>')
    parts.append("<h2>Figures</h2>")
    for name, caption in FIGURES:
        path = out / "figures" / name
        if path.is_file():
            mime = "image/gif" if name.endswith(".gif") else "image/png"
            data = base64.b64encode(path.read_bytes()).decode()
            parts.append(f'<figure><img src="data:{mime};base64,{data}" style="max-width:100%">'
                         f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append(f"<h2>Timings</h2><p>{html.escape(TIMINGS)}</p><ul>"
                 + "".join(f"<li>{html.escape(k)}: {v:.0f} s</li>" for k, v in timings.items()) + "</ul>")
    page = ("<!doctype html><html><head><meta charset='utf-8'><title>zodrive: Table 1</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
            "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;text-align:right}"
            "td:nth-child(-n+2),th{text-align:left}figure{margin:1.5em 0}</style></head><body>"
            + "".join(parts) + "</body></html>\n")
    write_atomic(out / "report.html", page)


TIMINGS = ("Seconds, as each invocation recorded them (an older invocation's cells may count from its grid's "
           "start). A cell's time runs from the previous cell's end to its own (cells run one after another, so "
           "it is the cell's own time; on Ray, where cells overlap, it is not); an invocation's total is its "
           "wall time.")


def _episodes(n: int) -> str:
    """'N episodes per cell (seeds ...)', in words that fit one episode too."""
    if n == 1:
        return f"1 episode per cell, seed {EVAL_SEED}, the same in every cell"
    return f"{n} episodes per cell, seeds {EVAL_SEED}–{EVAL_SEED + n - 1}, the same in every cell"


def _html_from_markdown_table(text: str) -> str:
    """A Markdown pipe table (what `compare` writes) as an HTML table; other lines as paragraphs."""
    lines = [line.strip() for line in text.strip().splitlines()]
    rows = [[html.escape(c.strip()) for c in line.strip("|").split("|")] for line in lines
            if line.startswith("|") and not set(line) <= set("|-: ")]
    rest = "".join(f"<p>{html.escape(line)}</p>" for line in lines if line and not line.startswith("|"))
    if not rows:
        return rest
    head = "<tr>" + "".join(f"<th>{c}</th>" for c in rows[0]) + "</tr>"
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows[1:])
    return f"<div style='overflow-x:auto'><table>{head}{body}</table></div>{rest}"


def _html_table(records: list[dict[str, Any]]) -> str:
    head = ["Policy", "Scenario", "zodrive return", "95% CI", "% of 450", "Paper", "Collisions", "Off-road",
            "Speed (m/s)", "Lane changes/ep", "Attack success", "Queries/step", "max L∞"]
    rows = []
    for r in records:
        cells = [r["algo"], r["row"], f"{r['mean_return']:.2f}", f"{r['ci95_low']:.2f}–{r['ci95_high']:.2f}",
                 f"{r['pct_of_max']:.2f}%", or_dash(r["paper_return"], "{:.2f}"), f"{r['collision_rate']:.0%}",
                 or_dash(r.get("offroad_rate"), "{:.0%}"), or_dash(r.get("mean_speed"), "{:.1f}"),
                 or_dash(r.get("lane_changes_per_episode"), "{:.1f}"),
                 _success(r),
                 or_dash(r["queries_per_step"], "{:.0f}"), or_dash(r["max_linf"], "{:.3f}")]
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    return ("<div style='overflow-x:auto'><table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"
            + "".join(rows) + "</table></div>")  # a narrow window scrolls the table instead of cutting it
