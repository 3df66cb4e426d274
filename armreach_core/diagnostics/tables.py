"""Markdown tables: the one way armreach's reports write them."""

from __future__ import annotations

from collections.abc import Iterable, Sequence


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[object]], align: str | None = None) -> str:
    """A GitHub-flavoured markdown table, one line per row, without a trailing newline.

    Args:
        headers: the column titles.
        rows: the cells, each turned into text with ``str`` (``|`` escaped); a row must
            have one cell per header.
        align: one letter per column, ``l``, ``r`` or ``c`` (default: every column left).

    Raises:
        ValueError: a row or ``align`` of the wrong length, or an unknown alignment letter.
    """
    marks = {"l": "---", "r": "---:", "c": ":---:"}
    align = align or "l" * len(headers)
    if len(align) != len(headers) or any(a not in marks for a in align):
        raise ValueError(f"align={align!r}: give one of l, r, c per column ({len(headers)} columns)")
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join(marks[a] for a in align) + "|"]
    for row in rows:
        cells = [str(cell).replace("|", "\\|") for cell in row]
        if len(cells) != len(headers):
            raise ValueError(f"row {cells} has {len(cells)} cells for {len(headers)} columns")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
