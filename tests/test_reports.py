"""The reproduction's report and the robustness figure read as what they are (issue 47's newcomer trial)."""

from __future__ import annotations

import json
from pathlib import Path

from zodrive.experiments.compare import plot_robustness
from zodrive.experiments.report import _episodes, _html_from_markdown_table

ROOT = Path(__file__).resolve().parents[1]


def test_the_robustness_table_is_an_html_table_not_raw_markdown() -> None:
    text = (ROOT / "results" / "reproduction" / "robustness" / "robustness.md").read_text()
    page = _html_from_markdown_table(text)
    assert "<pre>" not in page and "|" not in page.split("</table>")[0]
    assert page.count("<tr>") == sum(1 for line in text.splitlines() if line.startswith("|")) - 1  # no separator row
    assert "<th>Policy</th>" in page and "<td>dqn-driver</td>" in page


def test_one_episode_is_said_in_words_that_fit() -> None:
    assert _episodes(1) == "1 episode per cell, seed 100000, the same in every cell"
    assert _episodes(10) == "10 episodes per cell, seeds 100000–100009, the same in every cell"


def test_many_systems_get_a_panel_each(tmp_path: Path) -> None:
    """Eleven curves in one axes hid each other: more than six get one panel each."""
    import matplotlib.image

    rows = json.loads((ROOT / "results" / "reproduction" / "robustness" / "table.json").read_text())
    plot_robustness(rows, tmp_path / "many.png")
    few = [r for r in rows if r["model"] in ("dqn-driver", "baseline:slower")]
    plot_robustness(few, tmp_path / "few.png")
    many_h, many_w = matplotlib.image.imread(tmp_path / "many.png").shape[:2]
    few_h, few_w = matplotlib.image.imread(tmp_path / "few.png").shape[:2]
    assert many_w > 1.3 * few_w and many_h > few_h  # a grid of panels, not one crowded axes
