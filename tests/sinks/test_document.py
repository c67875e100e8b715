"""The reports' one document model: a section written once reads the same in Markdown and in HTML, each format
keeps its own blocks, and HTML is laid out in lines as the reports always were."""

from __future__ import annotations

from framechain.sinks.document import (
    Bullets,
    Callout,
    Column,
    Document,
    Heading,
    Html,
    ListItem,
    Paragraph,
    Section,
    html_page,
    markdown,
    table,
)


def _body(page: str) -> list[str]:
    """The page's lines after the title, without the closing tags."""
    head, body = page.removesuffix("</body></html>").split("<h1>t</h1>\n")
    assert head.startswith("<!doctype html><html lang='en'><head><meta charset='utf-8'><title>p</title>")
    return body.split("\n")


def test_a_table_is_built_once_and_reads_the_same_in_both_formats() -> None:
    rows = [("tag_3", "a | b", "ok"), ("tag_4", "two\nlines", "moving")]
    made = table([Column("label", "code"), "note", Column("verdict", only="html")], rows,
                 tone=lambda row: "alert" if row[2] == "moving" else "")
    doc = Document("t", "p", (Section(Heading("Labels"), (made,)),), pipe="\\|")
    assert markdown(doc) == ("# t\n\n## Labels\n\n| label | note |\n| --- | --- |\n| tag_3 | a \\| b |\n"
                             "| tag_4 | two lines |\n")
    assert "\n".join(_body(html_page(doc))) == (
        "<h2>Labels</h2>\n<table><tr><th>label</th><th>note</th><th>verdict</th></tr>\n"
        "<tr><td><code>tag_3</code></td><td>a | b</td><td>ok</td></tr>\n"
        "<tr style='background:#fff0f0'><td><code>tag_4</code></td><td>two\nlines</td><td>moving</td></tr>\n"
        "</table>")


def test_a_table_without_column_names_has_no_header_row_in_html() -> None:
    made = table([Column("", "key"), Column("", "wrap")], [("file", "a.bag")])
    doc = Document("t", "p", (Section(None, (made,)),))
    assert markdown(doc) == "# t\n\n| | |\n| --- | --- |\n| file | a.bag |\n"
    assert _body(html_page(doc)) == ["<table>", "<tr><th>file</th><td>a.bag</td></tr>", "</table>"]


def test_each_format_keeps_its_own_blocks() -> None:
    doc = Document("t", "p", (
        Section(None, (Callout("All clear.", kind="verdict clean"),)),
        Section(Heading("Error"), (Paragraph("median 3 mm", only="md"),
                                   Paragraph("median 3 mm. 10 observations.", only="html", joined=True),
                                   Html("<p class='legend'>swatches</p>"))),
        Section(Heading("Findings"), (Bullets((ListItem(": late by 30 ms", lead="latency"),), only="md"),)),
    ))
    assert markdown(doc) == ("# t\n\n**All clear.**\n\n## Error\n\nmedian 3 mm\n\n## Findings\n\n"
                             "- **latency**: late by 30 ms\n")
    assert _body(html_page(doc)) == ["<div class='verdict clean'>All clear.</div>",
                                     "<h2>Error</h2><p>median 3 mm. 10 observations.</p>",
                                     "<p class='legend'>swatches</p>", "<h2>Findings</h2>"]


def test_a_compact_section_is_one_run_of_markup_glued_to_what_follows() -> None:
    compact = Section(Heading("Checks"), (Paragraph("Can't see it.", raw=True),
                                         table(["a"], [("1",)])), compact=True)
    doc = Document("t", "p", (compact, Section(Heading("Provenance"), (Paragraph("x", muted=True, joined=True),))))
    assert _body(html_page(doc)) == [
        "<h2>Checks</h2><p>Can't see it.</p><table><tr><th>a</th></tr><tr><td>1</td></tr></table>"
        "<h2>Provenance</h2><p class='muted'>x</p>"]
    assert markdown(doc) == "# t\n\n## Checks\n\nCan't see it.\n\n| a |\n| --- |\n| 1 |\n\n## Provenance\n\nx\n"


def test_notes_are_a_list_in_markdown_and_muted_paragraphs_in_html() -> None:
    notes = Bullets((ListItem("note: a <b>"), ListItem("note: c")), muted=True)
    doc = Document("t", "p", (Section(None, (notes,)),))
    assert markdown(doc) == "# t\n\n- note: a <b>\n- note: c\n"
    assert _body(html_page(doc)) == ["<p class='muted'>note: a &lt;b&gt;</p>", "<p class='muted'>note: c</p>"]
