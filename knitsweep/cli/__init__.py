"""The ``knitsweep`` command line. It holds no logic: every command builds
validated models and calls one library function, the same one the tests call.
Bad input prints one line ``error: …`` naming the field and exits with code 2;
SIGINT/SIGTERM at any moment exits with code 3 (``service.signals``).

Importing this package is cheap: ``main`` handles the signals first and only then
imports typer and the commands, so a Ctrl-C during start-up is no traceback.
"""

from __future__ import annotations

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point: signals first, then the commands; exits."""
    import sys

    from ..service import signals

    signals.install(interruptible=True)
    rc = 1
    try:
        signals.fault_point("imports")
        from .application import main as run_cli

        rc = run_cli()
    except BaseException as e:  # during start-up, before typer took over
        interrupt = signals.as_interrupt(e)
        if interrupt is None:
            signals.quiet_exit(_leave)  # an unexpected error: no rank may wait for this one
            raise
        print(f"interrupted by {interrupt}", file=sys.stderr, flush=True)
        rc = signals.EXIT_INTERRUPTED
    signals.quiet_exit(_leave)
    failed_writes = sys.modules.get("knitsweep.store.failed_writes")
    if failed_writes is not None and failed_writes.hdf5_write_failed():
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)  # the file and journal are safe; HDF5's exit clean-up is not
    sys.exit(rc)


def _leave(comm) -> None:
    """A rank's part of the MPI protocol when it stops before reaching it."""
    from ..service.executors.protocol import leave_at_start_up

    leave_at_start_up(comm)


def __getattr__(name: str):
    if name == "app":
        from .application import build_app

        return build_app()
    raise AttributeError(name)
