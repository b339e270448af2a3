"""Ready-to-submit SLURM batch scripts (``knitsweep slurm render``).

The templates are shipped as package data, ``knitsweep/service/templates/*.sbatch``, and
are the only copy: ``slurm/*.sbatch`` in the repository are symlinks to them.
Each is a working script on its own (``sbatch knitsweep-mpi.sbatch JOB OUT``);
``render`` fills in what a user would otherwise pass each time: the job file
and output (as default arguments, absolute paths), the ``#SBATCH`` resources
and the ``KNITSWEEP_*`` settings, which the rendered script fixes instead of
reading them from the submitter's environment. The user guide is slurm/README.md.
"""

from __future__ import annotations

import re
import shlex
from importlib import resources
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from .._version import __version__
from ..errors import InputError

TemplateName = Literal["mpi", "array", "merge"]
TEMPLATE_FILES = {
    "mpi": "knitsweep-mpi.sbatch",
    "array": "knitsweep-array.sbatch",
    "merge": "knitsweep-merge.sbatch",
}
SIGNAL_LEAD_S = 120  # the templates' --signal=B:TERM@120
_WALLTIME = re.compile(r"(?:(\d+)-)?(\d+):([0-5]\d):([0-5]\d)")
_PARTITION = re.compile(r"[A-Za-z0-9_.-]+(?:,[A-Za-z0-9_.-]+)*")
_MODULES = re.compile(r"[A-Za-z0-9_.+/@=-]+(?: +[A-Za-z0-9_.+/@=-]+)*")

# settings that only some templates take
_TAKEN_BY = {
    "nodes": ("mpi",),
    "ntasks": ("mpi",),
    "launcher": ("mpi",),
    "shards": ("array",),
    "cpus_per_task": ("array",),
    "requeue": ("mpi", "array"),
}


def template_path(name: str) -> Path:
    """The shipped template file for ``name`` (mpi, array or merge)."""
    if name not in TEMPLATE_FILES:
        raise InputError(f"template = {name!r}: must be one of {', '.join(TEMPLATE_FILES)}")
    return Path(str(resources.files("knitsweep") / "service" / "templates" / TEMPLATE_FILES[name]))


def walltime_seconds(text: str) -> int:
    """Seconds in a SLURM walltime ``HH:MM:SS`` or ``D-HH:MM:SS``."""
    m = _WALLTIME.fullmatch(text)
    if m is None:
        raise ValueError("must be HH:MM:SS or D-HH:MM:SS, e.g. 24:00:00")
    days, hours, minutes, seconds = (int(g or 0) for g in m.groups())
    return ((days * 24 + hours) * 60 + minutes) * 60 + seconds


