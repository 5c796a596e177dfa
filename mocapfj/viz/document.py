"""A small document model (sections of paragraphs, tables, figures and notes) and its two
renderings: one self-contained HTML file (figures embedded as base64 PNG) and Markdown (figures
beside it in a folder). The report (:mod:`mocapfj.viz.report`) builds the sections; nothing here
knows about mocapfj's results.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field

__all__ = ["Figure", "Table", "Paragraph", "Note", "Section", "render_html", "render_markdown"]


@dataclass(frozen=True)
class Figure:
    """A PNG figure: `name` its file name in the Markdown folder, `caption` one or two sentences."""

    name: str
    png: bytes
    caption: str


@dataclass(frozen=True)
class Table:
    """A table: header cells and rows of cells (text); `flags[i]` marks row i (e.g. "bad")."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    flags: tuple[str, ...] = ()


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Note:
    """A paragraph set apart: a finding the reader must not miss (`kind` "warn" or "info")."""

    text: str
    kind: str = "info"


@dataclass(frozen=True)
class Section:
    key: str
    title: str
    blocks: tuple = field(default_factory=tuple)
    subtitle: str | None = None           # a sub-heading inside the previous section (h3)


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; margin: 0;
       color: #1d232a; background: #f6f7f9; line-height: 1.45; }
main { max-width: 1120px; margin: 0 auto; padding: 24px 32px 64px; background: white; }
h1 { font-size: 1.7em; margin: 0.2em 0 0.1em; }
h2 { font-size: 1.35em; margin-top: 1.8em; padding-top: 0.4em; border-top: 2px solid #e3e6ea; }
h3 { font-size: 1.1em; margin-top: 1.3em; }
.meta { color: #5b6570; font-size: 0.92em; }
nav { background: #f1f3f6; padding: 8px 14px; border-radius: 6px; font-size: 0.95em; }
nav a { margin-right: 14px; white-space: nowrap; }
table { border-collapse: collapse; margin: 0.6em 0 1em; font-size: 0.93em; }
th, td { border: 1px solid #d5d9de; padding: 4px 9px; text-align: left; vertical-align: top; }
th { background: #eef1f4; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.bad td { background: #fdecea; }
tr.good td { background: #eaf6ec; }
.note { border-left: 4px solid #3b82c4; background: #eef5fb; padding: 8px 12px; margin: 0.8em 0; }
.note.warn { border-left-color: #d9822b; background: #fdf3e7; }
figure { margin: 1em 0 1.4em; }
figure img { max-width: 100%; height: auto; border: 1px solid #e3e6ea; }
figcaption { color: #4a535c; font-size: 0.92em; margin-top: 4px; }
"""

_NUM_CHARS = set("0123456789+-−.,eE %±×/()[]")


def _is_num(cell: str) -> bool:
    s = cell.strip()
    return bool(s) and any(c.isdigit() for c in s) and set(s) <= _NUM_CHARS


def _html_table(t: Table) -> str:
    """Columns whose every filled cell is a number (or a vector of numbers) are right-aligned and
    do not wrap; the others are text."""
    out = ["<table>", "<thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in t.header) + "</tr></thead>",
           "<tbody>"]
    num = [all(_is_num(r[k]) for r in t.rows if k < len(r) and r[k].strip()) for k in range(len(t.header))]
    for i, row in enumerate(t.rows):
        flag = t.flags[i] if i < len(t.flags) and t.flags[i] else ""
        cells = "".join(f'<td class="num">{html.escape(c)}</td>' if k < len(num) and num[k] and c.strip()
                        else f"<td>{html.escape(c)}</td>" for k, c in enumerate(row))
        out.append(f'<tr class="{flag}">{cells}</tr>' if flag else f"<tr>{cells}</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def render_html(title: str, meta: str, sections: list[Section]) -> str:
    """One self-contained HTML page (inline CSS, figures as data: URIs)."""
    nav = " ".join(f'<a href="#{html.escape(s.key)}">{html.escape(s.title)}</a>' for s in sections if not s.subtitle)
    body = [f"<h1>{html.escape(title)}</h1>", f'<p class="meta">{html.escape(meta)}</p>', f"<nav>{nav}</nav>"]
    for s in sections:
        if s.subtitle:
            body.append(f'<h3 id="{html.escape(s.key)}">{html.escape(s.subtitle)}</h3>')
        else:
            body.append(f'<h2 id="{html.escape(s.key)}">{html.escape(s.title)}</h2>')
        for b in s.blocks:
            if isinstance(b, Paragraph):
                body.append(f"<p>{html.escape(b.text)}</p>")
            elif isinstance(b, Note):
                body.append(f'<p class="note {html.escape(b.kind)}">{html.escape(b.text)}</p>')
            elif isinstance(b, Table):
                body.append(_html_table(b))
            elif isinstance(b, Figure):
                data = base64.b64encode(b.png).decode("ascii")
                body.append(f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(b.caption)}" '
                            f'data-name="{html.escape(b.name)}"><figcaption>{html.escape(b.caption)}</figcaption></figure>')
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{html.escape(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n<main>\n"
            + "\n".join(body) + "\n</main>\n</body>\n</html>\n")


def _md_cell(c: str) -> str:
    return c.replace("|", "\\|").replace("\n", " ")


def render_markdown(title: str, meta: str, sections: list[Section], figures_dir: str) -> str:
    """Markdown with figures referenced as `figures_dir/<name>` (written beside it by the caller)."""
    out = [f"# {title}", "", f"_{meta}_", ""]
    for s in sections:
        out += [f"### {s.subtitle}" if s.subtitle else f"## {s.title}", ""]
        for b in s.blocks:
            if isinstance(b, Paragraph):
                out += [b.text, ""]
            elif isinstance(b, Note):
                out += [f"> **{'Note' if b.kind == 'info' else 'Attention'}:** {b.text}", ""]
            elif isinstance(b, Table):
                out.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
                out.append("|" + "---|" * len(b.header))
                out += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in b.rows]
                out.append("")
            elif isinstance(b, Figure):
                out += [f"![{b.caption}]({figures_dir}/{b.name})", "", f"_{b.caption}_", ""]
    return "\n".join(out).rstrip() + "\n"
