"""Commands on jobs and results files: run, status, merge, slurm render."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from ..stitches import DEFAULT_STITCH, check_stitch_name
from .common import (
    HELP,
    STITCH_HELP,
    JsonOpt,
    app,
    flag,
    option,
    user_errors,
)


@app.command()
def run(
    job: Annotated[Path, typer.Argument(help="job file (TOML), e.g. jobs/demo.toml")],
    out: Annotated[Path | None, option("--out", help="results file",
                                       default="<job name>.h5")] = None,
    workers: Annotated[int, typer.Option("--workers", help="local worker processes (no MPI), one task each")] = 1,
    executor: Annotated[
        str, typer.Option("--executor", help="where tasks run: auto (MPI under mpirun), serial, "
                          "processes or mpi")
    ] = "auto",
    shard: Annotated[str | None, typer.Option("--shard", help="run shard i/N of the grid "
                     "(e.g. 0/4), for knitsweep merge")] = None,
    retry_failed: Annotated[bool, flag("--retry-failed", help="rerun failed tasks")] = False,
    quiet: Annotated[bool, flag("--quiet", help="no progress bar")] = False,
    max_tasks: Annotated[int | None, typer.Option("--max-tasks", help="confirm a job of more "
                         "than 20000 tasks (points + sweeps): run up to this many")] = None,
    relabel: Annotated[bool, flag("--relabel", help="write into a results file made "
                       "by a job of another name or description, and give it this job's")] = False,
) -> None:  # fmt: skip
    """Run a job: every grid point's zero-force state and its x/y strain sweeps, into
    one HDF5 file. Under mpirun -n N, rank 0 schedules and N-1 ranks work.

    Exit codes: 0 every task done (or not knittable); 2 bad input, nothing computed;
    3 interrupted (run it again to resume); 4 finished, but some tasks failed."""
    from .. import service
    from ..errors import InputError
    from ..service.run_plan import EXIT_TASKS_FAILED

    with user_errors():
        if executor not in ("auto", "serial", "processes", "mpi"):
            raise InputError(f"executor = {executor!r}: must be auto, serial, processes or mpi")
        summary = service.run(job, out, executor=executor, workers=workers, shard=shard,
                              retry_failed=retry_failed, show_progress=not quiet,
                              max_tasks=max_tasks, relabel=relabel)  # fmt: skip
    if summary is None:  # an MPI worker rank
        return
    if summary.storage_error:  # the one line is printed; the run stopped as interrupted
        raise typer.Exit(summary.exit_code)
    c = summary.counts
    redone = (f"; {summary.redone} sweeps computed again from a lower zero-force state that "
              "another sweep of their point found" if summary.redone else "")  # fmt: skip
    typer.echo(f"{summary.out}: {c['done']} done, {c['failed']} failed, {c['not_knittable']} not "
               f"knittable of {summary.total} tasks ({summary.skipped} already finished{redone}) "
               f"in {summary.seconds:.1f} s{time_split(summary.seconds, summary.compile_seconds)}",
               err=True)  # fmt: skip
    for line in summary.failures[:10]:
        typer.echo(f"  failed: {line}", err=True)
    if summary.exit_code == EXIT_TASKS_FAILED:
        typer.echo(f"error: {c['failed']} of {summary.total} tasks failed (exit code "
                   f"{EXIT_TASKS_FAILED}): see knitsweep status {summary.out}; rerun with "
                   "--retry-failed to compute them again", err=True)  # fmt: skip
    raise typer.Exit(summary.exit_code)


def time_split(seconds: float, compile_seconds: float) -> str:
    """' (12.0 s compiling the kernels, cached from now on; 3.1 s computing)' for a run
    that compiled them first, else ''."""
    if not compile_seconds:
        return ""
    return (f" ({compile_seconds:.1f} s compiling the kernels, cached from now on; "
            f"{max(seconds - compile_seconds, 0.0):.1f} s computing)")  # fmt: skip


@app.command()
def status(
    results: Annotated[Path, typer.Argument(help="results file written by knitsweep run")],
    by: Annotated[
        str | None,
        typer.Option("--by", help="count per value of a parameter: L_mm, k_mN_per_mm2, …, "
                     "direction"),
    ] = None,
    tasks: Annotated[bool, flag("--tasks", help="also list every finished task: its id "
                                "(for render --task), parameters, status and seconds")] = False,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Counts of a results file (done, failed, running, pending), elapsed time and ETA
    while a run writes it, wall time once finished; with --tasks every task's id."""
    from .. import service
    from ..errors import InputError
    from ..quantities import PARAMETERS
    from ..service.progress import progress_line

    with user_errors():
        if by is not None and by not in (*PARAMETERS, "direction"):
            raise InputError(f"by = {by!r}: must be one of {', '.join((*PARAMETERS, 'direction'))}")
        s = service.status(results, by=by, tasks=tasks)
    if as_json:
        typer.echo(json.dumps(s))
        return
    state = (
        " (live)"
        if s["live"]
        else " (its writer is gone: rerun the job to resume)"
        if s["stale"]
        else ""
    )
    typer.echo(f"{s['file']}  job {s['job']}  {s['run_status']}{state}")
    typer.echo(progress_line(s))
    if not s["live"]:
        typer.echo(f"started {s['started_at']}, finished {s['finished_at'] or '-'}")
    for name, groups in s["by"].items():
        for value, counts in groups.items():
            listing = "  ".join(f"{k} {v}" for k, v in counts.items())
            typer.echo(f"  {name} = {value}: {listing}")
    for line in s["failures"][:20]:
        typer.echo(f"  failed {line}")
    for line in s["failed_series"]:
        typer.echo(f"  failed series {line}")
    for line in s["journal_problems"]:
        typer.echo(f"  malformed journal entry {line}: its task is recomputed on resume")
    for line in s["check"]:
        typer.echo(f"  {line}")
    if tasks:
        typer.echo(f"tasks (draw one with knitsweep render --results {results} --task ID; "
                   "a unique prefix of the id will do):")  # fmt: skip
        for line in task_lines(s["tasks"]):
            typer.echo(f"  {line}")


