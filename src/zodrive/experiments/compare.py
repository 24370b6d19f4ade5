"""`zodrive compare`: every attack (and a range of eps) on every model, one table.

Each cell is an ordinary resumable evaluation in OUT/cells/<model>[+defense]-<attack>-eps<eps>/, named by its
`cells.GridCell` (eps exact: `cells.number_name`; two models of one name told apart by their content:
`cells.policy_names`);
the table is rebuilt from their summaries, so an interrupted comparison resumes. With several
eps, `robustness.md` gives each model (and defense) its strongest attack inside each eps-ball (at
that eps or a smaller one): a defense is judged by the attack that hurts it most, not by the one
that flatters it.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any, Callable

from zodrive.policies.policy import Policy, resolve
from zodrive.policies.resolve import refuse_unused_shift, resolve_scenario
from zodrive.attacks.spec import load_attack
from zodrive.errors import ZodriveError
from zodrive.evaluation.evaluate import DEFAULT_ENVS, DEFAULT_EVAL_SEED, EvalJob
from zodrive.evaluation.report import headless_pyplot, or_dash, save_figure
from zodrive.experiments.cells import CLEAN, Cell, GridCell, number_name, policy_names, run_cells
from zodrive.runinfo import write_atomic, write_json


def compare(models: list[str], attacks: list[str], eps_values: list[float], episodes: int, out: Path, *,
            workers: int = 1, progress: bool = True, seed: int = DEFAULT_EVAL_SEED,
            query_budgets: list[int | None] | None = None, backend: str = "local",
            address: str | None = None, defenses: list[str | None] | None = None,
            env_set: list[str] | None = None, attack_set: list[str] | None = None, preset: str | None = None,
            env_id: str | None = None, obs_bounds: tuple[float, float] | None = None, shifted: bool = False,
            force: bool = False, claim: bool = True, envs: int = DEFAULT_ENVS,
            trust: bool = False, on_cell: Callable[[int, int, GridCell], None] | None = None,
            attack_budgets: dict[str, list[int | None]] | None = None,
            readable: bool = True) -> list[dict[str, Any]]:
    """Every model (x defense) x attack x eps x per-step query budget (`attack_budgets`: an attack's own
    budgets instead of `query_budgets`, as a bench protocol caps its black-box attacks and not PGD); one
    resumable evaluation per cell (`trust`: read SB3 zips with SB3's own loader, which unpickles). Policies
    that do not read the observation (constant and
    simulator-reading baselines) get their clean row only: no observation attack or filter
    can change what they do; white-box attacks skip policies that offer no gradients. `readable=False`
    writes the data alone (`table.json`), not its renderings for a reader (`table.csv`, `table.md`,
    `robustness.md`): a bench row's reader is the leaderboard."""
    from zodrive.defense import make_defense

    budgets = query_budgets or [None]
    eps: float | None  # the cells' radii; None: the clean cell
    budgets_of = {attack: (attack_budgets or {}).get(attack) or budgets for attack in attacks}
    defenses = defenses or [None]
    for attack in attacks:  # every attack is checked (and every budget against it) before any cell runs
        for budget in budgets_of[attack]:
            for eps in eps_values:
                load_attack(attack, attack_set).with_overrides(eps=eps, query_budget=budget).check()
    grid: list[dict[str, Any]] = []
    typed: list[GridCell] = []  # the grid's cells, as `on_cell` is told them
    cells: list[Cell] = []
    policies = [resolve(model) for model in models]
    names = policy_names([p.label for p in policies], [p.key() for p in policies])
    sources = [resolve_scenario(model, preset, env_set, env_id, obs_bounds, shifted=shifted) for model in models]
    if shifted:
        refuse_unused_shift([source for _, source in sources], "--shifted")
    for model, policy, name, (model_preset, source) in zip(models, policies, names, sources):
        policy.check(model_preset)
        gradients = policy.gradients
        reads = policy.reads
        reads_obs = reads == "observation"
        usable = [a for a in attacks if gradients or _black_box(a, attack_set)] if reads_obs else []
        for defense in defenses if reads_obs else [None]:
            if defense is not None:
                make_defense(defense, model_preset)  # the preset must be one the defense understands
            for attack in [CLEAN, *usable]:
                points: list[tuple[float | None, int | None]] = ([(None, None)] if attack == CLEAN
                          else [(e, b) for e in eps_values for b in budgets_of[attack]])
                for eps, budget in points:
                    spec = None if attack == CLEAN else \
                        load_attack(attack, attack_set).with_overrides(eps=eps, query_budget=budget)
                    cell = GridCell(name, attack_name(attack), eps, budget, defense,
                                    white_box=is_white_box(spec.attack if spec else attack))
                    job = EvalJob(model=policy, preset=model_preset, attack=spec, seed=seed,
                                  defense=defense, trust=trust, scenario_source=source)
                    grid.append(cell.entry(reads))
                    typed.append(cell)
                    cells.append(Cell(job, episodes, cell.folder(out), force=force))
    if claim:  # `zodrive compare` owns its folder; `reproduce` composes several grids in one
        _claim(out, grid, force)
    rows: list[dict[str, Any] | None] = [None] * len(cells)

    def done(i: int, s: dict[str, Any]) -> None:
        rows[i] = table_row(grid[i], s)
        write_tables([r for r in rows if r is not None], out, readable)  # in grid order, as cells finish
        if on_cell is not None:
            on_cell(sum(r is not None for r in rows), len(rows), typed[i])

    run_cells(cells, backend=backend, workers=workers, progress=progress, address=address, on_done=done, envs=envs)
    return rows  # type: ignore[return-value]


TABLE_NEEDS = ("mean_return", "ci95", "collision_rate", "mean_speed", "right_lane_share", "episodes")
"""The fields of a cell's summary its table row cannot do without (`table_row`)."""


def table_row(entry: dict[str, Any], s: dict[str, Any]) -> dict[str, Any]:
    """A cell's row of `table.json`: its grid entry (`GridCell.entry`) and the figures of its summary `s`. The one
    place a row is made, by the grid as each cell finishes and by a bench row read back from its cells
    (`zodrive.bench.bench.cells_table`), so the two never differ."""
    low, high = s["ci95"]
    return {
        **entry, "mean_return": s["mean_return"], "ci95_low": low,
        "ci95_high": high, "collision_rate": s["collision_rate"],
        "offroad_rate": s.get("offroad_rate"), "mean_speed": s["mean_speed"],
        "lane_changes_per_episode": s.get("lane_changes_per_episode"),
        "right_lane_share": s["right_lane_share"], "attack_success_rate": s.get("attack_success_rate"),
        "target_base_rate": s.get("target_base_rate"),
        "queries_per_step": s.get("queries_per_step"), "max_linf": s.get("max_linf"),
        "episodes": s["episodes"],
    }


def clean_cell(policy: Policy) -> GridCell:
    """The clean cell of `policy` in a grid of its own (a bench row's): as `compare` names it."""
    (name,) = policy_names([policy.label], [policy.key()])
    return GridCell(name)


def _claim(out: Path, grid: list[dict[str, Any]], force: bool) -> None:
    """The folder's tables belong to one grid: the same grid resumes (more episodes too), a
    different one is refused without --force (its tables would replace these)."""
    path = out / "grid.json"
    if path.is_file() and not force and json.loads(path.read_text()) != grid:
        raise ZodriveError(f"{out} holds the tables of another comparison (models, attacks, eps, budgets or "
                           "defenses differ); use --force to replace them, or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    write_json(path, grid)


def default_attacks(attack_set: list[str] | None = None) -> tuple[list[str], dict[str, str]]:
    """Every registered attack that runs without a trained folder (not vertex check) and takes
    `attack_set` (the grid without `--attacks`), and why each of the others does not (vertex-hold
    with `target=none`, say): a default grid leaves an attack out, where one named in `--attacks`
    is an error."""
    from zodrive.attacks.registry import ATTACKS, KNOWN

    names, left_out = [], {}
    for name in (name for name in ATTACKS if name in KNOWN):
        try:
            load_attack(name, attack_set).check()
        except ZodriveError as err:
            left_out[name] = str(err)
        else:
            names.append(name)
    if not names:
        raise ZodriveError("no attack takes these --attack-set options: "
                           + "; ".join(f"{name}: {why}" for name, why in left_out.items())[:400])
    return names, left_out


def _black_box(attack: str, attack_set: list[str] | None) -> bool:
    from zodrive.attacks.registry import attack_class

    return attack_class(load_attack(attack, attack_set).attack).black_box


def attack_name(attack: str) -> str:
    """What a cell and a table call an attack given as a registry name, a config name, a config file (its stem)
    or NAME:DIR (NAME and the folder's name): never a path, which would nest the cell's folder."""
    head, colon, folder = attack.partition(":")
    if colon and "/" not in head:
        return f"{head}:{Path(folder).name}"
    return Path(attack).stem if attack.endswith((".yaml", ".yml")) or "/" in attack else attack


def is_white_box(runs: str) -> bool:
    """Whether the registry's attack `runs` reads gradients (a cell's label says so)."""
    from zodrive.attacks.registry import ATTACKS

    return runs in ATTACKS and not ATTACKS[runs].black_box


def markdown(rows: list[dict[str, Any]]) -> str:
    budgets = any(r.get("query_budget") is not None for r in rows)
    lines = ["| Model | Attack | ε (L∞) | " + ("Budget/step | " if budgets else "")
             + "Return (95% CI) | Collisions | Off-road | Speed (m/s) | Lane changes/ep "
             "| Success (base rate) | Queries/step | max L∞ |",
             "|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if budgets else "")]
    for r in rows:
        success = "–" if r["attack_success_rate"] is None else \
            f"{r['attack_success_rate']:.1%} ({or_dash(r['target_base_rate'], '{:.1%}')})"
        budget = f"{or_dash(r.get('query_budget'), '{:d}')} | " if budgets else ""
        lines.append(f"| {_system(r)} | {r['attack']} | {'–' if r['eps'] is None else number_name(r['eps'])} | "
                     f"{budget}{r['mean_return']:.1f} "
                     f"({r['ci95_low']:.1f}–{r['ci95_high']:.1f}) | {r['collision_rate']:.0%} | "
                     f"{or_dash(r.get('offroad_rate'), '{:.0%}')} | {or_dash(r.get('mean_speed'), '{:.1f}')} | "
                     f"{or_dash(r.get('lane_changes_per_episode'), '{:.1f}')} | {success} | "
                     f"{or_dash(r['queries_per_step'], '{:.0f}')} | {or_dash(r['max_linf'], '{:.3f}')} |")
    return "\n".join(lines) + "\n"


def write_tables(rows: list[dict[str, Any]], out: Path, readable: bool = True) -> None:
    """`table.json` (what the bench and the leaderboard read) and, if `readable`, its renderings."""
    write_json(out / "table.json", rows)
    if not readable:
        return
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0].keys()))
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(out / "table.csv", buf.getvalue())
    write_atomic(out / "table.md", markdown(rows))
    if len({r["eps"] for r in rows if r["eps"] is not None}) > 1:
        write_atomic(out / "robustness.md", robustness_markdown(rows))


