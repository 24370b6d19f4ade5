"""The leaderboard's plots: return against ε per table, and clean against attacked (the frontier); a colour per
family of rows that stays when rows are added."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from zodrive.bench.bench import current_protocols
from zodrive.drivers.baselines import BASELINES, PREFIX
from zodrive.errors import ZodriveError

WRITER = "zodrive leaderboard"
"""What the leaderboard's files carry (the Markdown's first lines, the PNG's Software field): a file that
does not is someone else's, and is replaced only with --force."""


MARKERS = "osD^v<>"


def family_and_seed(policy: str) -> tuple[str, int]:
    """A row's family and seed: ('dqn-g99', 1) for 'dqn-g99-seed-1', (policy, 0) for a row without one."""
    family, sep, seed = policy.rpartition("-seed-")
    return (family, int(seed)) if sep and seed.isdigit() else (policy, 0)


def _constant(row: dict[str, Any]) -> bool:
    """A constant action (reads nothing): drawn dashed and grey, as a floor, not as a policy."""
    key = str(row.get("key", ""))
    return key.startswith(PREFIX) and key.removeprefix(PREFIX) in BASELINES \
        and BASELINES[key.removeprefix(PREFIX)].reads == "nothing"


def family_colours(families: list[str]) -> dict[str, int]:
    """A colour index of tab20 per family that does not change when another row is added: each family's
    own hue (a hash of its name; tab20's dark shades), the next free hue where two families of one panel
    share one, light shades only past ten families."""
    order = [*range(0, 20, 2), *range(1, 20, 2)]  # ten distinct hues, then their light shades
    taken: dict[str, int] = {}
    for family in sorted(families, key=lambda f: (hash_slot(f, 10), f)):
        slot = hash_slot(family, 10)
        while order[slot % 20] in taken.values() and len(taken) < 20:
            slot += 1
        taken[family] = order[slot % 20]
    return taken


def line_style(row: dict[str, Any], colours: dict[str, int]) -> dict[str, Any]:
    """How a row is drawn: a colour per family (its index in tab20), a marker per seed; the constant
    actions dashed, in grey shades, whatever their number."""
    family, seed = family_and_seed(row["policy"])
    if _constant(row):
        return {"color": ("0.15", "0.45", "0.7")[hash_slot(family, 3)], "marker": "x", "linestyle": "--"}
    return {"color": colours[family], "marker": MARKERS[seed % len(MARKERS)], "linestyle": "-"}


def hash_slot(name: str, n: int) -> int:
    import zlib

    return zlib.crc32(name.encode()) % n


PANELS_PER_LINE = 4
"""A board's plots put at most this many tables side by side, so that a panel stays readable as tables are added."""


def _panels(plt: Any, n: int, width: float, height: float) -> tuple[Any, list[Any]]:
    """A figure of `n` panels of `width` x `height` inches, at most `PANELS_PER_LINE` to a line; the grid's
    unused panels are hidden."""
    cols = min(n, PANELS_PER_LINE)
    lines = -(-n // cols)
    fig, grid = plt.subplots(lines, cols, figsize=(width * cols, height * lines), squeeze=False)
    axes = list(grid.flat)
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def plot_leaderboard(rows: list[dict[str, Any]], path: Path) -> None:
    """Return against ε per scenario (worst black-box attack), one line per row, a colour per family that
    stays when rows are added; unofficial rows dotted and faded, named so in the legend."""
    from zodrive.evaluation.report import headless_pyplot

    plt = headless_pyplot()
    shown = rows
    protocols = sorted({r["protocol"] for r in shown})  # one panel per table of the leaderboard
    fig, axes = _panels(plt, len(protocols), 4.2, 7.4)
    palette = plt.get_cmap("tab20")
    for ax, name in zip(axes, protocols):
        table = sorted((r for r in shown if r["protocol"] == name), key=lambda r: r["policy"])
        colours = family_colours(sorted({family_and_seed(r["policy"])[0] for r in table if not _constant(r)}))
        for r in table:
            eps = [0.0, *(p["eps"] for p in r["attacked"])]  # ε 0: the clean return of the attacked episodes
            ret = [r.get("clean_on_attacked_episodes", r["clean"])["return"], *(p["return"] for p in r["attacked"])]
            style = line_style(r, colours)
            if not isinstance(style["color"], str):
                style["color"] = palette(style["color"])
            label = r["policy"]
            if not r["official"]:  # a quick look: dotted, faded, and said in the legend
                style.update(linestyle=":", alpha=0.55)
                label += f" (unofficial, {r['episodes']} ep.)"
            ax.plot(eps, ret, lw=1.2, ms=4, label=label, **style)
        ax.set_title(f"{table[0]['scenario']} ({name})", fontsize=9)
        ax.set_xlabel("ε (L∞, normalized observation)")
        ax.set_ylabel("mean episode return\n(worst black-box attack at ≤ ε; ε 0: clean)", fontsize=8)
        ax.legend(fontsize=6, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    fig.suptitle("zodrive leaderboard (dashed grey: constant actions; dotted: unofficial rows)", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / fig.get_figheight()))  # room for the title above the panels
    fig.savefig(path, dpi=120, metadata={"Software": WRITER})
    plt.close(fig)


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats on both coordinates (higher is better), by the first."""
    keep = [i for i, (x, y) in enumerate(points)
            if not any((a >= x and b >= y) and (a, b) != (x, y) for a, b in points)]
    return sorted(keep, key=lambda i: points[i])


def plot_frontier(rows: list[dict[str, Any]], path: Path) -> None:
    """Clean return against the return under the strongest attack at the largest ε, one panel per current
    protocol's table of official rows: which systems both drive well and hold up. Defended rows are squares,
    constant actions grey; the line joins the rows no other row beats on both."""
    from zodrive.evaluation.report import headless_pyplot

    plt = headless_pyplot()
    current = set(current_protocols())  # an earlier version's table is history, not a choice
    official = [r for r in rows if r["official"] and r["protocol"] in current]
    protocols = sorted({r["protocol"] for r in official})
    if not protocols:
        raise ZodriveError("no official bench rows of a current protocol: the frontier compares rows of the "
                           "protocols' episodes")
    fig, axes = _panels(plt, len(protocols), 4.6, 4.6)
    for ax, name in zip(axes, protocols):
        table = sorted((r for r in official if r["protocol"] == name), key=lambda r: r["policy"])
        points = [(r["clean"]["return"], r["attacked"][-1]["return"]) for r in table]
        for r, (x, y) in zip(table, points):
            ax.scatter([x], [y], marker="s" if r.get("defense") else "o", s=22, zorder=3,
                       color="0.55" if _constant(r) else ("C3" if r.get("defense") else "C0"))
            ax.annotate(r["policy"], (x, y), fontsize=5, xytext=(3, 2), textcoords="offset points")
        front = pareto(points)
        ax.plot([points[i][0] for i in front], [points[i][1] for i in front], color="C2", lw=1, zorder=2)
        ax.set_title(f"{table[0]['scenario']} ({name})", fontsize=9)
        ax.set_xlabel("clean return (protocol's clean episodes)", fontsize=8)
        ax.set_ylabel(f"return at ε {table[0]['attacked'][-1]['eps']:g}\n(worst black-box attack)", fontsize=8)
    fig.suptitle("zodrive frontier: clean against attacked (squares: defended; grey: constant actions; "
                 "line: no row beats these on both)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / fig.get_figheight()))  # room for the title above the panels
    fig.savefig(path, dpi=130, metadata={"Software": WRITER})
    plt.close(fig)