def task_lines(rows: list[dict]) -> list[str]:
    """'point    43f8c26538190f30  done  L=11.4 k=0.1  0.57 s' per task of ``status``'s
    ``tasks``: the stitch and the parameters that vary among them, L always."""
    from ..quantities import PARAMETER_NAMES, PARAMETERS, value_text

    names = [p for p in PARAMETERS if p not in ("L_over_r",) and (p == "L_mm" or len(
        {r.get(p) for r in rows}) > 1)]  # fmt: skip
    lines = []
    for r in rows:
        kind = f"{r['kind']} {r['direction']}".strip()
        values = " ".join(f"{PARAMETER_NAMES[p].symbol}={value_text(r[p])}" for p in names
                          if r.get(p) is not None)  # fmt: skip
        seconds = "" if r["seconds"] is None else f"  {r['seconds']:.2f} s"
        lines.append(f"{kind:<7}  {r['task_id']}  {r['status']}  {values}{seconds}")
    return lines


@app.command()
def merge(
    out: Annotated[Path, typer.Argument(help="merged results file to write")],
    inputs: Annotated[list[Path], typer.Argument(help="shard files of one job")],
) -> None:
    """Combine the shard files of one job (knitsweep run --shard i/N) into one file."""
    from .. import service

    with user_errors():
        r = service.merge(out, inputs)
    state = (
        "complete"
        if r["complete"]
        else f"partial: {r['points'] + r['sweeps']} of {r['expected']} tasks"
    )
    typer.echo(f"{r['file']}: {r['points']} points, {r['sweeps']} sweeps ({state})")
    for line in r["problems"]:
        typer.echo(f"  {line}", err=True)


