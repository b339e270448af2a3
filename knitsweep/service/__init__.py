"""The service layer: job specs, the worker side, executors, the master, the results
file and the entry points behind ``knitsweep run``, ``status`` and ``merge``."""

from .runs import merge, run, status

__all__ = ["merge", "run", "status"]
