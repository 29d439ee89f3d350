"""Assembling the self-contained HTML page: template + data + vendored three.js.

Everything the page needs is inside the file: the data as JSON (typed arrays base64),
three.js and OrbitControls as module text turned into blob: URLs in the page, the
viewer script. A Content-Security-Policy (default-src 'none') forbids any network
request from the page.
"""

from __future__ import annotations

import json
import re
from html import escape
from importlib import resources

THREE_VERSION = "0.187.0"
VENDOR = ("three.core.js", "three.module.js", "OrbitControls.js", "LICENSE-three.txt")


def _text(*parts):
    return resources.files("openfdk.viewer").joinpath(*parts).read_text(encoding="utf-8")


def _embed(text, name):
    """Text inside a <script type="text/plain"> element (must not close it)."""
    if "</script" in text.lower():
        raise ValueError(f"vendored file {name} contains '</script' and cannot be inlined")
    return text


def render_page(data, title):
    """The HTML page (str) for the JSON-able ``data`` {meta, scene, frames}."""
    # '<' only occurs inside JSON strings: escaping it keeps the script element closed
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    core, module, orbit, lic = (_text("vendor", n) for n in VENDOR)
    html = _text("template.html")
    parts = {
        "__TITLE__": escape(title), "__THREE_VERSION__": THREE_VERSION,
        "__THREE_CORE__": _embed(core, VENDOR[0]), "__THREE_MODULE__": _embed(module, VENDOR[1]),
        "__THREE_ORBIT__": _embed(orbit, VENDOR[2]), "__THREE_LICENSE__": _embed(lic, VENDOR[3]),
        "__VIEWER_JS__": _embed(_text("viewer.js"), "viewer.js"), "__DATA__": payload,
    }
    # one pass, so that no inserted text is searched for later placeholders
    return re.sub("|".join(re.escape(k) for k in parts), lambda m: parts[m.group(0)], html)
