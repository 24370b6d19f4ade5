"""Every committed CARD.md under models/ is what the command that writes it prints: a shipped model's card
is the text of the `zodrive card ...` line written inside it (run here in-process, through the CLI's own
parser, into a string), a zoo card is what `python zoo/card.py` writes (the package's zoo_card, given the zoo's
recipe by the script). A card left behind by a change to the card code or to the records it reads fails here,
with the command that brings it up to date.

One allowance: a zoo card whose bench row (results/bench/SCENARIO/NAME/row.json) is not in this checkout
(a bench still running, rows that land with a later commit) is written by zoo/card.py with "No bench row
yet" where the row's lines go; the committed card may give the row there, and everything before it must
still match."""

from __future__ import annotations

import difflib
import importlib.util
import shlex
import sys
from pathlib import Path
from types import ModuleType

import pytest

from zodrive.bench.zoo_card import NO_ROW  # a zoo card's words for a row not in the checkout
from zodrive.cli import build_parser
from zodrive.experiments import card as card_module
from zodrive.experiments.card import card_text

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "models" / "zoo"
ALL_CARDS = sorted(ROOT.glob("models/**/CARD.md"))
ZOO_CARDS = [card for card in ALL_CARDS if card.is_relative_to(ZOO)]
HAND_WRITTEN = {ROOT / "models" / "ppo-highway-fast" / "CARD.md"}
"""Cards no command writes (the plain-SB3 PPO of the "bring your own model" example): not checked here."""
CARD_FLAGS = {"command", "verbose", "models_dir", "folder", "baseline", "eval", "note", "seeds", "attacked", "force"}
"""What `zodrive card` parses: a new flag fails `test_the_card_command_is_read_whole` till `_shipped_text` passes it."""


def _command_line(card: Path) -> str | None:
    """The `zodrive card ...` line a shipped card names (None: a card of another kind)."""
    lines = [line for line in card.read_text(encoding="utf-8").splitlines() if line.startswith("zodrive card ")]
    assert len(lines) <= 1, f"{card.relative_to(ROOT)} names {len(lines)} `zodrive card` commands"
    return lines[0] if lines else None


SHIPPED_CARDS = [card for card in ALL_CARDS if _command_line(card) is not None]


def _rel(card: Path) -> str:
    return str(card.relative_to(ROOT))


def _diff(committed: str, written: str, card: Path) -> str:
    return "".join(difflib.unified_diff(committed.splitlines(keepends=True), written.splitlines(keepends=True),
                                        f"{_rel(card)} (committed)", f"{_rel(card)} (its command)", n=1))


def _shipped_text(line: str) -> str:
    """The card `line` (a `zodrive card ...` command, shell-quoted --note strings and all) writes, as a string."""
    argv = shlex.split(line)
    assert argv[:2] == ["zodrive", "card"], line
    args = build_parser().parse_args(argv[1:])
    return card_text(args.folder, baseline=args.baseline, evaluation=args.eval, notes=args.note, seeds=args.seeds,
                     attacked=args.attacked)


def test_every_card_is_written_by_a_command() -> None:
    """No card outside both generators but the hand-written ones: a card nothing writes is not checked here."""
    assert SHIPPED_CARDS and ZOO_CARDS and HAND_WRITTEN <= set(ALL_CARDS)
    assert not set(SHIPPED_CARDS) & set(ZOO_CARDS)
    assert sorted(set(ALL_CARDS) - set(SHIPPED_CARDS) - set(ZOO_CARDS)) == sorted(HAND_WRITTEN)


def test_the_card_command_is_read_whole() -> None:
    """The flags the CLI parses for `card` are the ones `_shipped_text` passes on."""
    args = build_parser().parse_args(["card", "models/dqn"])
    assert set(vars(args)) == CARD_FLAGS


def _shipped_stale(card: Path, committed: str) -> str | None:
    """Why `committed`, the text of shipped card `card`, is not what its command writes (None: it is)."""
    line = _command_line(card)
    assert line is not None
    written = _shipped_text(line)
    if written == committed:
        return None
    return f"{_rel(card)} is stale: run `{line} --force` from the repository's root\n" + _diff(committed, written, card)


IQM_LINES = ("- Interquartile mean ", "- IQM")  # how `card._iqm_line` begins its line


def _with_seeds(card: Path) -> bool:
    return " --seeds " in (_command_line(card) or "")


