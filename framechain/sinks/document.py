"""One document model for every report: sections of headings, paragraphs, tables, lists and figures, written once
and rendered as Markdown (:func:`markdown`) or as one self-contained HTML page (:func:`html_page`).

A block may belong to one format only (``only``): the HTML findings table has an evidence column where Markdown
lists the evidence below the table, and the colour legend has swatches in HTML. HTML is laid out in lines as the
reports always were: each block starts a line unless it is ``joined`` to the one before (a heading and its
table), a table's rows and a grid's figures each take a line, and a ``compact`` section is one run of markup
glued to what follows. Markdown separates blocks by a blank line, and in a table cell or a list item a ``|``
becomes the document's ``pipe`` (a cell's line breaks become spaces).
"""

from __future__ import annotations

import html
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from framechain.sinks.plots import Figure, figure_html
from framechain.sinks.text import CSS, breakable

__all__ = [
    "Block",
    "Bullets",
    "Callout",
    "Column",
    "Document",
    "FigureBlock",
    "Figures",
    "Heading",
    "Html",
    "ListItem",
    "Paragraph",
    "Row",
    "Section",
    "Table",
    "code_spans",
    "html_page",
    "markdown",
    "table",
]

Format = Literal["md", "html"]
#: How an HTML table cell shows its text: escaped (``text``), with break opportunities in long words (``wrap``),
#: bold (``strong``), with its `backticked` commands as code (``command``), all code (``code``), right-aligned
#: (``num``), or as the row's header (``key``).
CellStyle = Literal["text", "wrap", "strong", "command", "code", "num", "key"]
#: A row drawn pale (a weak finding, a family not observable) or flagged (a label that disagrees).
Tone = Literal["", "muted", "alert"]
_TONE_ATTR: dict[Tone, str] = {"": "", "muted": " style='color:#777'", "alert": " style='background:#fff0f0'"}


@dataclass(frozen=True, kw_only=True)
class Block:
    """What every block has: the format it belongs to (None: both), and whether in HTML it continues the line of
    the block before it instead of starting one."""

    only: Format | None = None
    joined: bool = False


@dataclass(frozen=True)
class Heading(Block):
    text: str
    level: int = 2


@dataclass(frozen=True)
class Paragraph(Block):
    """Text; in HTML ``muted`` small and grey, ``code`` with its `backticked` words as code, ``raw`` as written
    (a sentence of ours without markup characters: its quotes are not escaped)."""

    text: str
    muted: bool = False
    code: bool = False
    raw: bool = False


@dataclass(frozen=True)
class Callout(Block):
    """One sentence set apart (a verdict, a summary): bold in Markdown, a box of ``kind`` in HTML."""

    text: str
    kind: str


@dataclass(frozen=True)
class Html(Block):
    """Markup for the HTML page alone (a legend with colour swatches)."""

    markup: str
    only: Format | None = field(default="html", kw_only=True)


@dataclass(frozen=True)
class ListItem:
    """An item of a list: a bold ``lead`` (may be empty), then ``text``."""

    text: str
    lead: str = ""


@dataclass(frozen=True)
class Bullets(Block):
    """A bulleted list; ``muted``: in HTML a muted paragraph per item instead (notes beside the page's content)."""

    items: tuple[ListItem, ...]
    muted: bool = False


@dataclass(frozen=True)
class Column:
    """A table column: its name, how HTML shows its cells, and the format it belongs to (None: both);
    ``right``: right-aligned in Markdown."""

    name: str
    cell: CellStyle = "text"
    only: Format | None = None
    right: bool = False


@dataclass(frozen=True)
class Row:
    cells: tuple[str, ...]
    tone: Tone = ""


@dataclass(frozen=True)
class Table(Block):
    """Columns and rows of text cells; a table whose columns have no names has no header row in HTML."""

    columns: tuple[Column, ...]
    rows: tuple[Row, ...]


@dataclass(frozen=True)
class FigureBlock(Block):
    """One figure on its own: its image in Markdown (a PNG beside the page), embedded in HTML."""

    figure: Figure


@dataclass(frozen=True)
class Figures(Block):
    """Figures side by side in HTML (a grid); in Markdown each under a heading of its caption (``headed``) or one
    image a line."""

    figures: tuple[Figure, ...]
    headed: bool = False


