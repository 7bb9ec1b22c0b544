"""Griffe extension for the docs build: let jaxhoist's markdown docstrings render as written.

jaxhoist's docstrings (diffrax style) start a list right under a line of text, e.g.

    **Arguments**
    - `scenario`: ...

Python-Markdown only starts a list after a blank line, so without help the items would run into one
paragraph. This extension inserts that blank line when griffe loads a docstring, and keeps formulas such as
"E(t) - [W - D](t)" from reading as links; the source is unchanged.
"""

import re

import griffe

_ITEM = re.compile(r"^\s*(?:[-*+]|\d+\.)\s")
_FENCE = re.compile(r"^\s*```")
# "[a - b](t)" in a formula is not a link: a target without "/", ".", "#" or ":" is escaped.
_NOT_A_LINK = re.compile(r"\]\(([^)\s/#.:]*)\)")


def _blank_before_lists(text: str) -> str:
    out: list[str] = []
    in_fence = False
    for line in text.splitlines():
        if _FENCE.match(line):
            in_fence = not in_fence
        elif not in_fence and _ITEM.match(line) and out and out[-1].strip() and not _ITEM.match(out[-1]):
            # a list item right after text that is not itself an item (nor an item's continuation line)
            if not out[-1].startswith((" ", "\t")):
                out.append("")
        out.append(line if in_fence else _NOT_A_LINK.sub(r"]\\(\1)", line))
    return "\n".join(out)


class DocstringLists(griffe.Extension):
    """Insert a blank line between a paragraph and a list that follows it directly."""

    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:  # noqa: D102
        if obj.docstring is not None:
            obj.docstring.value = _blank_before_lists(obj.docstring.value)
