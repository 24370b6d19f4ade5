"""Write the CARD.md of each zoo policy from its own records: the command and seed that trained it, the
checkpoint chosen on tuning seeds, its SHA-256, its bench row and the row's exact check. The cards are made by
the package's card writer (`zodrive.bench.zoo_card`, written by `zodrive.experiments.card.save_card`, as
a shipped model's card is); this script gives it the zoo's recipe, which lives in the zoo's own scripts.

Run: python zoo/card.py
"""

from __future__ import annotations

from pathlib import Path

from choose_checkpoint import EPISODES  # zoo/choose_checkpoint.py, beside this script
from q_ensemble import STEPS  # zoo/q_ensemble.py, beside this script
from train import DEFAULTS  # zoo/train.py, beside this script
from zodrive.bench.zoo_card import ZooRecipe, zoo_cards
from zodrive.experiments.card import save_card

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ZooRecipe(train_defaults=DEFAULTS, tuning_episodes=EPISODES, ensemble_steps=STEPS)


def cards() -> dict[Path, str]:
    """Every zoo card's path and text, as `main` writes them (nothing is written here)."""
    return zoo_cards(ROOT, RECIPE)


def main() -> None:
    for path, text in cards().items():
        save_card(path, text)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