@dataclass(frozen=True)
class Section:
    """A heading (or none) and its blocks; ``compact``: in HTML, one run of markup glued to what follows."""

    heading: Heading | None
    blocks: tuple[Block, ...] = ()
    compact: bool = False
    only: Format | None = None

    def all_blocks(self) -> tuple[Block, ...]:
        return self.blocks if self.heading is None else (self.heading, *self.blocks)


@dataclass(frozen=True)
class Document:
    """A page: its title (the ``# heading``), the HTML page's ``<title>``, its sections, and what a ``|`` inside a
    Markdown table cell or list item becomes."""

    title: str
    page_title: str
    sections: tuple[Section, ...] = field(default_factory=tuple)
    pipe: str = "/"


def table(columns: Sequence[str | Column], rows: Iterable[Sequence[str]], *,
          tone: Callable[[Sequence[str]], Tone] | None = None, only: Format | None = None,
          joined: bool = False) -> Table:
    """The one way to make a table: column names (or :class:`Column`), rows of text cells, each row's tone."""
    cols = tuple(c if isinstance(c, Column) else Column(c) for c in columns)
    made = tuple(Row(tuple(cells), tone(cells) if tone is not None else "") for cells in rows)
    return Table(cols, made, only=only, joined=joined)


# -- Markdown ---------------------------------------------------------------------------------
def write_document(doc: Document, figures: Iterable[Figure], out: Path, formats: Sequence[str], stem: str,
                   key_prefix: str = "") -> dict[str, Path]:
    """Write ``doc`` as ``out/STEM.md`` (with its figures as PNGs beside it, which the Markdown links to) and/or
    ``out/STEM.html`` (figures inline); returns the paths written, keyed ``md``/``html`` after ``key_prefix``."""
    paths: dict[str, Path] = {}
    if "md" in formats:
        for fig in figures:
            (out / f"{fig.name}.png").write_bytes(fig.png)
        paths[f"{key_prefix}md"] = out / f"{stem}.md"
        paths[f"{key_prefix}md"].write_text(markdown(doc))
    if "html" in formats:
        paths[f"{key_prefix}html"] = out / f"{stem}.html"
        paths[f"{key_prefix}html"].write_text(html_page(doc))
    return paths


def markdown(doc: Document) -> str:
    """The document as Markdown: the title, then every block of ``md`` or both formats, a blank line apart."""
    lines = [f"# {doc.title}"]
    for block in _blocks(doc, "md"):
        drawn = _md_lines(block, doc.pipe)
        if drawn:
            lines += ["", *drawn]
    return "\n".join(lines) + "\n"


def _md_lines(block: Block, pipe: str) -> list[str]:
    if isinstance(block, Heading):
        return [f"{'#' * block.level} {block.text}"]
    if isinstance(block, Paragraph):
        return [block.text]
    if isinstance(block, Callout):
        return [f"**{block.text}**"]
    if isinstance(block, Bullets):
        return [f"- {f'**{i.lead}**' if i.lead else ''}{i.text}".replace("|", pipe) for i in block.items]
    if isinstance(block, Table):
        return _md_table(block, pipe)
    if isinstance(block, FigureBlock):
        return [_md_image(block.figure)]
    if isinstance(block, Figures):
        if not block.headed:
            return [_md_image(f) for f in block.figures]
        return [line for k, f in enumerate(block.figures)
                for line in ([""] if k else []) + [f"### {f.caption}", "", _md_image(f)]]
    return []


def _md_image(figure: Figure) -> str:
    return f"![{figure.caption}]({figure.name}.png)"


def _md_table(block: Table, pipe: str) -> list[str]:
    keep = [k for k, c in enumerate(block.columns) if c.only != "html"]
    names = [block.columns[k].name for k in keep]
    header = "| " + " | ".join(names) + " |" if any(names) else "|" + " |" * len(names)
    rule = "| " + " | ".join("---:" if block.columns[k].right else "---" for k in keep) + " |"
    rows = ["| " + " | ".join(row.cells[k].replace("|", pipe).replace("\n", " ") for k in keep) + " |"
            for row in block.rows]
    return [header, rule, *rows]