def _system(row: dict[str, Any]) -> str:
    """The policy as attacked: the model, and the defense in front of it if any."""
    defense = row.get("defense", "none")
    return row["model"] if defense in (None, "none") else f"{row['model']} + {defense}"


def _ignores_input(row: dict[str, Any]) -> bool:
    """A constant or simulator-reading policy: no observation attack changes what it does."""
    return row.get("reads", "observation") != "observation"


def strongest(rows: list[dict[str, Any]]) -> dict[str, dict[float, dict[str, Any]]]:
    """Per system (model + defense): its clean row at eps 0 and, per eps, the row with the lowest
    mean return inside the eps-ball: over attacks and query budgets at that eps, at every smaller
    eps, and clean (a point within a smaller eps, or no perturbation, is within eps). So the return
    never rises with eps; a row kept from a smaller eps (or clean) has its own `eps`. Ties go to the
    row at the larger eps."""
    table: dict[str, dict[float, dict[str, Any]]] = {}
    for r in rows:
        eps = 0.0 if r["eps"] is None else float(r["eps"])
        cells = table.setdefault(_system(r), {})
        if eps not in cells or r["mean_return"] < cells[eps]["mean_return"]:
            cells[eps] = r
    for cells in table.values():
        inside: dict[str, Any] | None = None  # the strongest row of the smaller balls
        for eps in sorted(cells):
            if inside is not None and inside["mean_return"] < cells[eps]["mean_return"]:
                cells[eps] = inside
            inside = cells[eps]
    return table


