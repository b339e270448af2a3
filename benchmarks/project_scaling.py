"""Projected efficiency of a study on many MPI ranks, from measured figures (prints them).

Inputs are measurements, not guesses: the task times of a results file (each task's
``seconds`` attribute: zero-force points and sweeps, drawn from separately) and the
master's throughput from ``bench_master.py`` (results journalled and checkpointed per
second under MPI). The model is an event simulation of the run: one master and
``ranks - 1`` workers; a point's sweeps become ready when the point is done; each
worker holds a queue (prefetch), so it never waits on the master while the master
keeps up; the master spends ``1 / rate`` seconds on every result, one after the
other, and a worker whose queue the master has not refilled waits. Efficiency is
the task seconds over (ranks x wall time): the master's rank counts as a core
spent. Start-up (MPI, imports, loading numba's cache: ``--startup``) is added to the
wall time.

Run: ``python benchmarks/project_scaling.py RESULTS.h5 --rate 900 [--tasks 2688 100000]
[--ranks 64 256 1024]``.
"""

from __future__ import annotations

import argparse
import collections
import heapq

import numpy as np


def task_times(path: str) -> tuple[np.ndarray, np.ndarray]:
    """The ``seconds`` of every finished point and sweep of a results file (any schema)."""
    from knitsweep.store.read import iter_entries

    seconds: dict[str, list[float]] = {"points": [], "sweeps": []}
    for entry in iter_entries(path):
        if entry.kind in seconds:
            seconds[entry.kind].append(float(entry.meta["seconds"]))
    return np.array(seconds["points"]), np.array(seconds["sweeps"])


def simulate(points: np.ndarray, sweeps_of: list[np.ndarray], ranks: int, rate: float,
             depth: int = 4) -> tuple[float, float]:  # fmt: skip
    """(wall seconds without start-up, master busy seconds) of one run."""
    cost = 1.0 / rate
    heap: list = [(0.0, 1, w, None) for w in range(ranks - 1)]  # (time, 0 result | 1 free, …)
    points_left = collections.deque(range(len(points)))
    sweeps_ready: collections.deque = collections.deque()  # (ready time, seconds), FIFO
    idle: list[int] = []
    master = end = 0.0
    while heap:
        t, event, w, task = heapq.heappop(heap)
        if event == 0:  # a result reaches the master, which takes results one by one
            master = max(t, master) + cost
            end = max(end, master)
            if task is not None:  # a point: its sweeps are ready once it is journalled
                sweeps_ready.extend((master, float(d)) for d in sweeps_of[task])
            for v in idle:
                heapq.heappush(heap, (master, 1, v, None))
            idle = []
            continue
        if sweeps_ready:  # sweeps first, as the master schedules
            ready, seconds = sweeps_ready.popleft()
            start, point = max(t, ready), None
        elif points_left:
            point = points_left.popleft()
            start, seconds = t, float(points[point])
        else:
            idle.append(w)  # nothing to do until a point's sweeps are released
            continue
        finish = start + seconds
        heapq.heappush(heap, (finish, 0, w, point))
        # the worker's queue holds `depth` tasks: it waits only when the master is
        # further behind than that
        heapq.heappush(heap, (max(finish, master - depth * cost), 1, w, None))
    return end, len(points) * 3 * cost


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="a results file whose task times to draw from")
    ap.add_argument("--rate", type=float, required=True, help="master results/s (MPI)")
    ap.add_argument("--tasks", type=int, nargs="+", default=[2688, 100_000])
    ap.add_argument("--ranks", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--startup", type=float, default=2.0, help="start-up seconds")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    points, sweeps = task_times(args.results)
    rng = np.random.default_rng(args.seed)
    print(f"task times from {args.results}: {len(points)} points (median "
          f"{np.median(points):.3f} s), {len(sweeps)} sweeps (median {np.median(sweeps):.3f} s);"
          f" master {args.rate:,.0f} results/s; start-up {args.startup:.1f} s")  # fmt: skip
    print(f"{'tasks':>8}{'ranks':>7}{'task s':>10}{'wall s':>9}{'efficiency':>12}"
          f"{'master busy':>13}")  # fmt: skip
    for n in args.tasks:
        n_points = n // 3
        p = rng.choice(points, n_points) + rng.uniform(0, 1e-9, n_points)  # distinct
        s = [rng.choice(sweeps, 2) for _ in range(n_points)]
        work = p.sum() + sum(x.sum() for x in s)
        for ranks in args.ranks:
            wall, busy_s = simulate(p, s, ranks, args.rate)
            wall += args.startup
            busy = busy_s / wall
            print(f"{3 * n_points:8d}{ranks:7d}{work:10.0f}{wall:9.1f}"
                  f"{work / (ranks * wall):11.0%}{busy:12.0%}")  # fmt: skip


if __name__ == "__main__":
    main()
