"""docs/BENCHMARKS.md as named blocks, so one section can be measured again without the rest.

Each section's table and its lines in the summary sit between HTML comments (invisible in
rendered Markdown)::

    <!-- bench:live -->  ...  <!-- /bench:live -->
    <!-- summary:live --> ... <!-- /summary:live -->

A run of some sections replaces their blocks and keeps the others as they were; every section
says when, where and by which command it was measured, so a mixed document stays honest.
"""

from __future__ import annotations

import re

_BLOCK = re.compile(r"<!-- (bench|summary):([a-z_]+) -->\n(.*?)<!-- /\1:\2 -->\n", re.S)


def read_blocks(text: str) -> dict[tuple[str, str], str]:
    """``{(kind, name): body}`` of every block in a document (kind: bench or summary)."""
    return {(m.group(1), m.group(2)): m.group(3) for m in _BLOCK.finditer(text)}


def compose(intro: list[str], order: tuple[str, ...], blocks: dict[tuple[str, str], str]) -> str:
    """The whole document: the intro, the summary blocks, then the section blocks, in
    ``order``; a section never measured is left out."""
    def wrapped(kind: str) -> list[str]:
        return [f"<!-- {kind}:{name} -->\n{blocks[kind, name]}<!-- /{kind}:{name} -->"
                for name in order if (kind, name) in blocks]

    return "\n".join([*intro, "", "## Summary", "", *wrapped("summary"), "",
                      *wrapped("bench")]) + "\n"


def body(lines: list[str]) -> str:
    """Lines as a block body (ends with a newline, so the closing comment is on its own line)."""
    return "".join(line + "\n" for line in lines)
