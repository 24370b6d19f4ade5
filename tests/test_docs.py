"""The README is a short guide whose links resolve; the docs/ pages build with mkdocs --strict."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
MAX_README_LINES = 250
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")  # [text](target) and ![alt](target)


def relative_links(markdown: str) -> list[str]:
    """Targets of the Markdown links that point into the repository (no URL, no bare anchor)."""
    targets = [m.group(1) for m in LINK.finditer(markdown)]
    return [t for t in targets if not re.match(r"^([a-z][a-z0-9+.-]*:|#)", t, re.IGNORECASE)]


def test_readme_is_a_short_guide_whose_links_resolve() -> None:
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines (at most {MAX_README_LINES})"
    links = relative_links(text)
    assert links, "README.md links no repository file"
    broken = [t for t in links if not (REPO / t.split("#", 1)[0]).exists()]
    assert broken == [], f"README.md links to missing files: {broken}"


def test_relative_links_ignore_urls_and_anchors() -> None:
    text = "[a](docs/x.md) [b](https://e.org) ![c](img/p.png) [d](#top) [e](docs/y.md#part) [f](mailto:x@y.z)"
    assert relative_links(text) == ["docs/x.md", "img/p.png", "docs/y.md#part"]


@pytest.mark.slow
def test_the_docs_build_with_mkdocs_strict(tmp_path: Path) -> None:
    for module, package in (("mkdocs", "mkdocs"), ("material", "mkdocs-material")):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{package} is not installed (pip install mkdocs mkdocs-material)")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "site" / "index.html").is_file()
