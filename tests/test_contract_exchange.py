"""The contract's CSV files (issue 38): exchange.csv's one tail reader, and the monitor's
evaluations.csv and forecast.csv tables.  Real files in tmp_path, written as the writers do."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from fourbar_common.contract import evaluations as evaluations_csv
from fourbar_common.contract import forecast as forecast_csv
from fourbar_common.contract.exchange import (ExchangeFormatError, ExchangeTail, LineTail, format_header, format_row,
                                              read_exchange)
from fourbar_common.contract.problems import ContractError


def append(path, text: str) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(text)


# -- exchange.csv -----------------------------------------------------------------------------------------
def test_a_growing_file_is_read_in_complete_lines_each_once(tmp_path):
    path = tmp_path / "exchange.csv"
    tail = ExchangeTail(path, ["x2"])
    first = tail.poll()
    assert first.missing and len(first) == 0                    # not there yet
    append(path, format_header(["time", "x2", "y2"]))
    append(path, format_row([0.0, 0.1, -1.0]) + format_row([0.01, 1 / 3, -2.0]) + "0.02,0.7")   # torn last line
    batch = tail.poll()
    assert list(batch.time) == [0.0, 0.01] and batch.values["x2"].tolist() == [0.1, 1 / 3]   # exactly: repr round-trips
    assert set(batch.values) == {"x2"} and tail.pending_bytes == len("0.02,0.7")
    assert len(tail.poll()) == 0                                # nothing new
    append(path, "5,0.5\n")
    again = tail.poll()
    assert again.time.tolist() == [0.02] and again.values["x2"].tolist() == [0.75]     # the whole completed line
    assert tail.stats.rows == 3 and tail.stats.skipped == 0


def test_bad_rows_are_skipped_and_named(tmp_path):
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2,y2\n0.0,1.0,x\n0.01,nan,2\n0.01,3.0,3\n0.02,4.0\n0.03,5.0,5\n")
    tail = ExchangeTail(path, ["x2"])
    batch = tail.poll()
    # y2 is not asked for: its 'x' does not matter; nan in x2 and the short row are skipped
    assert batch.time.tolist() == [0.0, 0.01, 0.03]
    assert [i.kind for i in batch.issues] == ["non_finite", "malformed"]
    assert batch.issues[0].message == "exchange.csv line 3: column x2: value 'nan' is not finite; row skipped"
    loose = ExchangeTail(path, (), others=True).poll()     # only time decides; other fields NaN when not numbers
    assert loose.time.tolist() == [0.0, 0.01, 0.03] and math.isnan(loose.values["y2"][0])


def test_a_truncated_or_replaced_file_is_read_again_from_its_top(tmp_path):
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2\n" + "".join(format_row([k * 0.01, float(k)]) for k in range(100)))
    tail = ExchangeTail(path)
    assert len(tail.read_to_end()) == 100
    # truncated and rewritten in place to more than was read: the same inode, only the bytes before the offset tell
    with open(path, "r+") as fh:
        fh.truncate(0)
        fh.write("time,x2\n" + "".join(format_row([k * 0.01, -float(k)]) for k in range(200)))
    batch = tail.read_to_end()
    assert batch.restarted and len(batch) == 200 and batch.values["x2"][1] == -1.0 and tail.stats.restarts == 1
    # replaced by another file (a new inode), shorter
    new = tmp_path / "new.csv"
    new.write_text("time,x2\n0.0,7.0\n")
    os.replace(new, path)
    batch = tail.poll()
    assert batch.restarted and batch.values["x2"].tolist() == [7.0] and tail.stats.restarts == 2


def test_memory_is_bounded_by_the_chunk_and_an_overlong_line_is_dropped(tmp_path):
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2\n0.0,1.0\n" + "9" * 5000 + "\n0.01,2.0\n")
    tail = ExchangeTail(path, max_chunk_bytes=1024)
    batch = tail.read_to_end()
    assert batch.time.tolist() == [0.0, 0.01] and tail.stats.malformed == 1
    assert "line longer than 1024 bytes" in tail.issues[0].message


@pytest.mark.parametrize("text, expected", [
    ("x2,y2\n0.0,1.0\n", "header has no column 'time'; columns are x2, y2 (expected a header like "
                         "'time,<output>,...')"),
    ("time,y2\n0.0,1.0\n", "header has no column 'x2'; columns are time, y2; choose the column(s) to read among them"),
    ("time,x2,x2\n", "header names column(s) 'x2' more than once"),
    ("\n0.0,1.0\n", "line 1 (header) is empty"),
])
def test_a_bad_header_names_the_problem(tmp_path, text, expected):
    path = tmp_path / "exchange.csv"
    path.write_text(text)
    with pytest.raises(ExchangeFormatError) as caught:
        ExchangeTail(path, ["x2"]).poll()
    assert str(caught.value).startswith(f"{path}: ") and expected in str(caught.value)
    assert caught.value.problems and expected in caught.value.problems[0].message


def test_a_finished_file_is_read_whole_or_refused(tmp_path):
    path = tmp_path / "exchange.csv"
    with pytest.raises(FileNotFoundError):
        read_exchange(path)
    path.write_text("time,x2\n")
    with pytest.raises(ExchangeFormatError, match="has a header but no data rows"):
        read_exchange(path)
    path.write_text("time,x2\n0.0,1.0\n0.01,1.5\n0.0")
    data = read_exchange(path)
    assert data.time.tolist() == [0.0, 0.01] and "incomplete last line (3 bytes without newline)" in data.note
    with pytest.raises(ExchangeFormatError) as caught:
        format_header(["x2", "time", "x2"])
    assert {p.field for p in caught.value.problems} == {"header"} and len(caught.value.problems) == 2


def test_a_fifo_is_refused_or_skipped_never_opened(tmp_path):
    path = tmp_path / "exchange.csv"
    os.mkfifo(path)         # opened for reading in blocking mode, it would hang (no writer)
    with pytest.raises(ExchangeFormatError, match="is a FIFO .named pipe., not a regular file"):
        ExchangeTail(path).poll()
    assert LineTail(path, refuse_other_files=False).read().missing


# -- the monitor's tables ---------------------------------------------------------------------------------
def test_evaluations_round_trip(tmp_path):
    rows = [evaluations_csv.Evaluation(0.1, 1 / 3, 2.5, "monitoring"),
            evaluations_csv.Evaluation(0.2, math.inf, 2.5, "alarm")]
    path = tmp_path / "evaluations.csv"
    evaluations_csv.write_evaluations(path, rows)
    assert path.read_text().startswith("time,statistic,threshold,state\n")
    table = evaluations_csv.read_evaluations(path)
    assert table.rows() == rows                                        # exactly: floats as repr
    tail = evaluations_csv.EvaluationsTail(path)
    got, restarted = tail.poll()
    assert got.rows() == rows and not restarted and len(tail.poll()[0]) == 0


def test_forecast_round_trip(tmp_path):
    t = np.array([0.0, 0.01])
    x = np.array([[1.0, 2.0], [1 / 3, 4.0]])
    f = np.array([[np.nan, np.nan], [0.3, 4.5]])                      # a training sample has no forecast
    path = tmp_path / "forecast.csv"
    path.write_text(forecast_csv.HEADER + forecast_csv.format_rows(("x2", "x4"), t, x, f))
    table = forecast_csv.read_forecast(path)
    assert table.signal == ("x2", "x4", "x2", "x4") and table.value.tolist() == [1.0, 2.0, 1 / 3, 4.0]
    assert np.isnan(table.forecast[:2]).all() and table.forecast[2:].tolist() == [0.3, 4.5]
    copy = tmp_path / "copy.csv"
    forecast_csv.write_forecast(copy, table)
    assert copy.read_text() == path.read_text()


@pytest.mark.parametrize("module, reader, columns", [
    (evaluations_csv, evaluations_csv.read_evaluations, "time,statistic,threshold,state"),
    (forecast_csv, forecast_csv.read_forecast, "time,signal,value,forecast"),
])
def test_a_table_with_a_bad_header_or_rows_lists_its_problems(tmp_path, module, reader, columns):
    path = tmp_path / "table.csv"
    path.write_text("time,something,else\n")
    with pytest.raises(ContractError) as caught:
        reader(path)
    assert [p.field for p in caught.value.problems] == ["header"]
    assert f"expected {columns!r}" in caught.value.problems[0].message
    path.write_text(module.HEADER + "x,1.0,2.0,a\n0.1,1.0\n")
    with pytest.raises(ContractError) as caught:
        reader(path)
    assert [p.field for p in caught.value.problems] == ["line 2", "line 3"]      # every problem, in line order
    assert any("time 'x' is not a finite number" in p.message for p in caught.value.problems)


def test_a_bad_header_is_said_again_until_the_file_is_replaced(tmp_path):
    """A reader that goes on polling (the view) gets the same error, not the next line taken for a header."""
    path = tmp_path / "exchange.csv"
    path.write_text("x2\n1.0\n")
    tail = ExchangeTail(path)
    with pytest.raises(ExchangeFormatError) as first:
        tail.poll()
    append(path, "2.0\n")
    with pytest.raises(ExchangeFormatError) as again:
        tail.poll()
    assert str(again.value) == str(first.value)
    new = tmp_path / "new.csv"
    new.write_text("time,x2\n0.0,1.0\n")
    os.replace(new, path)
    assert tail.poll().values["x2"].tolist() == [1.0]
    table = evaluations_csv.EvaluationsTail(tmp_path / "evaluations.csv")
    (tmp_path / "evaluations.csv").write_text("time,mae\n")
    for _ in range(2):
        with pytest.raises(ContractError, match="header: expected 'time,statistic,threshold,state'"):
            table.poll()
