"""Real highway-env runs with the shipped models (minutes): `pytest -m slow`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zodrive.cli import main
from zodrive.experiments.reproduce import BASELINE_ROWS

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def test_reproduce_quick_runs_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "repro"
    assert main(["reproduce", "--quick", "--out", str(out), "--no-progress"]) == 0
    for name in ("table1.csv", "table1.json", "table1.md", "report.md", "report.html",
                 "figures/fig2_loss.png", "figures/fig3_attacked_episode.png", "figures/fig3_attacked_episode.gif",
                 "figures/fig4_ddpg_adversarial_training.png", "figures/fig5_dqn_adversarial_training.png",
                 "robustness/robustness.md", "robustness/robustness.png"):
        assert (out / name).is_file(), name
    report = (out / "report.md").read_text()
    assert report.index("## Robustness") < report.index("## Figures") and "dqn-robust" in report
    rows = json.loads((out / "table1.json").read_text())
    assert len(rows) == 8 + sum(map(len, BASELINE_ROWS.values())) and all(r["episodes"] == 5 for r in rows)
    before = json.loads((out / "timings.json").read_text())
    assert main(["reproduce", "--quick", "--out", str(out), "--no-progress"]) == 0  # resumes: nothing redone
    after = json.loads((out / "timings.json").read_text())
    assert {k: v for k, v in after.items() if k.startswith("cell")} == {k: v for k, v in before.items() if k.startswith("cell")}
    assert json.loads((out / "table1.json").read_text()) == rows


@pytest.mark.parametrize("name", ["dqn", "ddpg", "dqn-driver", "dqn-robust"])
def test_shipped_model_reproduces_its_card(name: str, tmp_path: Path) -> None:
    card = json.loads((ROOT / "models" / name / "eval" / "summary.json").read_text())
    assert main(["evaluate", str(ROOT / "models" / name), "--episodes", str(card["episodes"]), "--workers", "2",
                 "--out", str(tmp_path), "--no-progress"]) == 0
    mine = json.loads((tmp_path / "summary.json").read_text())
    assert mine["mean_return"] == pytest.approx(card["mean_return"], abs=1e-6)