def _source(row: dict[str, Any], eps: float) -> str:
    """Which cell a robustness entry at `eps` comes from: its attack, and its eps where smaller."""
    if row["eps"] is None:
        return "clean: no attack hurt more"
    return row["attack"] if float(row["eps"]) == eps else f"{row['attack']} at ε {number_name(float(row['eps']))}"


def robustness_markdown(rows: list[dict[str, Any]]) -> str:
    """Return under the strongest attack inside each eps-ball (which attack, in brackets; its eps
    where a smaller one's was stronger); policies that do not read the observation have one value,
    whatever the eps."""
    table = strongest(rows)
    eps_values = sorted({e for cells in table.values() for e in cells if e > 0})
    lines = ["| Policy | Clean | " + " | ".join(f"ε {number_name(e)}" for e in eps_values) + " |",
             "|---|---|" + "---|" * len(eps_values)]
    for system, cells in table.items():
        clean = cells[0.0]
        values = [f"{clean['mean_return']:.1f} (ignores its input)" if _ignores_input(clean)
                  else f"{cells[e]['mean_return']:.1f} ({_source(cells[e], e)}, {cells[e]['mean_speed']:.1f} m/s)"
                  if e in cells else "–" for e in eps_values]
        lines.append(f"| {system} | {clean['mean_return']:.1f} ({clean['mean_speed']:.1f} m/s) | "
                     + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def plot_robustness(rows: list[dict[str, Any]], path: Path) -> None:
    """Mean return (95% CI band) against eps, each system under its strongest attack; a
    policy that ignores its input is a horizontal dashed line (the floor a defense must beat).
    More than six systems get one panel each (the others faint behind it), so no line hides another."""
    plt = headless_pyplot()
    table = strongest(rows)
    floors = {s: c[0.0]["mean_return"] for s, c in table.items() if _ignores_input(c[0.0])}
    curves = {s: c for s, c in table.items() if s not in floors}
    top = max((float(r["eps"]) for r in rows if r["eps"] is not None), default=1.0)
    colors = plt.cm.tab20.colors if len(curves) > 10 else plt.cm.tab10.colors
    panels = list(curves) if len(curves) > 6 else [None]
    cols = min(len(panels), 4)
    fig, axes = plt.subplots((len(panels) + cols - 1) // cols, cols, figsize=(8.5 if cols == 1 else 3.2 * cols,
                             4.5 if cols == 1 else 2.8 * ((len(panels) + cols - 1) // cols)),
                             sharex=True, sharey=True, squeeze=False)
    for ax, focus in zip(axes.flat, panels):
        for k, (value, system) in enumerate(sorted((v, s) for s, v in floors.items())):
            ax.axhline(value, ls="--", lw=1, color="grey")
            left = k % 2 == 0  # floors often coincide: their labels alternate sides
            ax.annotate(system, (0 if left else top, value), fontsize=6, color="grey", xytext=(2 if left else -2, 2),
                        textcoords="offset points", ha="left" if left else "right")
        for color, (system, cells) in zip(colors * 2, curves.items()):
            eps = sorted(cells)
            faint = focus is not None and system != focus
            ax.plot(eps, [cells[e]["mean_return"] for e in eps], marker="" if faint else "o", lw=0.8 if faint else 1.5,
                    color="lightgrey" if faint else color, label=None if faint else system, zorder=1 if faint else 3)
            if not faint:
                ax.fill_between(eps, [cells[e]["ci95_low"] for e in eps], [cells[e]["ci95_high"] for e in eps],
                                alpha=0.15, color=color)
        if focus is not None:
            ax.set_title(focus, fontsize=8)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("ε (L∞, normalized units)")
    for ax in axes[:, 0]:
        ax.set_ylabel("mean return")
    if panels == [None]:
        axes[0, 0].set_title("return under the strongest attack")
        axes[0, 0].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    else:
        fig.suptitle("return under the strongest attack (each panel one system; the others in grey)")
    save_figure(fig, path)


def plot_budget_curves(rows: list[dict[str, Any]], path: Path) -> None:
    """Return (left) and step success (right) against queries spent per step, one line per
    model and attack; points are the cells of the grid (eps and budget)."""
    plt = headless_pyplot()
    fig, (ax_r, ax_s) = plt.subplots(1, 2, figsize=(10, 4))
    for (model, attack), group in _groups(rows).items():
        group = sorted(group, key=lambda r: r["queries_per_step"])
        q = [r["queries_per_step"] for r in group]
        label = f"{model} {attack}"
        ax_r.plot(q, [r["mean_return"] for r in group], marker="o", label=label)
        ax_s.plot(q, [100 * r["attack_success_rate"] for r in group], marker="o", label=label)
    for r in rows:
        if r["attack"] == CLEAN:
            ax_r.axhline(r["mean_return"], ls="--", lw=1, color="grey")
    ax_r.set(xscale="log", xlabel="queries per step (mean)", ylabel="mean return", title="return (dashed: clean)")
    ax_s.set(xscale="log", xlabel="queries per step (mean)", ylabel="steps won (%)", title="attack success")
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    for ax in (ax_r, ax_s):  # plain numbers on the log axis, no overlapping minor labels
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax_s.legend(fontsize=7)
    save_figure(fig, path)


def _groups(rows: list[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        if r["attack"] != CLEAN and r.get("queries_per_step"):
            groups.setdefault((r["model"], r["attack"]), []).append(r)
    return groups
