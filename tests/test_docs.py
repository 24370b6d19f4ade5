"""The README is a short guide whose links resolve; the docs/ pages (and the README) build with mkdocs --strict."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

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


def test_the_docs_build_with_mkdocs_strict(tmp_path: Path) -> None:
    """About 2 s: in the default suite (the `test` extra installs mkdocs and mkdocs-material).
    The README and the repository files the pages link to are part of the site (mkdocs_hooks.py),
    so a link into results/ works on the site and a broken one fails the build."""
    for module, package in (("mkdocs", "mkdocs"), ("material", "mkdocs-material")):
        assert importlib.util.find_spec(module) is not None, f"{package} is missing: pip install -e '.[test]'"
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)],
                          cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (site / "index.html").is_file() and (site / "readme" / "index.html").is_file()
    assert (site / "results" / "vertex-hold" / "picker" / "index.html").is_file()  # linked from attacks.md
    assert 'href="../results/vertex-hold/"' in (site / "attacks" / "index.html").read_text(encoding="utf-8")


def test_a_broken_link_fails_the_strict_build(tmp_path: Path) -> None:
    import shutil

    for name in ("mkdocs.yml", "mkdocs_hooks.py", "README.md"):
        shutil.copy(REPO / name, tmp_path / name)
    (tmp_path / "docs").mkdir()
    for page in (REPO / "docs").glob("*.md"):
        (tmp_path / "docs" / page.name).write_text(page.read_text(encoding="utf-8").replace(
            "../results/vertex-hold/README.md", "../results/no-such-study/README.md"), encoding="utf-8")
    shutil.copytree(REPO / "results" / "vertex-hold", tmp_path / "results" / "vertex-hold",
                    ignore=shutil.ignore_patterns("cells", "*.json*", "*.zip", "*.png", "*.pkl"))
    (tmp_path / "README.md").write_text("# zodrive\n", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode != 0 and "no-such-study" in proc.stderr, proc.stderr
