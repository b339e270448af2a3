"""The app with every command registered, and the run of one command line: the top
of the CLI (``common`` holds what the commands share, below them)."""

from __future__ import annotations

import typer

from . import analysis_commands, model_commands, run_commands  # noqa: F401 - registers
from .common import app


def build_app() -> typer.Typer:
    """The app with every command registered."""
    return app


def main() -> int:
    """The commands' exit code: usage errors become one line and exit code 2, a signal
    one line and exit code 3 (``knitsweep.cli.main`` handles signals first)."""
    from ..service.signals import EXIT_INTERRUPTED, Interrupted, as_interrupt

    try:
        rc = build_app()(prog_name="knitsweep", standalone_mode=False)
    except Interrupted as e:
        typer.echo(f"interrupted by {e}", err=True)
        rc = EXIT_INTERRUPTED
    except RuntimeError as e:  # a signal's exception wrapped (e.g. in class creation)
        if as_interrupt(e) is None:
            raise
        typer.echo(f"interrupted by {as_interrupt(e)}", err=True)
        rc = EXIT_INTERRUPTED
    except typer.Exit as e:
        rc = e.exit_code
    except typer.Abort:
        typer.echo("aborted", err=True)
        rc = 130
    except Exception as e:  # click's usage errors (typer vendors click privately)
        if not (hasattr(e, "format_message") and hasattr(e, "exit_code")):
            raise
        ctx = getattr(e, "ctx", None)
        if type(e).__name__ == "NoArgsIsHelpError":
            rc = 0  # typer has printed the help already
        else:
            where = f"{ctx.command_path}: " if ctx is not None else ""
            typer.echo(f"error: {where}{e.format_message()}", err=True)
            rc = e.exit_code
    return rc if isinstance(rc, int) else 0
