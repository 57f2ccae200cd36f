"""Progress reporting: one small abstraction for every long host-side loop.

In the habit of diffrax's progress meters: a meter is a small immutable object that turns
``start`` / ``update`` / ``close`` calls into output; the loop keeps the state.

    meter = progress_meter(progress)              # False/None, True, a meter or a callback
    task = meter.start(total, "reading x.sta")
    for done in ...:
        meter.update(task, done)                  # done: units finished so far, absolute
    meter.close(task)

`callback` wraps the three calls as a ``(done, total)`` function, for code that reports
through a callback (the Windcube readers' ``progress=``).

Meters:

- `NoProgress`: silent;
- `TextProgress`: one line on stderr redrawn in place, ``label:  42 % (420/1000)``, ended by
  a newline when the loop is done (`lidarjax correct`'s lines);
- `LineProgress`: one line on stderr per step, ``label: run 2/9 beta 40: ...`` (slow steps
  with something to say about each: `lidarjax table`'s CFD runs);
- `TqdmProgress`: a tqdm bar (optional extra ``progress``);
- `CallbackProgress`: calls a user's ``fn(done, total)``.

Each ``progress=`` argument of lidarjax takes ``False``/``None`` (silent), ``True`` (that
function's usual meter), a meter, or a ``(done, total)`` callable; `progress_meter`
normalises it. Meters run on the host, never inside ``jax.jit``.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from typing import Any, TextIO

from ._util import import_optional

__all__ = ["AbstractProgress", "NoProgress", "TextProgress", "LineProgress", "TqdmProgress",
           "CallbackProgress", "ProgressCallback", "ProgressTask", "progress_meter"]


@dataclasses.dataclass
class ProgressTask:
    """The state of one loop being reported (`AbstractProgress.start`).

    `label`: what is being done; `total`: units to do; `unit`: what a unit is (``"run"``,
    ``"B"``, or ``""``); `done`: units finished at the last update; `handle`: the meter's own
    (a tqdm bar, the last percentage drawn ...).
    """

    label: str
    total: int
    unit: str = ""
    done: int = 0
    handle: Any = None


class AbstractProgress:
    """A progress meter: subclasses override `start`, `update` and `close`.

    Meters hold no state of a loop (that is the `ProgressTask`), so one meter may report
    several loops, one after the other or nested.
    """

    def start(self, total: int, label: str = "", *, unit: str = "") -> ProgressTask:
        """Begin a loop of `total` units; returns its state."""
        return ProgressTask(label=label, total=int(total), unit=unit)

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        """`done` units (absolute, not an increment) are finished; `note` says something
        about the step just finished (meters that draw one line per step show it)."""
        task.done = int(done)

    def close(self, task: ProgressTask) -> None:
        """The loop is over (finished or not)."""

    def callback(self, label: str = "", *, unit: str = "") -> ProgressCallback:
        """A ``(done, total)`` function reporting one loop through this meter (started at the
        first call, closed when `done` reaches `total`)."""
        return ProgressCallback(self, label, unit)


class ProgressCallback:
    """``(done, total)`` reporting through a meter (`AbstractProgress.callback`).

    The loop starts at the first call and closes when `done` reaches `total`; a repeated
    final call is ignored and a later one with `done` below `total` starts a new loop.
    `close` ends an unfinished loop early (for a ``finally``).
    """

    def __init__(self, meter: AbstractProgress, label: str, unit: str = "") -> None:
        self.meter, self.label, self.unit = meter, label, unit
        self._task: ProgressTask | None = None
        self._finished = False

    def __call__(self, done: int, total: int) -> None:
        if self._finished:
            if done >= total:
                return
            self._finished = False
        if self._task is None:
            self._task = self.meter.start(total, self.label, unit=self.unit)
        self._task.total = int(total)
        self.meter.update(self._task, done)
        if done >= total:
            self.close()
            self._finished = True

    def close(self) -> None:
        if self._task is not None:
            self.meter.close(self._task)
            self._task = None


class NoProgress(AbstractProgress):
    """Reports nothing."""

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        pass


class TextProgress(AbstractProgress):
    """One line on `file` (default stderr), redrawn in place whenever the whole percentage
    changes: ``label:  42 % (420/1000)``; a newline when `done` reaches `total`. Notes are
    not shown."""

    def __init__(self, file: TextIO | None = None) -> None:
        self.file = file

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        task.done = int(done)
        total = task.total
        pct = 100 if total == 0 else int(100 * done / total)
        if pct != task.handle:
            task.handle = pct
            end = "\n" if done >= total else ""
            print(f"\r{task.label}: {pct:3d} % ({done}/{total})", end=end,
                  file=self.file or sys.stderr, flush=True)

    def close(self, task: ProgressTask) -> None:
        if task.handle is not None and task.done < task.total:  # end an unfinished line
            print(file=self.file or sys.stderr, flush=True)
        task.handle = None


class LineProgress(AbstractProgress):
    """One line on `file` (default stderr) per update: ``label: unit done/total note``
    (``table: run 2/9 beta 40: grid ...``), for slow steps."""

    def __init__(self, file: TextIO | None = None) -> None:
        self.file = file

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        task.done = int(done)
        unit = f"{task.unit} " if task.unit else ""
        tail = f" {note}" if note else ""
        print(f"{task.label}: {unit}{done}/{task.total}{tail}", file=self.file or sys.stderr,
              flush=True)


class TqdmProgress(AbstractProgress):
    """A tqdm bar per loop (``pip install lidarjax[progress]``; without tqdm, constructing
    one raises an `ImportError` naming the extra). `options` go to ``tqdm.tqdm`` (default
    ``leave=False``); a unit ``"B"`` is scaled (kB, MB ...); notes are the bar's postfix."""

    def __init__(self, **options: Any) -> None:
        self._tqdm = import_optional("tqdm", "progress", "TqdmProgress").tqdm
        self.options = {"leave": False, **options}

    def start(self, total: int, label: str = "", *, unit: str = "") -> ProgressTask:
        task = super().start(total, label, unit=unit)
        opts = {"desc": label or None, "unit": unit or "it", "unit_scale": unit == "B",
                **self.options}
        task.handle = self._tqdm(total=task.total, **opts)
        return task

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        task.done = int(done)
        bar = task.handle
        if bar.total != task.total:
            bar.total = task.total
        if note:
            bar.set_postfix_str(note, refresh=False)
        bar.update(task.done - bar.n)

    def close(self, task: ProgressTask) -> None:
        task.handle.close()


class CallbackProgress(AbstractProgress):
    """Calls `fn(done, total)` at each update (a plain callback as a meter)."""

    def __init__(self, fn: Callable[[int, int], Any]) -> None:
        self.fn = fn

    def update(self, task: ProgressTask, done: int, note: str = "") -> None:
        task.done = int(done)
        self.fn(task.done, task.total)


def progress_meter(progress: Any,
                   default: AbstractProgress | Callable[[], AbstractProgress] = TextProgress,
                   ) -> AbstractProgress:
    """The meter a ``progress=`` argument asks for.

    ``None`` / ``False``: `NoProgress`; ``True``: `default` (a meter, or a class or function
    making one: each function's usual meter); an `AbstractProgress`: itself; any other
    callable: `CallbackProgress` calling it with ``(done, total)``. Raises `TypeError` for
    anything else.
    """
    if progress is None or progress is False:
        return NoProgress()
    if progress is True:
        return default if isinstance(default, AbstractProgress) else default()
    if isinstance(progress, AbstractProgress):
        return progress
    if callable(progress):
        return CallbackProgress(progress)
    raise TypeError(f"progress must be a bool, a lidarjax.progress meter (TextProgress(), "
                    f"TqdmProgress() ...) or a callable (done, total); got {progress!r}")
