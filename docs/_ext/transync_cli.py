"""``.. transync-cli::`` -- the command line's help, rendered from ``transync.cli.build_parser()``.

One section per subcommand, in the parser's order, each with its one-line summary and its full
``--help`` text, so that the page can never drift from the parser.
"""

from __future__ import annotations

import argparse
import os

from docutils import nodes
from sphinx.util.docutils import SphinxDirective


def _subcommands(parser: argparse.ArgumentParser):
    for action in parser._actions:                         # noqa: SLF001 - argparse has no API
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            summaries = {a.dest: a.help for a in action._choices_actions}  # noqa: SLF001
            for name, sub in action.choices.items():
                yield name, summaries.get(name) or "", sub


def _help(parser: argparse.ArgumentParser) -> str:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"                        # a fixed width, whatever the terminal
    try:
        return parser.format_help()
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old


class TransyncCLI(SphinxDirective):
    """Top-level help, then a section per subcommand."""

    has_content = False

    def run(self):
        from transync.cli import build_parser

        parser = build_parser()
        out = [nodes.literal_block(text=_help(parser), language="text")]
        for name, summary, sub in _subcommands(parser):
            section_id = f"transync-{name}"
            section = nodes.section(ids=[section_id], names=[section_id])
            section += nodes.title(text=f"transync {name}")
            if summary:
                section += nodes.paragraph(text=summary[0].upper() + summary[1:] + ".")
            section += nodes.literal_block(text=_help(sub), language="text")
            out.append(section)
        return out


def setup(app):
    app.add_directive("transync-cli", TransyncCLI)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