class SlurmScript(BaseModel):
    """What ``knitsweep slurm render`` fills into a template. ``out`` is the
    results file for ``mpi`` and the shard directory for ``array`` and ``merge``
    (the merged file is ``<out>/<job name>.h5``)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    template: TemplateName = "mpi"
    job: Path = Field(description="job file (TOML)")
    out: Path = Field(description="results file (mpi) or shard directory (array, merge)")
    nodes: int | None = Field(None, ge=1, description="nodes (mpi)")
    ntasks: int | None = Field(None, ge=2, description="MPI ranks: 1 master + workers (mpi)")
    time: str | None = Field(None, description="walltime HH:MM:SS or D-HH:MM:SS")
    partition: str | None = None
    launcher: Literal["srun", "mpirun"] | None = None
    venv: Path | None = Field(None, description="virtualenv to activate in the job")
    modules: str | None = Field(None, description="space-separated modules to load")
    shards: int | None = Field(None, ge=1, description="array tasks = shards (array)")
    cpus_per_task: int | None = Field(None, ge=1, description="local workers per shard (array)")
    requeue: bool = Field(False, description="requeue after the walltime signal (mpi, array)")

    @field_validator("time")
    @classmethod
    def _walltime(cls, v: str | None) -> str | None:
        if v is not None:
            walltime_seconds(v)
        return v

    @field_validator("partition")
    @classmethod
    def _partition(cls, v: str | None) -> str | None:
        if v is not None and not _PARTITION.fullmatch(v):
            raise ValueError("must be a partition name (letters, digits, _ . -; comma-separated)")
        return v

    @field_validator("modules")
    @classmethod
    def _modules(cls, v: str | None) -> str | None:
        if v is not None and not _MODULES.fullmatch(v.strip()):
            raise ValueError("must be module names separated by spaces, e.g. 'gcc openmpi/4.1'")
        return None if v is None else v.strip()

    @field_validator("job")
    @classmethod
    def _job_exists(cls, v: Path) -> Path:
        if not v.is_file():
            raise ValueError("no such file")
        return v.resolve()

    @field_validator("venv")
    @classmethod
    def _venv(cls, v: Path | None) -> Path | None:
        if v is not None and not (v / "bin" / "activate").is_file():
            raise ValueError("not a virtualenv: it has no bin/activate")
        return None if v is None else v.resolve()


def _set_line(text: str, pattern: str, line: str) -> str:
    """Replace the one template line matching ``pattern`` (anchored) by ``line``."""
    new, n = re.subn(rf"(?m)^{pattern}.*$", lambda _: line, text)
    if n != 1:  # a template and this module disagree: a bug, not bad input
        raise RuntimeError(f"template has {n} lines matching {pattern!r}, expected 1")
    return new


def check_fits_template(script: SlurmScript) -> None:
    """Refuse settings that the chosen template does not use."""
    for name, templates in _TAKEN_BY.items():
        value = getattr(script, name)
        if value not in (None, False) and script.template not in templates:
            raise InputError(
                f"{name} = {value!r}: the {script.template} template does not take it "
                f"(only {' and '.join(templates)})"
            )
    signalled = script.template in ("mpi", "array")
    if signalled and script.time is not None and walltime_seconds(script.time) <= SIGNAL_LEAD_S:
        raise InputError(
            f"time = {script.time!r}: must be longer than {SIGNAL_LEAD_S} s: the {script.template}"
            f" template signals the run {SIGNAL_LEAD_S} s before the end (--signal=B:TERM@"
            f"{SIGNAL_LEAD_S})"
        )
    if script.template == "mpi" and not script.out.resolve().parent.is_dir():
        raise InputError(f"out = '{script.out}': directory {script.out.parent} does not exist")


def render(script: SlurmScript) -> str:
    """The template with ``script``'s values filled in, ready for ``sbatch``."""
    from .jobs import load_job

    check_fits_template(script)
    load_job(script.job)  # refuse a bad job now rather than in the queue
    text = template_path(script.template).read_text()
    q = shlex.quote
    out = script.out.resolve()
    out_var = "OUT" if script.template == "mpi" else "OUTDIR"
    text = _set_line(text, r"JOB=\$\{1:\?", f"JOB=${{1:-{q(str(script.job))}}}")
    text = _set_line(text, rf"{out_var}=\$\{{2:\?", f"{out_var}=${{2:-{q(str(out))}}}")
    sbatch = {
        "nodes": script.nodes,
        "ntasks": script.ntasks,
        "time": script.time,
        "partition": script.partition,
        "array": None if script.shards is None else f"0-{script.shards - 1}",
        "cpus-per-task": script.cpus_per_task,
    }
    for option, value in sbatch.items():
        if value is not None:
            text = _set_line(text, rf"##?SBATCH --{option}=", f"#SBATCH --{option}={value}")
    settings = {
        "KNITSWEEP_LAUNCHER": script.launcher,
        "KNITSWEEP_VENV": None if script.venv is None else q(str(script.venv)),
        "KNITSWEEP_MODULES": None if script.modules is None else q(script.modules),
        "KNITSWEEP_REQUEUE": "1" if script.requeue else None,
    }
    for name, value in settings.items():
        if value is not None:
            text = _set_line(text, f"{name}=", f"{name}={value}")
    shebang, rest = text.split("\n", 1)
    note = (
        f"# Rendered by `knitsweep slurm render` (knitsweep {__version__}) from "
        f"{TEMPLATE_FILES[script.template]}:\n# arguments default to the job and output "
        "below; settings given to render are fixed.\n"
    )
    return f"{shebang}\n{note}{rest}"


def write_script(path: str | Path, text: str) -> Path:
    """Write a rendered script, executable (``sbatch`` does not need it to be)."""
    from ..util.safe_files import replace_file

    path = replace_file(Path(path), text.encode())  # never through a symbolic link
    path.chmod(0o755)
    return path