# -- HTML -------------------------------------------------------------------------------------
def html_page(doc: Document) -> str:
    """The document as one self-contained HTML page (the reports' style; figures embedded)."""
    e = html.escape
    lines = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{e(doc.page_title)}</title>",
             f"<style>{CSS}</style></head><body>", f"<h1>{e(doc.title)}</h1>"]
    glued = ""  # a compact section's markup, waiting for what follows it
    for section in doc.sections:
        if section.only == "md":
            continue
        drawn = [(block, _html_chunks(block)) for block in section.all_blocks() if block.only != "md"]
        if section.compact:
            glued += "".join("".join(chunks) for _block, chunks in drawn)
            continue
        for block, chunks in drawn:
            if not chunks:
                continue
            first, glued = glued + chunks[0], ""
            if block.joined:
                lines[-1] += first
            else:
                lines.append(first)
            lines += chunks[1:]
    lines[-1] += glued + "</body></html>"
    return "\n".join(lines)


def _html_chunks(block: Block) -> list[str]:
    """A block's markup, a piece per line: a table's opening, each row and its end; a grid's opening, each figure
    and its end; one piece for anything else."""
    e = html.escape
    if isinstance(block, Heading):
        return [f"<h{block.level}>{e(block.text, quote=False)}</h{block.level}>"]
    if isinstance(block, Paragraph):
        text = block.text if block.raw else code_spans(block.text) if block.code else e(block.text)
        return [f"<p class='muted'>{text}</p>" if block.muted else f"<p>{text}</p>"]
    if isinstance(block, Callout):
        return [f"<div class='{block.kind}'>{e(block.text)}</div>"]
    if isinstance(block, Html):
        return [block.markup]
    if isinstance(block, Bullets):
        if block.muted:
            return [f"<p class='muted'>{_html_item(i, wrap=False)}</p>" for i in block.items]
        return ["<ul>" + "".join(f"<li>{_html_item(i, wrap=True)}</li>" for i in block.items) + "</ul>"]
    if isinstance(block, Table):
        return list(_html_table(block))
    if isinstance(block, FigureBlock):
        return [figure_html(block.figure)]
    if isinstance(block, Figures):
        return ["<div class='plots'>", *(figure_html(f) for f in block.figures), "</div>"]
    return []


def _html_item(item: ListItem, *, wrap: bool) -> str:
    text = breakable(item.text) if wrap else html.escape(item.text)
    return f"<b>{html.escape(item.lead)}</b>{text}" if item.lead else text


def _html_table(block: Table) -> Iterator[str]:
    kept = [(k, c) for k, c in enumerate(block.columns) if c.only != "md"]
    head = "".join(f"<th>{html.escape(c.name)}</th>" for _k, c in kept)
    yield f"<table><tr>{head}</tr>" if any(c.name for _k, c in kept) else "<table>"
    for row in block.rows:
        yield f"<tr{_TONE_ATTR[row.tone]}>" + "".join(_CELLS[c.cell](row.cells[k]) for k, c in kept) + "</tr>"
    yield "</table>"


_CELLS: dict[CellStyle, Callable[[str], str]] = {
    "text": lambda text: f"<td>{html.escape(text)}</td>",
    "wrap": lambda text: f"<td>{breakable(text)}</td>",
    "strong": lambda text: f"<td><b>{breakable(text)}</b></td>",
    "command": lambda text: f"<td>{code_spans(text, wrap=True)}</td>",
    "code": lambda text: f"<td><code>{html.escape(text)}</code></td>",
    "num": lambda text: f"<td class='num'>{html.escape(text)}</td>",
    "key": lambda text: f"<th>{html.escape(text)}</th>",
}


def code_spans(text: str, *, wrap: bool = False) -> str:
    """Escape, and show `backticked` words as code; ``wrap``: both breaking long words at their joints
    (:func:`~framechain.sinks.text.breakable`; a command's ``--flag`` kept whole)."""
    if not wrap:
        pieces = html.escape(text).split("`")
        return "".join(f"<code>{p}</code>" if i % 2 else p for i, p in enumerate(pieces))
    pieces = text.split("`")
    return "".join(f"<code>{breakable(p, code=True)}</code>" if i % 2 else breakable(p) for i, p in enumerate(pieces))


def _blocks(doc: Document, fmt: Format) -> Iterator[Block]:
    for section in doc.sections:
        if section.only in (None, fmt):
            yield from (b for b in section.all_blocks() if b.only in (None, fmt))
