"""`lidarjax.progress`: each meter's output, the normalisation of ``progress=`` arguments, the
``(done, total)`` callback form, tqdm present (a stand-in module) and absent, and the call
sites (Windcube readers, Fluent reader, records correction)."""

from __future__ import annotations

import io
import sys
import types

import pytest

from lidarjax.progress import (
    AbstractProgress,
    CallbackProgress,
    LineProgress,
    NoProgress,
    ProgressCallback,
    TextProgress,
    TqdmProgress,
    progress_meter,
)


def test_text_progress_format_is_the_records_bar(capsys):
    show = TextProgress().callback("correcting x.sta")
    show(0, 4)
    show(1, 4)
    show(1, 4)  # same percentage: not redrawn
    show(3, 4)
    show(4, 4)
    show(4, 4)  # a repeated final call: ignored
    assert capsys.readouterr().err == ("\rcorrecting x.sta:   0 % (0/4)"
                                       "\rcorrecting x.sta:  25 % (1/4)"
                                       "\rcorrecting x.sta:  75 % (3/4)"
                                       "\rcorrecting x.sta: 100 % (4/4)\n")
    TextProgress().callback("writing CSV")(0, 0)  # nothing to do: done at once
    assert capsys.readouterr().err == "\rwriting CSV: 100 % (0/0)\n"


def test_text_progress_close_ends_an_unfinished_line_and_writes_to_a_file():
    out = io.StringIO()
    meter = TextProgress(file=out)
    task = meter.start(10, "job")
    meter.update(task, 3, "a note is not shown")
    meter.close(task)
    assert out.getvalue() == "\rjob:  30 % (3/10)\n"
    task = meter.start(2, "done")
    meter.update(task, 2)
    meter.close(task)  # finished: no second newline
    assert out.getvalue().endswith("\rdone: 100 % (2/2)\n")


def test_line_progress_one_line_per_step(capsys):
    meter = LineProgress()
    task = meter.start(3, "table", unit="run")
    meter.update(task, 1, "beta 0: grid (4, 4, 4) -> crop (2, 2, 2) in 0.1 s")
    meter.update(task, 2)
    meter.close(task)
    task = meter.start(5, "copy")
    meter.update(task, 5)
    assert capsys.readouterr().err.splitlines() == [
        "table: run 1/3 beta 0: grid (4, 4, 4) -> crop (2, 2, 2) in 0.1 s",
        "table: run 2/3",
        "copy: 5/5",
    ]


def test_no_progress_is_silent(capsys):
    meter = NoProgress()
    task = meter.start(3, "x")
    meter.update(task, 3, "note")
    meter.close(task)
    meter.callback("y")(1, 1)
    assert capsys.readouterr() == ("", "")


def test_callback_progress_and_the_callback_form():
    calls = []
    meter = CallbackProgress(lambda d, t: calls.append((d, t)))
    show = meter.callback("label")
    assert isinstance(show, ProgressCallback)
    for d in (0, 5, 10, 10):
        show(d, 10)
    show(3, 7)  # a new pass after the end: starts again
    assert calls == [(0, 10), (5, 10), (10, 10), (3, 7)]


def test_callback_form_starts_and_closes_one_task():
    log = []

    class Recorder(AbstractProgress):
        def start(self, total, label="", *, unit=""):
            log.append(("start", total, label, unit))
            return super().start(total, label, unit=unit)

        def update(self, task, done, note=""):
            log.append(("update", done, task.total))

        def close(self, task):
            log.append(("close", task.label))

    show = Recorder().callback("rows", unit="row")
    show(1, 3)
    show(3, 3)
    assert log == [("start", 3, "rows", "row"), ("update", 1, 3), ("update", 3, 3),
                   ("close", "rows")]
    log.clear()
    show = Recorder().callback("cut")
    show(1, 4)
    show.close()  # an early end (a finally): closed once, a second close is a no-op
    show.close()
    assert log == [("start", 4, "cut", ""), ("update", 1, 4), ("close", "cut")]


def test_progress_meter_normalises_the_argument():
    assert type(progress_meter(None)) is NoProgress
    assert type(progress_meter(False)) is NoProgress
    assert type(progress_meter(True)) is TextProgress  # the default default
    assert type(progress_meter(True, LineProgress)) is LineProgress  # a class
    mine = LineProgress()
    assert progress_meter(True, mine) is mine  # an instance
    assert type(progress_meter(True, lambda: NoProgress())) is NoProgress  # a factory
    assert progress_meter(mine) is mine
    fn = print
    meter = progress_meter(fn)
    assert isinstance(meter, CallbackProgress) and meter.fn is fn
    for bad in ("yes", 1.5, object()):
        with pytest.raises(TypeError, match="progress must be a bool"):
            progress_meter(bad)


