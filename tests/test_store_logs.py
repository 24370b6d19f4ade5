"""A study's printed outputs (`P/NAME.txt`) fold into one `P.txt` beside their folder and come back byte for byte
(`zodrive pack --logs`, `store.pack_logs` / `unpack_logs`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from zodrive.cli import main
from zodrive.errors import ZodriveError
from zodrive.evaluation import store

LOGS = {
    "a-eps0.02.txt": "$ zodrive evaluate models/dqn --eps 0.02\nepisodes: 3\nmean return: 1.50\n",
    "b.txt": "one line\n",
    "c.txt": "\n\ntwo blank lines first, a blank one last\n\n",
    "d.txt": "ünïcode, and a tab\tand a carriage return \r in a line\n",
}


def _logs(folder: Path, logs: dict[str, str]) -> dict[str, bytes]:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in logs.items():
        (folder / name).write_bytes(text.encode("utf-8"))
    return {name: text.encode("utf-8") for name, text in logs.items()}


def test_logs_fold_into_one_file_that_reads_as_tail_and_come_back_byte_for_byte(tmp_path: Path, capsys) -> None:
    cells = tmp_path / "study" / "cells"
    files = _logs(cells, LOGS)
    assert main(["pack", "--logs", str(cells)]) == 0
    folded = tmp_path / "study" / "cells.txt"
    assert f"folded 4 logs into {folded}" in capsys.readouterr().out
    assert not cells.exists()  # the folder went with its last file
    text = folded.read_bytes()
    _logs(tmp_path / "copy", LOGS)
    tail = subprocess.run(["tail", "-n", "+1", *sorted(LOGS)], cwd=tmp_path / "copy", capture_output=True,
                          check=True).stdout
    assert text == tail  # what `tail -n +1 *.txt` prints in the folder
    assert store.read_logs(folded) == LOGS
    assert main(["pack", "--logs", "--unpack", str(cells)]) == 0
    assert "unpacked" in capsys.readouterr().out and not folded.exists()
    assert {p.name: p.read_bytes() for p in cells.iterdir()} == files


def test_a_log_that_would_not_come_back_is_left_and_said(tmp_path: Path, capsys) -> None:
    cells = tmp_path / "cells"
    _logs(cells, {"ok.txt": "fine\n", "no-newline.txt": "cut", "header.txt": "x\n==> other.txt <==\ny\n"})
    (cells / "latin1.txt").write_bytes("caf\xe9\n".encode("latin-1"))
    (cells / "NAME").mkdir()  # an evaluation folder beside its printed output stays where it is
    assert main(["pack", "--logs", str(cells)]) == 0
    out = capsys.readouterr().out
    assert "folded 1 log into" in out
    for name, why in (("no-newline.txt", "does not end in a newline"), ("header.txt", "a header"),
                      ("latin1.txt", "not UTF-8")):
        assert f"left {cells / name}: " in out and why in out
        assert (cells / name).is_file()
    assert store.read_logs(tmp_path / "cells.txt") == {"ok.txt": "fine\n"} and (cells / "NAME").is_dir()


def test_folding_again_adds_to_the_folded_file_and_a_newer_file_wins(tmp_path: Path) -> None:
    cells = tmp_path / "cells"
    _logs(cells, {"a.txt": "old\n", "b.txt": "b\n"})
    store.pack_logs(cells)
    _logs(cells, {"a.txt": "new\n", "c.txt": "c\n"})
    done = store.pack_logs(cells)
    assert done.packed == ["a.txt", "c.txt"] and store.read_logs(done.pack) == {"a.txt": "new\n", "b.txt": "b\n",
                                                                               "c.txt": "c\n"}
    _logs(cells, {"b.txt": "kept\n"})  # unpacking keeps a file that is there
    assert store.unpack_logs(cells) == ["a.txt", "c.txt"] and (cells / "b.txt").read_text() == "kept\n"


@pytest.mark.parametrize("text", ["no header\n", "==> a.txt <==\nno newline", "==> a/b.txt <==\nx\n",
                                  "==> a.txt <==\nx\n==> b.txt <==\ny\n", "==> a.txt <==\nx\n\n==> a.txt <==\nx\n"])
def test_a_damaged_folded_file_is_one_line(tmp_path: Path, text: str) -> None:
    path = tmp_path / "cells.txt"
    path.write_text(text)
    with pytest.raises(ZodriveError, match="cells.txt"):
        store.read_logs(path)


def test_the_cli_refuses_what_it_cannot_fold_or_give_back(tmp_path: Path, capsys) -> None:
    assert main(["pack", "--logs", str(tmp_path / "nowhere")]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["pack", "--logs", "--unpack", str(tmp_path / "nowhere")]) == 2
    assert "no logs of" in capsys.readouterr().err


def test_match_folds_only_the_logs_it_names(tmp_path: Path, capsys) -> None:
    study = tmp_path / "study"
    _logs(study, {"adv-a.txt": "a\n", "adv-b.txt": "b\n", "paired.txt": "the study's table\n"})
    (study / "README.md").write_text("# notes\n")
    assert main(["pack", "--logs", str(study), "--match", "adv-*.txt", "--match", "none-*.txt"]) == 0
    assert "folded 2 logs into" in capsys.readouterr().out
    assert store.read_logs(tmp_path / "study.txt") == {"adv-a.txt": "a\n", "adv-b.txt": "b\n"}
    assert sorted(p.name for p in study.iterdir()) == ["README.md", "paired.txt"]  # the folder stays with them
    assert store.unpack_logs(study) == ["adv-a.txt", "adv-b.txt"]
    assert main(["pack", "--match", "adv-*.txt", str(study)]) == 2
    assert "--match chooses the logs that --logs folds" in capsys.readouterr().err
