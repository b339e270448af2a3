"""The service layer: job specs, the worker side, executors, the master, the results
file and the entry points behind ``knitsweep run``, ``status`` and ``merge``.

``run``, ``status``, ``merge`` and ``recover`` (``service.recovery``) load on first use, so that importing
``knitsweep.service.signals`` (the CLI's first act) stays cheap."""

__all__ = ["merge", "recover", "run", "status"]


def __getattr__(name: str):
    if name == "recover":
        from .recovery import recover

        return recover
    if name in __all__:
        from . import runs

        return getattr(runs, name)
    raise AttributeError(name)
