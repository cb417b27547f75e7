"""The pages a person opens in a browser: benchlab's Markdown pages (report.md, diagnose.md) as HTML beside them.

One small renderer for the subset those pages are written in (headings, paragraphs, pipe tables, images on a line of
their own, **bold**, `code`, *italics*, [links](url), backslash escapes, the pages' own <details> blocks), not a
general Markdown engine: the pages are ours, so a dependency for the rest of Markdown would earn nothing. What a
stranger wrote enters a page through benchlab/report/markdown.py as text; the renderer itself still turns no other
HTML into markup and links only relative or http(s) addresses. Figures become <figure>s with their caption, tables
keep their units in the header, and the page is one file that opens from disk (a bench PC without a web server).
"""

from __future__ import annotations

import html
import os
import re
from pathlib import Path

from benchlab.outputs import write_text
from benchlab.report.markdown import ESCAPABLE

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
_SUMMARY = re.compile(r"^<details><summary>([^<>\n]*)</summary>$")  # the pages' own HTML, a collapsed table
_NUMBER = re.compile(r"^([-+−]?\d[\d.,]*(e[-+]?\d+)?|—)(\s*[^\s\d]{1,4})?$")
_CODE_OR_ESCAPE = re.compile(r"(`[^`]*`|\\[" + re.escape(ESCAPABLE) + "])")
_CELL = re.compile(r"(?<!\\)\|")
#: Each code span or escaped character stands in the text as one character of Unicode's private use plane 15 while
#: the markup is read, so no markup inside them counts; such characters in the page itself are dropped.
_HOLDER = 0xF0000
_HOLDERS = re.compile("[\U000F0000-\U000FFFFF]")
_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*):")


def safe_url(url: str) -> bool:
    """Whether a link or image may point there: relative, or http(s); never javascript:, data: or any other scheme
    (as a browser reads the address: entities decoded, white space and control characters ignored)."""
    bare = re.sub(r"[\x00-\x20\x7f]", "", html.unescape(url))
    scheme = _SCHEME.match(bare)
    return scheme is None or scheme[1].lower() in ("http", "https")


def _link(match: re.Match[str]) -> str:
    label, url = match[1], html.unescape(match[2])
    if _HOLDERS.search(url) or not safe_url(url):  # an address with code or escapes in it is none of ours
        return match[0]
    return f'<a href="{html.escape(url)}">{label}</a>'


def _inline(text: str) -> str:
    """One line of Markdown text as HTML: escaped, then `code` (left as it is inside), backslash escapes (the
    character itself), **bold**, *italics*, links (relative or http(s) only)."""
    held: list[str] = []

    def hold(match: re.Match[str]) -> str:
        piece = match[0]
        held.append(f"<code>{html.escape(piece[1:-1])}</code>" if piece.startswith("`") else html.escape(piece[1]))
        return chr(_HOLDER + len(held) - 1)

    text = _CODE_OR_ESCAPE.sub(hold, _HOLDERS.sub("", text))
    text = html.escape(text, quote=False)
    text = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", text)
    text = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<i>\1</i>", text)
    text = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", _link, text)
    text = re.sub(r"([ϑωΔ])_([A-Za-z]{1,3})\b", r"\1<sub>\2</sub>", text)  # ϑ_F as the paper writes it
    return _HOLDERS.sub(lambda m: held[ord(m[0]) - _HOLDER], text)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in _CELL.split(line.strip().strip("|"))]


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


def _figure(match: re.Match[str]) -> str:
    """An image on a line of its own as a figure with its caption (a link to it); text where its address is unsafe."""
    if not safe_url(match[2]):
        return f"<p>{html.escape(match[0])}</p>"
    src, caption = html.escape(match[2]), html.escape(match[1])
    return f'<figure><a href="{src}"><img src="{src}" alt="{caption}"></a><figcaption>{caption}</figcaption></figure>'


def _block(block: str) -> str:
    """One block as HTML. Raw HTML only as the pages' own blocks (a <details> with its <summary>, its end); any
    other HTML is text."""
    lines = block.strip().splitlines()
    first = lines[0]
    summary = _SUMMARY.match(block.strip())
    if summary:
        return f"<details><summary>{_inline(summary[1])}</summary>"
    if block.strip() == "</details>":
        return "</details>"
    if first.startswith("#"):
        level = min(len(first) - len(first.lstrip("#")), 6)
        heading = f"<h{level}>{_inline(first[level:].strip())}</h{level}>"
        return heading + (_block("\n".join(lines[1:])) if len(lines) > 1 else "")
    if len(lines) >= 2 and first.startswith("|") and _TABLE_RULE.match(lines[1].replace(" ", "")):
        return _table(lines)
    images = [_IMAGE.match(line.strip()) for line in lines]
    if all(images):
        return "".join(_figure(m) for m in images if m is not None)
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
