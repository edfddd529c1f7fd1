from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from sim.trajectories import COLUMNS, Trajectory, read_trajectories, write_trajectories

HEADER = ",".join(COLUMNS) + "\n"


def rows_read_by_csv(path: Path) -> dict[str, list[list[float]]]:
    """Each vehicle's rows as the csv module and float() read them, in the file's order."""
    rows: dict[str, list[list[float]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            rows.setdefault(row["vehicle_id"], []).append([float(row[c]) for c in COLUMNS[1:]])
    return rows


def test_values_are_those_float_parses_bit_for_bit(tmp_path: Path) -> None:
    # Digits at the limits of a double's precision, signed zeros and exponents: the reader must
    # round each as float() does, or replayed traffic (and every record) would change.
    rng = np.random.default_rng(3)
    texts = [repr(v) for v in rng.normal(0.0, 1e3, 400).tolist()] + [
        "-0.0",
        "0.1",
        "1e-310",
        "2.5e+2",
    ]
    path = tmp_path / "trajectories.csv"
    lines = [f"v{k % 7},{k * 0.1:.1f},{t},{t},{t},{t},4.5,{t}" for k, t in enumerate(texts)]
    path.write_text(HEADER + "\n".join(lines) + "\n")
    read = read_trajectories(path)
    for vid, rows in rows_read_by_csv(path).items():
        expected = np.array(rows)
        got = read[vid]
        for column, name in enumerate(("time", "x", "y", "heading", "speed")):
            assert getattr(got, name).tobytes() == expected[:, column].tobytes()
        assert (got.length, got.width) == tuple(expected[-1, 5:])


def test_vehicles_keep_their_first_appearance_order_and_frames_sort_stably_by_time(
    tmp_path: Path,
) -> None:
    path = tmp_path / "trajectories.csv"
    path.write_text(
        HEADER
        + "b,0.2,1,0,0,1,4.0,1.8\r\n"
        + '"a,1",0.1,5,0,0,1,4.0,1.8\r\n'
        + "b,0.1,2,0,0,1,4.0,1.8\r\n"
        + "\r\n"  # a blank line is skipped, as the csv module skips it
        + "b,0.1,3,0,0,1,4.2,1.9\r\n"
    )
    read = read_trajectories(path)
    assert list(read) == ["b", "a,1"]  # a quoted id may hold the delimiter
    assert read["b"].time.tolist() == [0.1, 0.1, 0.2]
    assert read["b"].x.tolist() == [2.0, 3.0, 1.0]  # equal times keep the file's order
    assert (read["b"].length, read["b"].width) == (4.2, 1.9)  # the size of the last row


def test_what_write_trajectories_writes_reads_back(tmp_path: Path) -> None:
    path = tmp_path / "trajectories.csv"
    write_trajectories(path, {})
    assert read_trajectories(path) == {}
    frames = np.arange(4)
    written = Trajectory("car.7", 0.3 + 0.1 * frames, 1.25 * frames, -2.0 + frames, 0.125 * frames,
                         np.full(4, 9.5), 4.6, 1.85)  # fmt: skip
    write_trajectories(path, [written])
    (read,) = read_trajectories(path).values()
    assert read.vehicle_id == "car.7" and (read.length, read.width) == (4.6, 1.85)
    for name in ("x", "y", "heading", "speed"):
        np.testing.assert_array_equal(getattr(read, name), getattr(written, name))
    np.testing.assert_allclose(read.time, written.time)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("a,0.0,1,2,3,fast,4.5,1.8\n", "could not convert string 'fast'"),
        ("a,0.0,1,2,3\n", "invalid column index"),
    ],
)
def test_a_malformed_row_is_an_error_naming_the_file(
    tmp_path: Path, body: str, message: str
) -> None:
    path = tmp_path / "trajectories.csv"
    path.write_text(HEADER + body)
    with pytest.raises(ValueError, match=message) as error:
        read_trajectories(path)
    assert str(path) in str(error.value)


def test_a_file_with_other_columns_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "trajectories.csv"
    path.write_text("id,t,x,y\na,0.0,1,2\n")
    with pytest.raises(ValueError, match="expected columns"):
        read_trajectories(path)
