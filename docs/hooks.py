"""mkdocs hook: the README and the protocol documents become pages, unchanged on disk.

The documents live beside the code they describe (the wheel ships them, the
docstrings cite them); copying them into docs/ would let the copies drift.
Instead this hook adds them to the build as generated pages and rewrites their
relative links: a link to another of these documents points at its page, an
image is copied along, and a link to anything else in the repository becomes
its path in code (the site has no page for it).
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]

PAGES = {
    # repository path -> page path in the site
    "README.md": "index.md",
    "serialsocket/PROTOCOL.md": "protocol/serialsocket.md",
    "serialsocket/KERMIT.md": "protocol/kermit.md",
    "tcpstream/PROTOCOL.md": "protocol/tcpstream.md",
    "RELIABILITY.md": "reliability.md",
    "bench/results/README.md": "bench-results.md",
}

_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def _rewrite(source: str, page: str, text: str, assets: dict[str, str]) -> str:
    here = posixpath.dirname(source)
    page_dir = posixpath.dirname(page)

    def replace(match: re.Match[str]) -> str:
        bang, label, target = match.groups()
        if "://" in target or target.startswith(("#", "mailto:")):
            return match.group(0)
        path, _, anchor = target.partition("#")
        repo_path = posixpath.normpath(posixpath.join(here, path))
        if repo_path in PAGES:
            dest = PAGES[repo_path]
        elif bang and (ROOT / repo_path).is_file():
            dest = assets.setdefault(repo_path, "assets/" + repo_path.replace("/", "-"))
        else:
            return f"{label} (`{repo_path}`)"
        rel = posixpath.relpath(dest, page_dir or ".")
        return f"{bang}[{label}]({rel}{'#' + anchor if anchor else ''})"

    return _LINK.sub(replace, text)


def on_files(files: Files, config: Any) -> Files:
    assets: dict[str, str] = {}
    for source, page in PAGES.items():
        text = (ROOT / source).read_text(encoding="utf-8")
        content = _rewrite(source, page, text, assets)
        files.append(File.generated(config, page, content=content))
    for source, dest in assets.items():
        files.append(File.generated(config, dest, abs_src_path=str(ROOT / source)))
    return files
