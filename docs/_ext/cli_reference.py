"""The command-line reference, generated from the typer app when the docs build.

``.. aiofl-cli-reference::`` writes one section per ``aiofl`` command: its help text, its
arguments and options with their defaults, read from :data:`aiofl.cli.app.app`, so the page
lists what ``aiofl COMMAND --help`` lists.
"""

from __future__ import annotations

import re
from typing import Any


def _clean(text: str) -> str:
    """Help text as plain reST: rich markup dropped, ``|`` escaped, backquotes literal."""
    text = re.sub(r"\[/?[a-z ]+\]", "", text or "")
    text = text.replace("\b", "").replace("*", "\\*").replace("|", "\\|")
    return re.sub(r"(?<!`)`([^`]+)`(?!`)", r"``\1``", text)


def cli_rst() -> str:
    """Every command of ``aiofl`` as reStructuredText."""
    import click
    import typer

    from aiofl.cli.app import app

    group = typer.main.get_command(app)
    ctx = click.Context(group, info_name="aiofl")
    lines: list[str] = []
    for name in group.list_commands(ctx):  # type: ignore[attr-defined]
        cmd = group.get_command(ctx, name)  # type: ignore[attr-defined]
        if cmd is None or cmd.hidden:
            continue
        title = f"aiofl {name}"
        lines += [f".. _cli-{name}:", "", title, "-" * len(title), ""]
        help_text = _clean(cmd.help or "").split("Examples:")[0].strip()
        lines += [*help_text.splitlines(), ""]
        sub = click.Context(cmd, info_name=name, parent=ctx)
        usage = " ".join(cmd.collect_usage_pieces(sub))
        lines += [f"Usage: ``aiofl {name} {usage}``", ""]
        for param in cmd.params:
            if param.name == "help":
                continue
            if isinstance(param, click.Argument):
                head = f"``{param.human_readable_name}``"
            else:
                head = ", ".join(f"``{o}``" for o in (*param.opts, *param.secondary_opts))
            facts = []
            if getattr(param, "required", False):
                facts.append("required")
            default = param.default
            if (
                default is not None
                and not callable(default)
                and default is not False
                and default != ()
                and default != ""
                and not getattr(param, "is_flag", False)
            ):
                facts.append(f"default: ``{default}``")
            doc = _clean(getattr(param, "help", "") or "")
            tail = f" ({'; '.join(facts)})" if facts else ""
            lines += [head, f"   {' '.join(doc.split())}{tail}", ""]
    return "\n".join(lines)


def setup(app: Any) -> dict[str, Any]:
    from docutils import nodes
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    class CliReference(SphinxDirective):
        has_content = False

        def run(self) -> list[Any]:
            container = nodes.container()
            self.state.nested_parse(
                StringList(cli_rst().splitlines(), source="aiofl.cli.app"),
                self.content_offset,
                container,
                match_titles=True,
            )
            return container.children

    app.add_directive("aiofl-cli-reference", CliReference)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