@pytest.mark.parametrize("card", SHIPPED_CARDS, ids=_rel)
def test_a_shipped_card_is_what_its_command_writes(card: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every line but the IQM over training seeds (rliable's 10,000-draw bootstrap: seconds a card), for which
    the committed card's own line stands in: `test_the_iqm_of_a_card_is_what_its_command_writes` checks it."""
    monkeypatch.chdir(ROOT)  # the command's paths are the repository's, as the card gives them
    committed = card.read_text(encoding="utf-8")
    own = [line for line in committed.splitlines() if line.startswith(IQM_LINES)]
    monkeypatch.setattr(card_module, "_iqm_line", lambda folders: own[0] if own else "(the card has no IQM line)")
    stale = _shipped_stale(card, committed)
    assert stale is None, stale


@pytest.mark.slow
@pytest.mark.parametrize("card", [card for card in SHIPPED_CARDS if _with_seeds(card)], ids=_rel)
def test_the_iqm_of_a_card_is_what_its_command_writes(card: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole card, IQM line and all."""
    monkeypatch.chdir(ROOT)
    stale = _shipped_stale(card, card.read_text(encoding="utf-8"))
    assert stale is None, stale


@pytest.fixture(scope="module")
def zoo_cards() -> dict[Path, str]:
    """zoo/card.py's cards (path -> text), written nowhere."""
    return _load_zoo_card().cards()


def _load_zoo_card() -> ModuleType:
    if str(ROOT / "zoo") not in sys.path:
        sys.path.append(str(ROOT / "zoo"))  # the zoo's scripts import each other as the zoo runs them
    spec = importlib.util.spec_from_file_location("zoo_card", ROOT / "zoo" / "card.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_zoo_card_writes_every_zoo_card(zoo_cards: dict[Path, str]) -> None:
    assert sorted(zoo_cards) == ZOO_CARDS


def _same_but_the_missing_row(committed: str, written: str) -> bool:
    """`written` says the bench row is not in this checkout: the committed card matches up to it, then gives
    the row (or says the same)."""
    if NO_ROW not in written:
        return False
    before = written[:written.index(NO_ROW)]
    rest = committed.removeprefix(before)
    return committed.startswith(before) and (rest == written[len(before):] or rest.startswith("Bench row ("))


def _zoo_stale(card: Path, committed: str, written: str) -> str | None:
    """Why `committed`, the text of zoo card `card`, is not `written` by zoo/card.py (None: it is)."""
    if written == committed or _same_but_the_missing_row(committed, written):
        return None
    return f"{_rel(card)} is stale: run `python zoo/card.py`\n" + _diff(committed, written, card)


@pytest.mark.parametrize("card", ZOO_CARDS, ids=_rel)
def test_a_zoo_card_is_what_zoo_card_py_writes(card: Path, zoo_cards: dict[Path, str]) -> None:
    assert card in zoo_cards, f"zoo/card.py writes no {_rel(card)}"
    stale = _zoo_stale(card, card.read_text(encoding="utf-8"), zoo_cards[card])
    assert stale is None, stale


def test_a_changed_card_fails(monkeypatch: pytest.MonkeyPatch, zoo_cards: dict[Path, str]) -> None:
    """One character changed in a copy of a committed card is stale, and so is a card whose command
    writes otherwise (here: a note its command does not give); the missing-row allowance covers the row only."""
    monkeypatch.chdir(ROOT)
    card = ROOT / "models" / "dqn" / "CARD.md"
    committed = card.read_text(encoding="utf-8")
    assert _shipped_stale(card, committed) is None
    changed = committed.replace("of the maximum", "of the max", 1)
    assert changed != committed and "-**Mean return" in (_shipped_stale(card, changed) or "")
    with monkeypatch.context() as m:
        line = _command_line(card)
        m.setattr(sys.modules[__name__], "_command_line", lambda c: f"{line} --note 'one more'")
        assert "+- one more" in (_shipped_stale(card, committed) or "")

    zoo = ZOO / "merge-dqn" / "seed-0" / "CARD.md"
    committed = zoo.read_text(encoding="utf-8")
    assert _zoo_stale(zoo, committed, zoo_cards[zoo]) is None
    assert _zoo_stale(zoo, committed.replace("seed 0", "seed 9", 1), zoo_cards[zoo]) is not None

    written = "# a / seed-0\n\nSHA-256 of `model.zip`: `00`\n\n" + NO_ROW + "\n"
    row = "# a / seed-0\n\nSHA-256 of `model.zip`: `00`\n\nBench row (merge-v3, ...): ...\n"
    assert _zoo_stale(zoo, row, written) is None and _zoo_stale(zoo, written, written) is None
    assert _zoo_stale(zoo, row.replace("`00`", "`01`"), written) is not None  # before the row: checked
    assert _zoo_stale(zoo, row.replace("Bench row (", "Bench "), written) is not None
    assert _zoo_stale(zoo, written, row) is not None  # the row in the checkout: the card must give it
