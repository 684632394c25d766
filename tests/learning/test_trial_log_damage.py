"""A damaged or read-only trial log: refused with the real reason, never modified.

A few bytes scribbled inside a record pass SQLite's quick check (it verifies the
b-trees, not the records' bytes); the log must still refuse such a file when it
is opened, naming the damage, and leave every byte as it was. A valid log the
process may not write opens read-only: reads work, a write says "read-only".
"""

import os
import random
import sqlite3

import numpy as np
import pytest

from handle_drake.learning import TrialLogError
from handle_drake.learning.log import TrialLog


def _write_log(path, trials=30):
    with TrialLog(path) as log:
        log.create_run("r", "random", [[0, 1], [0, 1]], 0, "objective")
        for i in range(trials):
            log.add_pending("r", i, [0.5, 0.25], i, scenario="hand: {kind: shadow}\n")
            log.mark_running("r", i)
            log.mark_done("r", i, 0.1 * i, contacts={"thumb": [1, 2, 3]})
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    return path.read_bytes()


def test_scribbled_records_are_refused_naming_the_damage_and_the_file_is_untouched(tmp_path):
    original = _write_log(tmp_path / "log.sqlite")
    rng = random.Random(15)
    refused = readable = 0
    for k in range(60):
        damaged = bytearray(original)
        start = rng.randrange(4096, len(damaged) - 8)  # past the header page: inside records
        for i in range(rng.randint(1, 6)):
            damaged[start + i] = rng.randrange(256)
        path = tmp_path / f"damaged{k}.sqlite"
        path.write_bytes(bytes(damaged))
        try:
            with TrialLog(path) as log:
                records = log.trials("r")
            readable += 1
            assert all(np.all(np.isfinite(r.parameters)) for r in records)
        except TrialLogError as error:
            refused += 1
            assert str(path) in str(error) and "damaged" in str(error)
        assert path.read_bytes() == bytes(damaged)  # not one byte changed
    # Some scribbles land in free space or text and leave a readable log; many do not.
    assert refused >= 5 and readable + refused == 60


def test_a_read_only_valid_log_opens_read_only_and_refuses_writes_saying_so(tmp_path,
                                                                              monkeypatch):
    path = tmp_path / "log.sqlite"
    original = _write_log(path)
    real_access = os.access

    def no_write(p, mode, *args, **kwargs):  # as a user without write permission sees it
        if mode & os.W_OK and str(p).startswith(str(tmp_path)):
            return False
        return real_access(p, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", no_write)
    with TrialLog(path) as log:
        assert log.read_only
        assert [r.metric for r in log.trials("r")] == pytest.approx([0.1 * i for i in range(30)])
        with pytest.raises(TrialLogError, match="read-only"):
            log.add_pending("r", 99, [0.1, 0.1], 0)
    assert path.read_bytes() == original


def test_not_sqlite_and_foreign_files_are_refused_untouched(tmp_path):
    text = tmp_path / "notes.sqlite"
    text.write_text("my notes")
    with pytest.raises(TrialLogError, match="not an SQLite database"):
        TrialLog(text)
    assert text.read_text() == "my notes"
