"""mkdocs hook: the site's home page is the README, its links made relative to docs/."""

from __future__ import annotations

import re
from pathlib import Path


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != "index.md":
        return markdown
    readme = (Path(config["config_file_path"]).parent / "README.md").read_text(encoding="utf-8")
    return re.sub(r"\]\(docs/", "](", readme)
