"""The viewer's HTML document: linked static files (served) or everything inlined (export).

The data of an exported page sits in a ``<script type="application/json">`` element with
``<``, ``>`` and ``&`` escaped as JSON unicode escapes, so no recorded string can close the
element or be read as markup; the page reads it with ``JSON.parse`` and puts every
recorded string into the document as text (``textContent``), never as HTML.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

#: The page's files, in load order (scripts after the stylesheet).
STATIC_FILES = ("viewer.css", "api.js", "graph.js", "timeline.js", "panels.js", "app.js")
#: No network at all for an exported page: inline scripts and styles, data: images.
EXPORT_CSP = (
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src data:"
)


def static_text(name: str) -> str:
    """One of the page's static files."""
    return resources.files("btlog.view").joinpath("static", name).read_text(encoding="utf-8")


def embed_json(data: Any) -> str:
    """JSON safe inside a ``<script type="application/json">`` element."""
    text = json.dumps(data, separators=(",", ":"), default=repr, allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def page_html(data: Any | None = None, title: str = "btlog view") -> str:
    """The document: with ``data`` (an export) everything is inlined, else linked."""
    styles = [n for n in STATIC_FILES if n.endswith(".css")]
    scripts = [n for n in STATIC_FILES if n.endswith(".js")]
    head = ['<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">']
    head.append('<meta name="viewport" content="width=device-width, initial-scale=1">')
    safe_title = title.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    head.append(f"<title>{safe_title}</title>")
    body = ['</head><body><div id="app" class="loading">loading…</div>']
    if data is None:
        head += [f'<link rel="stylesheet" href="/static/{n}">' for n in styles]
        body += [f'<script src="/static/{n}"></script>' for n in scripts]
    else:
        head.insert(1, f'<meta http-equiv="Content-Security-Policy" content="{EXPORT_CSP}">')
        head += [f"<style>{static_text(n)}</style>" for n in styles]
        body.append(f'<script type="application/json" id="btlog-data">{embed_json(data)}</script>')
        body += [f"<script>{_inline_script(static_text(n))}</script>" for n in scripts]
    return "".join(head + body) + "</body></html>\n"


def _inline_script(text: str) -> str:
    """A script that cannot end its own element early (our code, checked here anyway)."""
    if "</script" in text.lower():
        raise ValueError("a static script holds '</script'")
    return text