@app.command()
def recover(
    results: Annotated[Path, typer.Argument(help="damaged results file")],
    job: Annotated[Path | None, option("--job", help="the job file, if no copy of the file's "
                   "job spec is intact", default="the file's own spec")] = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Rebuild a damaged results file from its intact tasks, the previous checkpoint's
    copy and the journal; say what was recovered and what must be recomputed."""
    from ..service.recovery import recover as rebuild

    with user_errors():
        r = rebuild(results, job)
    if as_json:
        typer.echo(json.dumps(r))
        return
    if r["intact"]:
        typer.echo(f"{r['file']}: intact ({r['verified']} tasks verified, {r['unverified']} "
                   "without checksums): nothing to recover")  # fmt: skip
        return
    for source, note in r["sources"].items():
        typer.echo(f"  {source}: {note}")
    got = ", ".join(f"{n} from the {k}" for k, n in r["from"].items() if n)
    typer.echo(f"{r['file']}: recovered {r['recovered']} of {r['planned']} tasks"
               f"{' (' + got + ')' if got else ''}; the damaged file is kept as {r['kept']}")  # fmt: skip
    for line in r["damaged_lost"]:
        typer.echo(f"  damaged, not recovered: {line}")
    if r["recompute"]:
        typer.echo(f"{r['recompute']} tasks must be recomputed: run the job again with "
                   f"--out {r['file']} to resume (finished tasks are skipped)")  # fmt: skip
    else:
        typer.echo("every planned task is recovered")


# ---- knitsweep slurm … (batch scripts; knitsweep/service/slurm.py, slurm/README.md)
slurm_app = typer.Typer(
    no_args_is_help=True,
    context_settings=HELP,
    help="SLURM batch scripts for knitsweep runs (slurm/README.md).",
)
app.add_typer(slurm_app, name="slurm")


@slurm_app.command("render")
def slurm_render(
    job: Annotated[Path, typer.Argument(help="job file (TOML)")],
    out: Annotated[Path, typer.Option("--out", help="results file (mpi) or shard directory "
                                      "(array, merge)")],
    template: Annotated[str, typer.Option("--template", help="batch script: mpi, array or "
                        "merge")] = "mpi",
    nodes: Annotated[int | None, typer.Option("--nodes", help="nodes (mpi)")] = None,
    ntasks: Annotated[int | None, typer.Option("--ntasks", help="MPI ranks, >= 2 (mpi)")] = None,
    time: Annotated[str | None, typer.Option("--time", help="walltime HH:MM:SS")] = None,
    partition: Annotated[str | None, typer.Option("--partition", help="SLURM partition")] = None,
    launcher: Annotated[str | None, typer.Option("--launcher", help="srun or mpirun (mpi)")] = None,
    venv: Annotated[Path | None, typer.Option("--venv", help="virtualenv to activate")] = None,
    modules: Annotated[str | None, typer.Option("--modules", help="modules to load, "
                                                "space-separated")] = None,
    shards: Annotated[int | None, typer.Option("--shards", help="array tasks (array)")] = None,
    cpus_per_task: Annotated[int | None, typer.Option("--cpus-per-task", help="local workers "
                                                      "per shard (array)")] = None,
    requeue: Annotated[bool, flag("--requeue", help="requeue after the walltime "
                                          "signal, to resume (mpi, array)")] = False,
    script: Annotated[Path | None, typer.Option("--script", help="write it here, not to stdout")] = None,
) -> None:  # fmt: skip
    """Print (or write) a ready-to-submit batch script: a shipped template with the job,
    output, resources and environment filled in."""
    from ..service.slurm import SlurmScript, render, write_script

    with user_errors():
        text = render(SlurmScript(
            template=template, job=str(job), out=str(out), nodes=nodes, ntasks=ntasks,
            time=time, partition=partition, launcher=launcher,
            venv=None if venv is None else str(venv), modules=modules, shards=shards,
            cpus_per_task=cpus_per_task, requeue=requeue,
        ))  # fmt: skip
    if script is None:
        typer.echo(text, nl=False)
    else:
        typer.echo(f"wrote {write_script(script, text)}: submit it with sbatch", err=True)


@app.command("compile")
def compile_(
    cache_dir: Annotated[Path | None, option("--cache-dir", help="numba cache directory to "
                         "fill (e.g. node-local)", default="$NUMBA_CACHE_DIR or "
                         "~/.cache/knitsweep")] = None,
    jobs: Annotated[int | None, option("--jobs", help="processes compiling side by side",
                    default="as many as idle cores, at most 3")] = None,
    stitch: Annotated[list[str] | None, option("--stitch", help=STITCH_HELP,
                      default=DEFAULT_STITCH)] = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Compile every kernel a `run` uses (and the pair forces `report` computes) into
    numba's on-disk cache (warm a node-local cache before a batch job), and say what was
    compiled and how long it took."""
    import os
    import sys
    import time

    from ..errors import InputError

    with user_errors():
        if jobs is not None and not 1 <= jobs <= 64:
            raise InputError(f"jobs = {jobs}: must be in 1..64")
        if cache_dir is not None:
            if "knitsweep.kernels" in sys.modules:  # its cache directory is fixed at import
                raise InputError(f"cache_dir = {cache_dir}: set before the kernels are imported")
            cache_dir.mkdir(parents=True, exist_ok=True)
            os.environ["NUMBA_CACHE_DIR"] = str(cache_dir.resolve())
        stitches = tuple(check_stitch_name(name) for name in stitch or (DEFAULT_STITCH,))
        from .. import kernels
        from ..compilation import KERNEL_GROUPS, compile_kernels, kernel_entry_points

        needed = kernel_entry_points(stitches)
        was_cached = kernels.cached(needed)
        t0 = time.perf_counter()
        seconds = compile_kernels(stitches=stitches, jobs=jobs, what="all")
        wall = time.perf_counter() - t0
    result = {"cache_dir": kernels.numba.config.CACHE_DIR, "was_cached": was_cached,
              "cached": kernels.cached(needed), "seconds": round(wall, 2),
              "groups": {g: round(s, 2) for g, s in seconds.items()}}  # fmt: skip
    if as_json:
        typer.echo(json.dumps(result))
        return
    verb = "loaded (already cached)" if was_cached else "compiled"
    typer.echo(
        f"{verb} the kernels of {', '.join(stitches)} in {wall:.1f} s into {result['cache_dir']}"
    )
    for group, s in seconds.items():
        typer.echo(f"  {group:9s} {s:7.1f} s  {KERNEL_GROUPS[group]}")
