"""MkDocs hook: the command-line reference, generated from the CLI itself when the site
is built (``mkdocs build``), so that it cannot drift from ``knitsweep COMMAND -h``.

It walks the command tree of ``knitsweep.cli`` (typer on its own copy of click) and adds
one generated page, ``cli.md``, to the build; nothing is written into ``docs/``. Each
command gets its usage line, its help text and a table of its arguments and options as
click formats them for ``-h`` (option names with their value type, help, default).
"""

from __future__ import annotations

import html
import re

PAGE = "cli.md"
_MARKDOWN_SPECIALS = re.compile(r"([\\`*_\[\]|#])")


def _text(s: str) -> str:
    """Help text as Markdown that shows it literally: rich's escapes undone, markup
    characters escaped, angle brackets as entities (``<path>`` is no HTML tag)."""
    s = s.replace("\\[", "[")
    return _MARKDOWN_SPECIALS.sub(r"\\\1", html.escape(s, quote=False))


def _code(s: str) -> str:
    return "`" + s.replace("`", "'") + "`"


def _paragraphs(help_text: str) -> list[str]:
    """click's help paragraphs, each re-flowed onto one line (``\\b`` blocks kept)."""
    out = []
    for block in re.split(r"\n\s*\n", help_text.strip()):
        lines = [ln for ln in block.splitlines() if ln.strip() != "\b"]
        if block.lstrip().startswith("\b"):
            out.append("  \n".join(_text(ln.strip()) for ln in lines))
        else:
            out.append(_text(" ".join(ln.strip() for ln in lines)))
    return out


def _command(cmd, ctx, level: int) -> list[str]:
    click = _click()
    path = ctx.command_path
    lines = [f"{'#' * level} {path}", ""]
    if cmd.help:
        lines += [p + "\n" for p in _paragraphs(cmd.help)]
    lines += ["```text", cmd.get_usage(ctx).strip(), "```", ""]
    rows = []
    for param in cmd.get_params(ctx):
        if getattr(param, "hidden", False):
            continue
        record = param.get_help_record(ctx)
        if record is None:
            continue
        names, help_text = record
        if param.param_type_name == "option":
            short = [o for o in param.opts + param.secondary_opts if not o.startswith("--")]
            if short and not any(s in names for s in short):
                names = ", ".join(short) + ", " + names
        kind = "argument" if param.param_type_name == "argument" else "option"
        rows.append(f"| {_code(names)} | {kind} | {_text(' '.join(help_text.split()))} |")
    if rows:
        lines += ["| name | kind | meaning |", "|---|---|---|", *rows, ""]
    if hasattr(cmd, "list_commands"):  # a group (typer's copy of click has no Group class)
        for name in cmd.list_commands(ctx):
            sub = cmd.get_command(ctx, name)
            if sub is None or getattr(sub, "hidden", False):
                continue
            sub_ctx = click.Context(sub, info_name=name, parent=ctx, **sub.context_settings)
            lines += _command(sub, sub_ctx, min(level + 1, 6))
    return lines


def _click():
    import typer._click as click  # typer's own copy of click, which its commands subclass

    return click


def root_command():
    """The ``knitsweep`` command group as click sees it."""
    import typer.main

    from knitsweep.cli.application import build_app

    return typer.main.get_command(build_app())


def render() -> str:
    """The whole reference page as Markdown."""
    root = root_command()
    ctx = _click().Context(root, info_name="knitsweep", **root.context_settings)
    head = [
        "# Command line",
        "",
        "Generated from the command line itself when this site is built: the same text as "
        "`knitsweep -h` and `knitsweep COMMAND -h`. Bad input is one line `error: …` naming "
        "the field and the allowed range, exit code 2 ([Input validation](input-validation.md)); "
        "the exit codes of `run` are in [Running, resuming and growing]"
        "(how-to/runs.md#how-a-run-ends-exit-codes).",
        "",
    ]
    return "\n".join(head + _command(root, ctx, 2)) + "\n"


def on_files(files, config):
    """MkDocs event: add the generated page to the build."""
    from mkdocs.structure.files import File

    files.append(File.generated(config, PAGE, content=render()))
    return files
