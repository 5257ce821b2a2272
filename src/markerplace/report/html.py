"""Self-contained HTML pages: images embedded as data URIs, CSS inline, no network.

A page opens from disk in any browser, can be mailed as one file, and shows the same offline.
The scripts are inline and use no library: the plan report's review buttons
(:mod:`markerplace.report.review`; it builds its download as a ``data:`` URL) and the 3D view
(:mod:`markerplace.report.view3d`: WebGL, its data embedded as base64).
Helpers here build the pieces (escaped text, tables, figures, markdown tables from
``tables.md``) and :func:`write_page` writes the document atomically.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path

__all__ = ["esc", "data_uri", "png_file_uri", "jpeg_uri", "png_uri", "img", "table", "markdown_to_html", "page",
           "write_page"]

CSS = """
body { font-family: -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; margin: 0 auto; max-width: 1320px;
       padding: 1em 2em 3em; color: #1d1d1f; background: #fff; line-height: 1.45; }
h1 { font-size: 1.7em; margin-bottom: 0.2em; } h2 { margin-top: 1.8em; border-bottom: 2px solid #ddd; }
h3 { margin-bottom: 0.3em; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.93em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; height: auto; border: 1px solid #ccc; }
figure { margin: 0.5em 0; } figcaption { font-size: 0.85em; color: #555; }
.note { color: #555; font-size: 0.9em; }
.tag { border: 1px solid #bbb; border-radius: 6px; padding: 0.6em 1em 1em; margin: 1.2em 0; page-break-inside: avoid; }
.views { display: flex; flex-wrap: wrap; gap: 1em; } .views figure { flex: 1 1 420px; }
.caption { font-size: 1.05em; } .caption li { margin: 0.15em 0; }
.gallery { display: flex; flex-wrap: wrap; gap: 0.8em; } .gallery figure { flex: 1 1 260px; max-width: 330px; }
.failed { display: flex; align-items: center; justify-content: center; min-height: 160px; background: #f4f4f4;
          border: 1px dashed #aaa; color: #a00; font-weight: bold; }
.good { color: #176317; } .bad { color: #a00; }
.review { border: 1px solid #bbb; border-radius: 6px; padding: 0.5em 1em; background: #fafafa; }
button.mp-reject { font: inherit; padding: 0.25em 0.8em; border: 1px solid #a00; color: #a00; background: #fff;
                   border-radius: 4px; cursor: pointer; } button.mp-reject.on { background: #a00; color: #fff; }
a.mp-download[aria-disabled="true"] { color: #888; pointer-events: none; }
.mp-view3d-stage { position: relative; border: 1px solid #ccc; background: #eef1f5; }
.mp-view3d-stage canvas { display: block; width: 100%; height: 100%; cursor: grab; }
.mp-view3d-labels { position: absolute; inset: 0; pointer-events: none; overflow: hidden; }
.mp-label { position: absolute; transform: translate(-50%, -100%); color: #fff; font: bold 12px sans-serif;
            padding: 0 4px; border-radius: 3px; white-space: nowrap; }
.mp-label.mp-found { transform: translate(-50%, 0); } .mp-label.mp-hidden { opacity: 0.35; }
.mp-view3d-bar { margin: 0.4em 0; font-size: 0.9em; } .mp-view3d-bar input { vertical-align: middle; }
.mp-swatch { display: inline-block; width: 0.9em; height: 0.9em; margin-left: 1em; vertical-align: middle; }
.mp-selected { outline: 3px solid #f5c518; outline-offset: 2px; }
"""


def esc(text) -> str:
    """HTML-escaped ``str(text)``."""
    return html.escape(str(text), quote=True)


def data_uri(data: bytes, mime: str) -> str:
    """``data:`` URI of ``data`` (base64)."""
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def png_file_uri(path: str | Path) -> str:
    """``data:`` URI of a PNG file."""
    return data_uri(Path(path).read_bytes(), "image/png")


def jpeg_uri(rgb: np.ndarray, quality: int = 88) -> str:
    """``data:`` URI of an (H, W, 3) uint8 RGB image encoded as JPEG."""
    import cv2

    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(np.asarray(rgb, np.uint8)[..., ::-1]),
                           [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return data_uri(buf.tobytes(), "image/jpeg")


def png_uri(rgb: np.ndarray) -> str:
    """``data:`` URI of an (H, W, 3) uint8 RGB image encoded as PNG (for line drawings)."""
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(np.asarray(rgb, np.uint8)[..., ::-1]))
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return data_uri(buf.tobytes(), "image/png")


def img(uri: str, alt: str, caption: str | None = None) -> str:
    """A ``<figure>`` with an embedded image and an optional caption (escaped)."""
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return f'<figure><img src="{uri}" alt="{esc(alt)}">{cap}</figure>'


def _cell(value, tag: str) -> str:
    if isinstance(value, (float, np.floating)):
        return f'<{tag} class="num">{value:.2f}</{tag}>'
    if isinstance(value, (int, np.integer)):
        return f'<{tag} class="num">{int(value)}</{tag}>'
    return f"<{tag}>{esc(value)}</{tag}>"


def table(headers: Sequence[str] | None, rows: Iterable[Sequence]) -> str:
    """An HTML table (no header row when ``headers`` is None); floats are shown with 2 decimals,
    everything else escaped."""
    head = "" if headers is None else "<thead><tr>" + "".join(f"<th>{esc(h)}</th>" for h in headers) + "</tr></thead>"
    body = "".join("<tr>" + "".join(_cell(v, "td") for v in r) + "</tr>" for r in rows)
    return f"<table>{head}<tbody>{body}</tbody></table>"


_INLINE = [(re.compile(r"\*\*(.+?)\*\*"), r"<strong>\1</strong>"), (re.compile(r"(?<![\w*])\*(?!\s)(.+?)\*(?![\w*])"), r"<em>\1</em>"),
           (re.compile(r"`(.+?)`"), r"<code>\1</code>")]


def _inline(text: str) -> str:
    out = esc(text)
    for pattern, repl in _INLINE:
        out = pattern.sub(repl, out)
    return out


def _split_row(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_to_html(md: str, heading_offset: int = 1) -> str:
    """The markdown that :mod:`markerplace.testbed.reporting.tables` writes, as HTML: ``#`` headings
    (shifted down by ``heading_offset`` levels), pipe tables (the ``|---|`` line marks the
    header), paragraphs, and inline ``**bold**``, ``*italic*`` and ``code``."""
    lines = md.splitlines()
    out: list[str] = []
    para: list[str] = []

    def flush() -> None:
        if para:
            out.append(f"<p>{_inline(' '.join(para))}</p>")
            para.clear()

    i = 0
    while i < len(lines):
        line = lines[i].rstrip()
        if line.startswith("|"):
            flush()
            block = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                block.append(lines[i])
                i += 1
            rows = [_split_row(b) for b in block]
            header, body = (rows[0], rows[2:]) if len(rows) > 1 and all(set(c) <= set("-: ") for c in rows[1]) \
                else ([], rows)
            head = "<thead><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in header) + "</tr></thead>" if header else ""
            trs = "".join("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in body)
            out.append(f"<table>{head}<tbody>{trs}</tbody></table>")
            continue
        m = re.match(r"^(#{1,6})\s+(.*)$", line)
        if m:
            flush()
            level = min(6, len(m.group(1)) + heading_offset)
            out.append(f"<h{level}>{_inline(m.group(2))}</h{level}>")
        elif not line.strip():
            flush()
        else:
            para.append(line.strip())
        i += 1
    flush()
    return "\n".join(out)


def page(title: str, body: str) -> str:
    """A complete HTML5 document: inline CSS, an empty favicon (no request), ``body`` as given."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{esc(title)}</title><link rel=\"icon\" href=\"data:,\"><style>{CSS}</style></head>\n"
            f"<body>\n{body}\n</body></html>\n")


def write_page(path: str | Path, title: str, body: str) -> Path:
    """Write :func:`page` to ``path`` atomically; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(page(title, body), encoding="utf-8")
    return path
