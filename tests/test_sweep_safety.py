"""The sweep engine against a busy machine and a careless user: cache entries that are not what their
key says are refused, an unwritable cache is refused before any compute, a cell whose worker process was
killed runs once more, and a sweep that still fails says so briefly and logs the rest."""

from __future__ import annotations

import os
import pickle
import signal
import sys
import threading
import time
import types
from pathlib import Path

import pytest

from hipref import sweep
from hipref.sweep import SweepError, cached_artefact, cell_key, run_sweep
from tests._sweep_cells import ToyCell, dying_cell, executions, toy_cell


def test_rows_stored_under_another_cells_key_are_refused_and_recomputed(tmp_path: Path) -> None:
    cells = [ToyCell(seed=1000), ToyCell(seed=1002)]
    reference = run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1)
    source, victim = (tmp_path / "cells" / f"{cell_key(toy_cell, cell)}.pkl" for cell in cells)
    victim.write_bytes(source.read_bytes())  # seed 1000's entry where seed 1002's belongs
    with pytest.warns(UserWarning, match=f"{victim.name}: it was stored under the key {source.stem[:16]}"):
        again = run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1)
    assert again.to_csv() == reference.to_csv()
    assert sweep.read_entry(victim)[0] == victim.stem, "the recomputed entry replaced the moved one"


def test_forged_and_tampered_entries_are_refused(tmp_path: Path) -> None:
    cells = [ToyCell(seed=0)]
    reference = run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1)
    (path,) = (tmp_path / "cells").glob("*.pkl")
    path.write_bytes(pickle.dumps(reference.assign(value=123.0)))  # tidy rows, but no key
    with pytest.warns(UserWarning, match="it is no cache entry"):
        assert run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1).to_csv() == reference.to_csv()
    entry = pickle.loads(path.read_bytes())
    entry["payload"] = pickle.dumps(reference.assign(value=123.0))  # the right key, another payload
    path.write_bytes(pickle.dumps(entry))
    with pytest.warns(UserWarning, match="its payload does not match its checksum"):
        assert run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1).to_csv() == reference.to_csv()


@pytest.mark.parametrize("kind", ["file", "read_only"])
def test_an_unwritable_cache_is_refused_before_any_compute(tmp_path: Path, kind: str) -> None:
    cache = tmp_path / "cache"
    if kind == "file":
        cache.write_text("a file where the cache directory should be")
    else:
        if os.geteuid() == 0:
            pytest.skip("root writes into read-only directories")
        cache.mkdir(mode=0o555)
    log = tmp_path / "log"
    log.mkdir()
    with pytest.raises(PermissionError, match=f"cache directory {cache}/cells cannot be written"):
        run_sweep(toy_cell, [ToyCell(seed=0, log_dir=str(log))], cache_dir=cache, workers=1)
    assert executions(log) == [], "no cell ran"
    built: list[int] = []
    with pytest.raises(PermissionError, match=f"cache directory {cache}/artefacts cannot be written"):
        cached_artefact("dataset", {"n": 1}, lambda: built.append(1), cache_dir=cache)
    assert built == [], "nothing was built"


def test_a_cell_whose_worker_is_killed_runs_once_more(tmp_path: Path) -> None:
    log = tmp_path / "log"
    log.mkdir()
    cells = [ToyCell(seed=seed, log_dir=str(log), sleep=1.0 if seed == 0 else 0.1) for seed in range(4)]
    reference = run_sweep(toy_cell, [ToyCell(seed=seed) for seed in range(4)], cache_dir=False, workers=1)
    killed: list[int] = []

    def kill_the_first_worker_of_seed_0() -> None:
        deadline = time.monotonic() + 60
        while not killed and time.monotonic() < deadline:
            for marker in log.iterdir():
                seed, pid, _ = marker.name.split("-")
                if seed == "0":
                    os.kill(int(pid), signal.SIGKILL)
                    killed.append(int(pid))
                    return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_the_first_worker_of_seed_0)
    killer.start()
    with pytest.warns(UserWarning, match="lost their worker process"):
        rows = run_sweep(toy_cell, cells, cache_dir=tmp_path / "cache", workers=2)
    killer.join()
    assert killed, "the worker running seed 0 was found and killed"
    assert rows.to_csv() == reference.to_csv()
    assert executions(log).count(0) == 2, "seed 0 ran in the killed worker, then once more"
    assert executions(log, pid=killed[0]).count(0) == 1


def test_a_sweep_still_failing_after_the_retry_says_briefly_which_cells_and_logs_the_rest(
    tmp_path: Path,
) -> None:
    cells = [ToyCell(seed=0), ToyCell(seed=1, fail=True)]
    with pytest.warns(UserWarning, match="lost their worker process"), pytest.raises(SweepError) as raised:
        run_sweep(dying_cell, cells, cache_dir=tmp_path, workers=2, desc="dying sweep")
    message = str(raised.value)
    assert repr(cells[1]) in message
    assert message.count("Traceback") == 0 and len(message.splitlines()) <= 10, message
    assert "BrokenProcessPool" in message, "the first error's last lines"
    log = raised.value.log
    assert log is not None and log.parent == tmp_path / "logs" and log.name.startswith("dying-sweep-")
    assert str(log) in message
    logged = log.read_text()
    assert repr(cells[1]) in logged and "Traceback (most recent call last)" in logged


def test_a_failure_log_without_a_cache_goes_to_the_temporary_directory() -> None:
    with pytest.raises(SweepError) as raised:
        run_sweep(toy_cell, [ToyCell(seed=3, fail=True)], cache_dir=False, workers=1)
    log = raised.value.log
    assert log is not None and "RuntimeError: toy failure in cell with seed 3" in log.read_text()
    log.unlink()


def test_a_sweep_runs_after_ipythons_reset_deleted_the_main_modules_spec(monkeypatch) -> None:
    """`%reset` in a notebook deletes `__main__.__spec__`, which spawn reads to start each worker."""
    main = types.ModuleType("__main__")
    del main.__spec__
    monkeypatch.setitem(sys.modules, "__main__", main)
    rows = run_sweep(toy_cell, [ToyCell(seed=seed) for seed in range(2)], cache_dir=False, workers=2)
    assert len(rows) == len(run_sweep(toy_cell, [ToyCell(seed=0)], cache_dir=False, workers=1)) * 2
