"""The progress of ``nematic run``: a bar on a terminal, progress lines in a batch job's log,
failures as they happen, and the ETA."""

from __future__ import annotations

import math
import statistics
import threading
import time
from typing import TYPE_CHECKING, Any

from rich.markup import escape
from rich.progress import Progress, TaskID

from .app import Console, fmt_time

if TYPE_CHECKING:
    from ..store import Record


class ProgressEvents:
    """Draws the progress bar and prints failures as they happen. Without a terminal (a
    batch job's log) it prints a progress line when a run completes (at most one every
    :data:`LOG_MIN` seconds) and at least every :data:`LOG_EVERY` seconds instead.

    The ETA is the remaining runs times the median run time of the runs completed so far,
    over the number of worker threads: a first run that compiled kernels does not skew it."""

    LOG_EVERY = 30.0
    LOG_MIN = 5.0

    def __init__(
        self,
        console: Console,
        progress: Progress,
        store: Any,
        *,
        clock: Any = time.monotonic,
        compiled: bool = True,
    ):
        self.console, self.progress, self.store = console, progress, store
        #: whether the campaign's model compiles kernels before its runs (the nematic model)
        self.compiled = compiled
        self.clock = clock
        self.task: TaskID | None = None
        self.ok = 0
        self.failed = 0
        self.total = self.skipped = 0
        self.workers = 1
        self.run_times: list[float] = []
        self.t0 = self.last_log = clock()
        #: seconds from these events' creation (the command's start) to the first workers
        #: ready: the driver's start-up, which a re-estimate mid-campaign no longer pays
        self.startup: float | None = None
        self._stop = threading.Event()
        self._heartbeat: threading.Thread | None = None
        self._lock = threading.Lock()

    @property
    def terminal(self) -> bool:
        return bool(self.console.is_terminal)

    def planned(self, plan: Any, expansion: Any) -> None:
        c = expansion.campaign
        skipped = " (skipped; --retry-failed redoes them)" if plan.failed else ""
        self.console.print(
            f"campaign [bold]{escape(c.name)}[/]: {len(expansion)} runs ({c.n_points} points "
            f"x {len(c.seeds)} seeds); {len(plan.done)} done, {len(plan.failed)} failed"
            f"{skipped}, {len(plan.todo)} to run -> {escape(str(self.store.root))}",
            soft_wrap=True,
        )
        if plan.unspooled:
            self.console.print(
                f"moved {plan.unspooled} result(s) that could not be written "
                "before into the results folder"
            )
        if plan.adopted:
            self.console.print(f"recovered {plan.adopted} unindexed run file(s)")
        if getattr(plan, "reused", None):
            from ..catalogue.reuse import reuse_line

            self.console.print(reuse_line(plan.reused), soft_wrap=True, markup=False)
        if plan.redone:
            self.console.print(
                f"[yellow]{len(plan.redone)} run(s) will be redone[/] (their "
                "file is missing, truncated or corrupt):",
                soft_wrap=True,
            )
            for rid, why in plan.redone[:10]:
                self.console.print(f"  {rid}: {why}", soft_wrap=True, markup=False)
            if len(plan.redone) > 10:
                self.console.print(f"  ... and {len(plan.redone) - 10} more")

    def dashboard(self, link: str | None) -> None:
        if link:
            self.console.print(f"dask dashboard: {escape(link)}", soft_wrap=True)
        else:
            self.console.print(
                "dask dashboard: none answers from here (it needs bokeh "
                "where the scheduler runs, and its port reachable)",
                soft_wrap=True,
            )

    def warming(self) -> None:
        if not self.compiled:
            self.console.print("preparing the workers: importing the model ...", soft_wrap=True)
            return
        self.console.print(
            "preparing the workers: compiled kernels (cached on disk; about a "
            "minute once per machine, then seconds) ...",
            soft_wrap=True,
        )

    def warmed(self, infos: list[dict[str, Any]], seconds: float) -> None:
        compiled = sum(int(i.get("compiled", 0)) for i in infos)
        what = (
            f" ({compiled} kernel(s) compiled once, now cached for every worker)"
            if compiled
            else " (loaded from the cache)"
            if self.compiled
            else ""
        )
        self.console.print(f"workers ready in {seconds:.0f} s{what}", soft_wrap=True)
        if self.startup is None:
            self.startup = self.clock() - self.t0

    def started(self, plan: Any, total: int, workers: int) -> None:
        self.ok = self.failed = 0  # per call: a refined campaign runs one call per round
        self.skipped = plan.skipped
        self.total = total
        self.workers = max(1, workers)
        self.t0 = self.last_log = self.clock()
        self.task = self.progress.add_task(
            "runs", total=total, completed=self.skipped, counts=self._counts(), eta="unknown"
        )
        if not self.terminal:
            self._heartbeat = threading.Thread(
                target=self._beat, daemon=True, name="nematic-progress"
            )
            self._heartbeat.start()

    def close(self) -> None:
        self._stop.set()
        if self._heartbeat is not None:
            self._heartbeat.join(timeout=5)

    def _beat(self) -> None:
        while not self._stop.wait(1.0):
            if self.clock() - self.last_log >= self.LOG_EVERY:
                self._log_line()

    def _counts(self) -> str:
        return f"[green]{self.ok} ok[/] [red]{self.failed} failed[/]"

    @property
    def remaining(self) -> int:
        return max(0, self.total - self.skipped - self.ok - self.failed)

    def eta(self) -> float | None:
        """Remaining runs x median run time / workers (None before the first run ends)."""
        if not self.remaining:
            return 0.0
        if not self.run_times:
            return None
        return self.remaining * statistics.median(self.run_times[-200:]) / self.workers

    def progress_line(self) -> str:
        done = self.skipped + self.ok + self.failed
        running = min(self.workers, self.remaining)
        return (
            f"progress: {done}/{self.total} runs ({self.ok} ok, {self.failed} failed, "
            f"{running} running this session), elapsed "
            f"{fmt_time(self.clock() - self.t0)}, ETA {fmt_time(self.eta())}"
        )

    def _log_line(self) -> None:
        with self._lock:
            self.last_log = self.clock()
            self.console.print(self.progress_line(), highlight=False, markup=False, soft_wrap=True)

    def finished_run(self, run: Any, record: Record) -> None:
        from ..run.failures import describe_failure

        if record.get("status") == "ok":
            self.ok += 1
        else:
            self.failed += 1
            self.progress.console.print(
                f"[red]FAILED[/] {escape(describe_failure(run, record))}",
                highlight=False,
                soft_wrap=True,
            )
        wall = record.get("wall_time")
        if isinstance(wall, (int, float)) and math.isfinite(wall):
            self.run_times.append(float(wall))
        if self.task is not None:
            self.progress.update(
                self.task, advance=1, counts=self._counts(), eta=fmt_time(self.eta())
            )
        if not self.terminal and (
            self.clock() - self.last_log >= self.LOG_MIN or not self.remaining
        ):
            self._log_line()
