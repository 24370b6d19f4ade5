"""mkdocs hooks (mkdocs.yml `hooks:`): the site also holds the README and every repository file
that a page links to, so no link of the site points outside it.

`docs/` pages keep their places; the README becomes `readme.md`; any other file a page links to
(a study's README, a model card, an example script, a figure) is added at its repository path,
and Markdown files among them are scanned in turn. Links are rewritten to where their targets
sit on the site. A link to a file that does not exist is left as written, so that
`mkdocs build --strict` still fails on it.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

LINK = re.compile(r"(!?\[[^\]]*\]\()([^)\s]+)((?:\s+\"[^\"]*\")?\))")  # [text](target "title"), ![alt](target)
URL = re.compile(r"^([a-z][a-z0-9+.-]*:|#|/)", re.IGNORECASE)
README = "README.md"

_repo_of: dict[str, str] = {}  # a site page's src_uri -> its repository path


def site_uri(repo_path: str) -> str:
    """Where a repository file sits in the site."""
    if repo_path.startswith("docs/"):
        return repo_path[len("docs/"):]
    return "readme.md" if repo_path == README else repo_path


def targets(text: str, repo_path: str) -> list[tuple[re.Match[str], str, str]]:
    """(match, repository path of the target, #anchor) of each relative link in `text`."""
    found = []
    for match in LINK.finditer(text):
        link = match.group(2)
        if URL.match(link):
            continue
        path, _, anchor = link.partition("#")
        target = posixpath.normpath(posixpath.join(posixpath.dirname(repo_path), path))
        found.append((match, target, "#" + anchor if anchor else ""))
    return found


def on_files(files: Files, config: Any) -> Files:
    root = Path(config.config_file_path).parent
    pages = [f"docs/{f.src_uri}" for f in files.documentation_pages()]
    _repo_of.clear()
    _repo_of.update({site_uri(p): p for p in pages})
    todo = [README, *pages]
    seen = set(todo)
    files.append(File.generated(config, site_uri(README), abs_src_path=str(root / README)))
    _repo_of[site_uri(README)] = README
    while todo:
        repo_path = todo.pop()
        if not repo_path.endswith(".md"):
            continue
        for _, target, _ in targets((root / repo_path).read_text(encoding="utf-8"), repo_path):
            if target in seen or target.startswith("../") or target.startswith("docs/") \
                    or not (root / target).is_file():
                continue
            seen.add(target)
            todo.append(target)
            files.append(File.generated(config, site_uri(target), abs_src_path=str(root / target)))
            _repo_of[site_uri(target)] = target
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    repo_path = _repo_of.get(page.file.src_uri)
    if repo_path is None:
        return markdown
    root = Path(config.config_file_path).parent
    here = posixpath.dirname(page.file.src_uri)

    def rewrite(match: re.Match[str], target: str, anchor: str) -> str:
        if not (root / target).is_file() or target.startswith("../"):
            return match.group(0)  # left for mkdocs to report
        link = posixpath.relpath(site_uri(target), here or ".")
        return f"{match.group(1)}{link}{anchor}{match.group(3)}"

    replaced = {m.start(): rewrite(m, t, a) for m, t, a in targets(markdown, repo_path)}
    return LINK.sub(lambda m: replaced.get(m.start(), m.group(0)), markdown)