def test_tqdm_missing_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm raises ImportError
    with pytest.raises(ImportError, match=r"pip install lidarjax\[progress\]"):
        TqdmProgress()


class FakeBar:
    def __init__(self, total, **kwargs):
        self.total, self.kwargs, self.n = total, kwargs, 0
        self.postfix, self.closed, self.steps = None, False, []

    def update(self, k):
        self.steps.append(k)
        self.n += k

    def set_postfix_str(self, text, refresh=True):
        self.postfix = text

    def close(self):
        self.closed = True


@pytest.fixture
def fake_tqdm(monkeypatch):
    bars = []
    mod = types.ModuleType("tqdm")

    def tqdm(**kwargs):
        bars.append(FakeBar(**kwargs))
        return bars[-1]

    mod.tqdm = tqdm
    monkeypatch.setitem(sys.modules, "tqdm", mod)
    return bars


def test_tqdm_progress_drives_a_bar(fake_tqdm):
    meter = TqdmProgress(mininterval=0.5)
    task = meter.start(1000, "big.csv", unit="B")
    meter.update(task, 400)
    meter.update(task, 1000, "done")
    meter.close(task)
    (bar,) = fake_tqdm
    assert bar.total == 1000 and bar.steps == [400, 600] and bar.closed
    assert bar.kwargs == {"desc": "big.csv", "unit": "B", "unit_scale": True, "leave": False,
                          "mininterval": 0.5}
    assert bar.postfix == "done"
    show = TqdmProgress(leave=True).callback("rows")
    show(5, 10)
    show(10, 20)  # the total grew
    show(20, 20)
    bar = fake_tqdm[-1]
    assert bar.total == 20 and bar.n == 20 and bar.closed
    assert bar.kwargs["leave"] is True and bar.kwargs["unit"] == "it"


# -- the call sites ---------------------------------------------------------------------------


def test_windcube_readers_take_a_bool_a_meter_or_a_callback(tmp_path, capsys):
    from lidarjax.io import read_rtd, read_sta
    from tests.io import record_samples as S

    sta = tmp_path / "a.sta"
    sta.write_bytes(S.sta_v2_text(n=6).encode("cp1252"))
    calls = []
    read_sta(sta, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(6, 6)]
    read_sta(sta, progress=True)
    assert capsys.readouterr().err == "\rreading a.sta: 100 % (6/6)\n"
    out = io.StringIO()
    rtd = tmp_path / "b.rtd"
    rtd.write_bytes(S.rtd_v2_text().encode("cp1252"))
    read_rtd(rtd, progress=LineProgress(file=out))
    assert out.getvalue() == "reading b.rtd: 15/15\n"
    read_sta(sta, progress=False)
    read_rtd(rtd)
    assert capsys.readouterr() == ("", "")


def test_fluent_reader_reports_bytes(tmp_path, fake_tqdm):
    from lidarjax.io import read_fluent_points

    path = tmp_path / "export.csv"
    rows = [f"{i},{i % 3},{i % 5},1,0,0" for i in range(20)]
    path.write_text("x-coordinate,y-coordinate,z-coordinate,x-velocity,y-velocity,"
                    "z-velocity\n" + "\n".join(rows) + "\n")
    size = path.stat().st_size
    calls = []
    read_fluent_points(path, progress=lambda d, t: calls.append((d, t)), chunk_rows=8)
    assert calls[-1] == (size, size) and len(calls) == 3  # two full chunks, then the end
    read_fluent_points(path, progress=True)  # True: tqdm when installed (here the stand-in)
    (bar,) = fake_tqdm
    assert bar.total == size and bar.n == size and bar.closed
    assert bar.kwargs["unit"] == "B" and bar.kwargs["desc"] == "export.csv"


def test_fluent_reader_without_tqdm_is_silent(tmp_path, monkeypatch, capsys):
    from lidarjax.io import read_fluent_points

    monkeypatch.setitem(sys.modules, "tqdm", None)
    path = tmp_path / "export.csv"
    path.write_text("x-coordinate,y-coordinate,z-coordinate,x-velocity,y-velocity,"
                    "z-velocity\n0,0,0,1,0,0\n1,0,0,1,0,0\n")
    read_fluent_points(path, progress=True)
    assert capsys.readouterr() == ("", "")


def test_records_progress_callback_is_the_text_bar(capsys):
    from lidarjax.workflows import records

    show = records._progress("writing CSV", True)
    show(0, 2)
    show(2, 2)
    assert capsys.readouterr().err == "\rwriting CSV:   0 % (0/2)\rwriting CSV: 100 % (2/2)\n"
    records._progress("writing CSV", False)(1, 2)
    out = io.StringIO()
    records._progress("writing CSV", LineProgress(file=out))(1, 2)
    assert out.getvalue() == "writing CSV: 1/2\n"
    assert capsys.readouterr() == ("", "")
