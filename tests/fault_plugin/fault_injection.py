"""The tests' fault injector: with ``KNITSWEEP_TEST_SIGNAL_AT=<stage>[#<n>][+<seconds>][@<rank>]``
a process sends itself SIGTERM at a named fault point of knitsweep
(``knitsweep.service.signals.fault_point``; the stages are ``signals.STAGES`` and
``signals.COMPILE_STAGES``). ``<n>``: the n-th time this process reaches the stage
(default the first); ``<seconds>``: that long after it, from a timer thread, so that the
signal lands wherever the main thread then is; ``<rank>``: the MPI rank, from the
launcher's PMI_RANK (default every rank).

Loaded in every process the tests start by ``sitecustomize.py`` beside it (conftest puts
this directory on PYTHONPATH), and does nothing there unless the variable is set. Two
points live here rather than in knitsweep:

* ``class``: reached inside the class creation of ``JobSpec`` (a pydantic model), in a
  ``__set_name__``, where Python wraps the signal's exception in RuntimeError (3.11),
  which every entry point must still see as the signal;
* ``llvm``: reached each time LLVM hands numba the machine code of a module it compiled
  (armed at the fault point ``compiling``, just before the kernels compile): the first
  Python code to run after LLVM's long stretch of C, so where most signals sent during
  a compile land. A signal's exception raised inside that ctypes callback does not
  propagate: ctypes reports it as unraisable and returns to LLVM.
"""

from __future__ import annotations

import os
import signal
import threading

VARIABLE = "KNITSWEEP_TEST_SIGNAL_AT"

_reached: dict[str, int] = {}
"""How often this process has reached each stage."""


def reach(stage: str) -> None:
    """Send this process SIGTERM if ``stage`` is the one the variable names (and this the
    n-th time, on this rank); arm the ``llvm`` point at ``compiling``."""
    wanted = os.environ.get(VARIABLE, "")
    if not wanted:
        return
    if stage == "compiling" and wanted.startswith("llvm"):
        _arm_llvm()
    where, _, rank = wanted.partition("@")
    where, _, delay = where.partition("+")
    where, _, nth = where.partition("#")
    if where != stage or (rank and rank != os.environ.get("PMI_RANK", "0")):
        return
    _reached[stage] = _reached.get(stage, 0) + 1
    if _reached[stage] != int(nth or 1):
        return
    if delay:
        timer = threading.Timer(float(delay), os.kill, (os.getpid(), signal.SIGTERM))
        timer.daemon = True
        timer.start()
        return
    os.kill(os.getpid(), signal.SIGTERM)  # the handler runs before the next bytecode


def _arm_llvm() -> None:
    """Make llvmlite's object-cache callbacks, which LLVM calls from C through ctypes as
    it looks for and emits a module's machine code, reach ``llvm`` first (their first
    call, ``ExecutionEngine._find_module_ptr``, is looked up at each call); once."""
    from llvmlite.binding.executionengine import ExecutionEngine

    find = ExecutionEngine._find_module_ptr
    if getattr(find, "fault_point", False):
        return

    def reached(engine, module_ptr):
        reach("llvm")
        return find(engine, module_ptr)

    reached.fault_point = True
    ExecutionEngine._find_module_ptr = reached


class _SetNameProbe:
    def __set_name__(self, owner, name) -> None:
        reach("class")


def _probe_job_spec_creation() -> None:
    """Reach ``class`` inside the creation of the class ``JobSpec``: pydantic's model
    metaclass first creates a class holding a ``__set_name__`` probe, so the signal
    arrives within a class creation and Python wraps it as it would any there."""
    from pydantic._internal._model_construction import ModelMetaclass

    create = ModelMetaclass.__new__

    def new(mcs, name, bases, namespace, *args, **kwargs):
        if name == "JobSpec":
            type("JobSpecProbe", (), {"probe": _SetNameProbe()})
        return create(mcs, name, bases, namespace, *args, **kwargs)

    ModelMetaclass.__new__ = staticmethod(new)


def install() -> None:
    """Be knitsweep's fault injector in this process (with the variable set)."""
    from knitsweep.service import signals

    signals.injector = reach
    if os.environ.get(VARIABLE, "").startswith("class"):
        _probe_job_spec_creation()
