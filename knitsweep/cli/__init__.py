"""The ``knitsweep`` command line. It holds no logic: every command builds
validated models and calls one library function, the same one the tests call.
Bad input prints one line ``error: …`` naming the field and exits with code 2.
"""

from . import analysis_commands, model_commands, run_commands  # noqa: F401 - registers commands
from .common import app, main

__all__ = ["app", "main"]
