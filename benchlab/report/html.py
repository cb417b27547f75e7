"""The pages a person opens in a browser: benchlab's Markdown pages (report.md, diagnose.md) as HTML beside them.

One small renderer for the subset those pages are written in (headings, paragraphs, pipe tables, images on a line of
their own, **bold**, `code`, *italics*, [links](url), <details> blocks), not a general Markdown engine: the pages are
ours, so a dependency for the rest of Markdown would earn nothing. Figures become <figure>s with their caption, tables
keep their units in the header, and the page is one file that opens from disk (a bench PC without a web server).
"""

from __future__ import annotations

import html
import os
import re
from pathlib import Path

from benchlab.outputs import write_text

#: The look of every page benchlab writes as HTML (the job's index page too): readable width, ruled tables with
#: numbers right-aligned, figures no wider than the page.
STYLE = ("body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em;line-height:1.4}"
         "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}"
         "td:first-child,th:first-child,.text{text-align:left}th{background:#eee}img{max-width:100%}"
         "figure{margin:1em 0}"
         "figcaption{color:#555;font-size:0.9em}code{background:#f4f4f4;padding:0 2px}"
         ".sim{background:#fff4d6;padding:0.6em;border:1px solid #e0c060}.scroll{overflow-x:auto}")

_IMAGE = re.compile(r"^!\[([^\]]*)\]\(([^)\s]+)\)$")
_TABLE_RULE = re.compile(r"^\|(\s*:?-+:?\s*\|)+$")
_RAW = ("<details", "</details")
_NUMBER = re.compile(r"^([-+−]?\d[\d.,]*(e[-+]?\d+)?|—)(\s*[^\s\d]{1,4})?$")


def _inline(text: str) -> str:
    """One line of Markdown text as HTML: escaped, then `code` (left as it is inside), **bold**, *italics*, links."""
    pieces = re.split(r"(`[^`]*`)", text)
    out = []
    for piece in pieces:
        if len(piece) >= 2 and piece.startswith("`") and piece.endswith("`"):
            out.append(f"<code>{html.escape(piece[1:-1])}</code>")
            continue
        piece = html.escape(piece, quote=False)
        piece = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", piece)
        piece = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<i>\1</i>", piece)
        piece = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", lambda m: f'<a href="{html.escape(m[2])}">{m[1]}</a>', piece)
        piece = re.sub(r"([ϑωΔ])_([A-Za-z]{1,3})\b", r"\1<sub>\2</sub>", piece)  # ϑ_F as the paper writes it
        out.append(piece)
    return "".join(out)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _table(lines: list[str]) -> str:
    """A pipe table; a column of numbers (with a unit, or a dash for none) right-aligned, its header too, others
    left-aligned."""
    header, rows = _cells(lines[0]), [_cells(line) for line in lines[2:]]
    numeric = [all(_NUMBER.match(row[i]) for row in rows if i < len(row)) for i in range(len(header))]
    align = ["" if number else " class='text'" for number in numeric]
    head = "".join(f"<th{align[i]}>{_inline(c)}</th>" for i, c in enumerate(header))
    body = "".join("<tr>" + "".join(f"<td{align[i] if i < len(align) else ''}>{_inline(c)}</td>"
                                    for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f"<div class='scroll'><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>"


def _block(block: str) -> str:
    lines = block.strip().splitlines()
    first = lines[0]
    if first.startswith(_RAW):  # the pages' own HTML (a collapsed table): kept as written
        return block.strip()
    if first.startswith("#"):
        level = min(len(first) - len(first.lstrip("#")), 6)
        heading = f"<h{level}>{_inline(first[level:].strip())}</h{level}>"
        return heading + (_block("\n".join(lines[1:])) if len(lines) > 1 else "")
    if len(lines) >= 2 and first.startswith("|") and _TABLE_RULE.match(lines[1].replace(" ", "")):
        return _table(lines)
    images = [_IMAGE.match(line.strip()) for line in lines]
    if all(images):
        return "".join(f'<figure><a href="{html.escape(m[2])}"><img src="{html.escape(m[2])}" '
                       f'alt="{html.escape(m[1])}"></a><figcaption>{html.escape(m[1])}</figcaption></figure>'
                       for m in images if m is not None)
    return f"<p>{_inline(' '.join(line.strip() for line in lines))}</p>"


def markdown_html(text: str, title: str) -> str:
    """A whole HTML page of one of benchlab's Markdown pages (blocks separated by blank lines)."""
    blocks = [b for b in re.split(r"\n\s*\n", text) if b.strip()]
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{STYLE}</style></head><body>\n" + "\n".join(_block(b) for b in blocks) + "\n</body></html>\n")


def write_html(markdown_page: "str | os.PathLike[str]", title: str) -> Path:
    """Write the HTML page beside a Markdown page (same name, .html; its figures are beside both); its path."""
    source = Path(markdown_page)
    page = source.with_suffix(".html")
    write_text(page, markdown_html(source.read_text(encoding="utf-8"), title))
    return page
