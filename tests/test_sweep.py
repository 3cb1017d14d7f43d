"""Properties of the sweep engine: same rows on every backend, nothing computed twice, nothing lost."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from hipref import sweep
from hipref.sweep import SweepError, cached_artefact, cell_key, run_sweep
from hipref.sweep import progress as sweep_progress
from hipref.sweep.cache import NOT_IN_ROWS, without_docstrings
from tests._sweep_cells import (
    ThreadsCell,
    ToyCell,
    artefact_cell,
    executing_pids,
    executions,
    resume_cells,
    threads_cell,
    toy_cell,
)

REPO = Path(__file__).resolve().parent.parent


def grid(log_dir: Path | str = "") -> list[ToyCell]:
    """Six cells, the first one slow: with two workers it finishes last, the others out of order."""
    return [
        ToyCell(seed=seed, noise=noise, log_dir=str(log_dir), sleep=0.5 if (seed, noise) == (0, 0.0) else 0.0)
        for seed in (0, 1, 2)
        for noise in (0.0, 0.2)
    ]


def entries(cache_dir: Path) -> list[Path]:
    return sorted((cache_dir / "cells").glob("*.pkl"))


@pytest.fixture
def log_dir(tmp_path: Path) -> Path:
    path = tmp_path / "log"
    path.mkdir()
    return path


@pytest.fixture(scope="module")
def dask_address(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A two-worker local cluster whose scratch space (with its lock files) is a pytest temporary folder,
    not Dask's default folder under the system's temporary directory, which no test may leave files in."""
    distributed = pytest.importorskip("distributed")
    import dask

    scratch = tmp_path_factory.mktemp("dask")
    with (
        dask.config.set({"temporary-directory": str(scratch)}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        ) as cluster,
    ):
        yield cluster.scheduler_address


@pytest.fixture(autouse=True)
def _isolated(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """No cluster or cache location from the caller's environment, and no artefact memo between tests."""
    monkeypatch.delenv("HIPREF_DASK_SCHEDULER", raising=False)
    monkeypatch.delenv("HIPREF_CACHE_DIR", raising=False)
    sweep.forget_artefacts()
    yield
    sweep.forget_artefacts()


def test_rows_are_identical_on_every_backend_and_follow_cell_order(
    dask_address: str,
    log_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    cells = grid(log_dir)
    one = run_sweep(toy_cell, cells, cache_dir=False, workers=1)
    two = run_sweep(toy_cell, cells, cache_dir=False, workers=2)
    on_dask = run_sweep(toy_cell, cells, cache_dir=False, scheduler=dask_address)

    expected = [(cell.seed, cell.noise) for cell in cells for _ in range(5)]
    assert list(zip(one["seed"], one["noise"], strict=True)) == expected
    assert list(one.index) == list(range(len(one)))
    pd.testing.assert_frame_equal(one, two)
    pd.testing.assert_frame_equal(one, on_dask)
    assert one.to_csv() == two.to_csv() == on_dask.to_csv()

    # The environment variable selects the cluster too, and the cells really run on its workers.
    env_log = log_dir / "env"
    env_log.mkdir()
    monkeypatch.setenv("HIPREF_DASK_SCHEDULER", dask_address)
    via_env = run_sweep(toy_cell, grid(env_log), cache_dir=False)
    assert via_env.to_csv() == one.to_csv()
    distributed = pytest.importorskip("distributed")
    with distributed.Client(dask_address) as client:
        worker_pids = set(client.run(os.getpid).values())
        scratch = set(client.run(lambda dask_worker: dask_worker.local_directory).values())
    assert executing_pids(env_log) <= worker_pids
    # The workers' scratch space, lock files and all, lies in pytest's temporary folder.
    assert all(Path(folder).is_relative_to(tmp_path_factory.getbasetemp()) for folder in scratch), scratch


def test_no_progress_bar_is_written_when_stderr_is_no_terminal(capsys: pytest.CaptureFixture[str]) -> None:
    # In a log file each update would only lengthen one line.
    run_sweep(toy_cell, grid(), cache_dir=False, workers=1)
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_cells_run_single_threaded_in_workers_and_in_process() -> None:
    import torch

    cells = [ThreadsCell(seed) for seed in range(2)]
    in_workers = run_sweep(threads_cell, cells, cache_dir=False, workers=2)
    assert list(in_workers["torch_threads"]) == [1, 1]
    assert list(in_workers["omp"]) == ["1", "1"]
    assert list(in_workers["blas_threads"]) == [1, 1]

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        in_process = run_sweep(threads_cell, cells, cache_dir=False, workers=1)
        assert list(in_process["torch_threads"]) == [1, 1]
        assert torch.get_num_threads() == 2, "the caller's thread setting is restored"
    finally:
        torch.set_num_threads(before)


@pytest.mark.slow
def test_workers_run_blas_on_one_thread_where_the_main_module_loaded_it() -> None:
    """A spawned worker imports its parent's main module before its initializer sets the thread count
    (`python -m hipref.bench.held_out_steps` imports numpy): the BLAS already loaded is limited too. The
    sweep's process asks for two BLAS threads, which a worker would otherwise keep."""
    env = {**os.environ, "OMP_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"}
    result = subprocess.run(
        [sys.executable, "-m", "tests._sweep_cells", "--threads"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    assert result.stdout.split() == ["1", "1"]


@pytest.mark.parametrize("workers", [1, 2])
def test_second_run_recomputes_nothing(tmp_path: Path, log_dir: Path, workers: int) -> None:
    cells = grid(log_dir)
    first = run_sweep(toy_cell, cells, cache_dir=tmp_path / "cache", workers=workers)
    assert executions(log_dir) == sorted(cell.seed for cell in cells)
    assert len(entries(tmp_path / "cache")) == len(cells)

    second = run_sweep(toy_cell, cells, cache_dir=tmp_path / "cache", workers=workers)
    assert len(executions(log_dir)) == len(cells), "no cell ran again"
    assert second.to_csv() == first.to_csv()


def test_progress_counts_cached_cells_as_done(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # as on a terminal
    cells = grid()
    run_sweep(toy_cell, cells[:4], cache_dir=tmp_path, workers=1, desc="first")
    capsys.readouterr()
    run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1, desc="second")
    progress = capsys.readouterr()
    assert progress.out == ""
    assert "second" in progress.err and "4/6" in progress.err and "6/6" in progress.err


def test_no_progress_goes_to_a_file_or_a_pipe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_sweep(toy_cell, grid(), cache_dir=tmp_path, workers=1, desc="piped")
    assert capsys.readouterr() == ("", "")


def test_a_notebook_shows_one_line_updated_to_its_last_state(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """In a kernel the line is one output re-sent under its display id (here, an IPython shell prints each
    sending): the saved notebook holds the last, with the cells read from the cache."""
    from IPython.core.interactiveshell import InteractiveShell

    InteractiveShell.instance()
    monkeypatch.setattr(sweep_progress, "EVERY", 0.0)
    monkeypatch.setattr(sweep_progress, "in_kernel", lambda: True)
    cells = grid()
    run_sweep(toy_cell, cells[:4], cache_dir=tmp_path, workers=1, desc="first")
    capsys.readouterr()
    run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=1, desc="second")
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("second: 66%| 4 of 6 cells, 4 from the cache, ")
    assert lines[-1].startswith("second: 100%| 6 of 6 cells, 4 from the cache, ") and lines[-1].endswith(" s")


def test_workers_must_be_positive() -> None:
    with pytest.raises(ValueError, match="workers must be an integer at least 1 or None, got 0"):
        run_sweep(toy_cell, grid(), cache_dir=False, workers=0)


def test_equal_cells_are_computed_once(log_dir: Path) -> None:
    cell = ToyCell(seed=3, log_dir=str(log_dir))
    df = run_sweep(toy_cell, [cell, ToyCell(seed=4), cell], cache_dir=False, workers=1)
    assert executions(log_dir) == [3]
    assert list(df["seed"]) == [3] * 5 + [4] * 5 + [3] * 5


@pytest.mark.parametrize("damage", ["truncate", "garbage", "wrong_type", "untidy_frame"])
def test_damaged_cache_entry_is_recomputed_with_a_warning(tmp_path: Path, log_dir: Path, damage: str) -> None:
    cells = grid(log_dir)
    cache = tmp_path / "cache"
    reference = run_sweep(toy_cell, cells, cache_dir=cache, workers=1)
    victim = cache / "cells" / f"{cell_key(toy_cell, cells[2])}.pkl"
    if damage == "truncate":
        victim.write_bytes(victim.read_bytes()[:50])
    elif damage == "garbage":
        victim.write_bytes(b"not a pickle at all")
    elif damage == "wrong_type":
        sweep.write_entry(victim, victim.stem, ["a list, not a DataFrame"])
    else:  # a frame under the right key, but not rows of a cell
        sweep.write_entry(victim, victim.stem, pd.DataFrame({"seed": [cells[2].seed], "value": [0.0]}))

    with pytest.warns(UserWarning, match=victim.name):
        again = run_sweep(toy_cell, cells, cache_dir=cache, workers=1)
    assert again.to_csv() == reference.to_csv()
    assert executions(log_dir) == sorted([*(cell.seed for cell in cells), cells[2].seed])
    # The recomputed entry replaced the damaged one.
    key, rows = sweep.read_entry(victim)
    assert key == victim.stem
    assert rows.equals(reference.iloc[10:15].reset_index(drop=True))


@pytest.mark.parametrize("workers", [1, 2])
def test_failing_cell_reports_config_and_traceback_and_others_are_cached(
    tmp_path: Path, workers: int
) -> None:
    cells = [ToyCell(seed=0), ToyCell(seed=1, fail=True), ToyCell(seed=2)]
    with pytest.raises(SweepError) as raised:
        run_sweep(toy_cell, cells, cache_dir=tmp_path, workers=workers)
    message = str(raised.value)
    assert repr(cells[1]) in message
    assert "RuntimeError: toy failure in cell with seed 1" in message
    log = raised.value.log
    assert log is not None and str(log) in message
    assert "Traceback (most recent call last)" in log.read_text()
    assert [cell for cell, _ in raised.value.failures] == [cells[1]]
    assert {path.stem for path in entries(tmp_path)} == {cell_key(toy_cell, c) for c in (cells[0], cells[2])}


def test_wrong_return_type_is_a_failure(tmp_path: Path) -> None:
    with pytest.raises(SweepError, match="returned list, not a pandas DataFrame") as raised:
        run_sweep(_returns_list, [ToyCell(seed=0)], cache_dir=False, workers=1)
    assert raised.value.log is not None
    raised.value.log.unlink()  # without a cache the log goes to the system's temporary directory


def _returns_list(cell: ToyCell) -> list[int]:
    return [cell.seed]


@pytest.mark.slow
def test_killed_sweep_resumes_without_recomputing_and_matches_an_uninterrupted_run(
    tmp_path: Path, log_dir: Path
) -> None:
    cache = tmp_path / "cache"
    cells = resume_cells(str(log_dir))
    process = subprocess.Popen(
        [sys.executable, "-m", "tests._sweep_cells", str(cache), str(log_dir)],
        cwd=REPO,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while len(entries(cache)) < 3 and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.wait()
    assert process.returncode == -signal.SIGKILL, "the sweep was killed, not finished"
    cached = {path.stem for path in entries(cache)}
    assert 3 <= len(cached) < len(cells)

    resumed = run_sweep(toy_cell, cells, cache_dir=cache, workers=1)
    missing = sorted(cell.seed for cell in cells if cell_key(toy_cell, cell) not in cached)
    assert executions(log_dir, pid=os.getpid()) == missing

    uninterrupted = run_sweep(toy_cell, cells, cache_dir=tmp_path / "fresh", workers=1)
    assert resumed.to_csv() == uninterrupted.to_csv()


def test_cell_key_depends_on_config_and_function_only() -> None:
    assert cell_key(toy_cell, ToyCell(seed=1)) == cell_key(toy_cell, ToyCell(seed=1))
    assert cell_key(toy_cell, ToyCell(seed=1)) != cell_key(toy_cell, ToyCell(seed=2))
    assert cell_key(toy_cell, ToyCell(seed=1)) != cell_key(_returns_list, ToyCell(seed=1))
    with pytest.raises(TypeError, match="dataclass"):
        cell_key(toy_cell, {"seed": 1})


def test_code_version_names_the_package_version() -> None:
    import hipref

    assert sweep.code_version().startswith(hipref.__version__ + "+")
    assert sweep.code_version() is sweep.code_version()


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_the_artefacts_of_a_sweeps_cells_go_to_its_cache_dir(
    tmp_path: Path, workers: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path / "default"))
    cache = tmp_path / "cache"
    cells = [ToyCell(seed=10 * workers + s) for s in (1, 2)]  # seeds no other test builds in this process
    rows = run_sweep(artefact_cell, cells, cache_dir=cache, workers=workers)
    assert len(list((cache / "artefacts").glob("toy_offset-*.pkl"))) == 2
    assert not (tmp_path / "default").exists()
    pd.testing.assert_frame_equal(rows, run_sweep(artefact_cell, cells, cache_dir=sweep.NO_CACHE, workers=1))


def test_the_cache_key_ignores_docstrings_and_comments_but_not_code() -> None:
    def tree(source: str) -> str:
        return ast.dump(without_docstrings(ast.parse(source)))

    base = 'def f(x):\n    """Doubles."""\n    return 2 * x\n'
    assert tree(base) == tree('def f(x):\n    """Twice x."""\n    # the double\n    return 2 * x\n')
    assert tree(base) == tree("def f(x):\n    return 2 * x\n")
    assert tree(base) != tree('def f(x):\n    """Doubles."""\n    return 3 * x\n')
    assert "bench" in NOT_IN_ROWS and "plots.py" in NOT_IN_ROWS


def test_a_prefix_artefact_serves_every_shorter_length_and_grows_on_demand(tmp_path: Path) -> None:
    builds: list[int] = []

    def build(count: int) -> list[int]:
        builds.append(count)
        return [10 * k for k in range(count)]

    def get(length: int) -> list[int]:
        config = ("prefix test", str(tmp_path))
        return sweep.cached_prefix("tens_prefix", config, length, build, cache_dir=tmp_path)

    assert get(3) == [0, 10, 20] and get(2) == [0, 10] and builds == [3]
    assert get(5) == [0, 10, 20, 30, 40] and builds == [3, 5]
    sweep.forget_artefacts()  # a new process: read back from disk
    assert get(4) == [0, 10, 20, 30] and builds == [3, 5]


def test_default_cache_dir(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("HIPREF_CACHE_DIR", raising=False)
    assert sweep.default_cache_dir() == REPO / ".cache" / "hipref"
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path))
    assert sweep.default_cache_dir() == tmp_path


def test_cached_artefact_builds_once_then_loads(tmp_path: Path) -> None:
    builds: list[int] = []

    def build() -> dict[str, list[float]]:
        builds.append(1)
        return {"weights": [0.5, 1.5]}

    config = ToyCell(seed=7)
    first = cached_artefact("model", config, build, cache_dir=tmp_path)
    assert cached_artefact("model", config, build, cache_dir=tmp_path) is first, "memoised in process"
    sweep.forget_artefacts()
    assert cached_artefact("model", config, build, cache_dir=tmp_path) == first, "loaded from disk"
    assert len(builds) == 1

    sweep.forget_artefacts()
    cached_artefact("model", ToyCell(seed=8), build, cache_dir=tmp_path)
    assert len(builds) == 2, "another config is another artefact"


def test_corrupted_artefact_is_rebuilt_with_a_warning(tmp_path: Path) -> None:
    builds: list[int] = []

    def build() -> list[int]:
        builds.append(1)
        return list(range(1000))

    cached_artefact("dataset", {"episodes": 3}, build, cache_dir=tmp_path)
    (path,) = (tmp_path / "artefacts").glob("dataset-*.pkl")
    path.write_bytes(path.read_bytes()[:20])
    sweep.forget_artefacts()
    with pytest.warns(UserWarning, match=path.name):
        value = cached_artefact("dataset", {"episodes": 3}, build, cache_dir=tmp_path)
    assert value == list(range(1000))
    assert len(builds) == 2
    assert sweep.read_entry(path)[1] == value, "the rebuilt artefact replaced the damaged file"
    assert [p.name for p in (tmp_path / "artefacts").iterdir()] == [path.name], "no temporary file left"


def _untidy_cell(cell: ToyCell) -> pd.DataFrame:
    return pd.DataFrame({"seed": [cell.seed], "value": [1.0]})


def test_rows_without_the_tidy_columns_are_returned_but_not_cached(tmp_path: Path) -> None:
    cells = [ToyCell(seed=0), ToyCell(seed=1)]
    untidy = r"_untidy_cell are not cached.*lack the tidy column\(s\) \['domain'"
    with pytest.warns(UserWarning, match=untidy):
        rows = run_sweep(_untidy_cell, cells, cache_dir=tmp_path, workers=1)
    assert list(rows["seed"]) == [0, 1]
    assert entries(tmp_path) == [], "an entry that could never be loaded back is not written"


def _square_pair() -> tuple[list[int], list[int]]:
    return [1, 2, 3], [1, 4, 9]


def _paired(value: tuple[list[int], list[int]]) -> bool:
    return len(value) == 2 and len(value[0]) == len(value[1])


@pytest.mark.parametrize(
    ("stale", "match"),
    [
        ({"a": "dict from another version"}, "holds dict, expected tuple"),
        (([1, 2, 3], [1, 4]), "fails its check _paired"),
        ((1, 2), "check _paired raised TypeError"),
    ],
)
def test_a_stale_artefact_is_rebuilt_with_a_warning(tmp_path: Path, stale: object, match: str) -> None:
    expect = sweep.Expect(tuple, _paired)
    built = cached_artefact("pairs", {"n": 3}, _square_pair, cache_dir=tmp_path, expect=expect)
    (path,) = (tmp_path / "artefacts").glob("pairs-*.pkl")
    sweep.write_entry(path, sweep.read_entry(path)[0], stale)
    sweep.forget_artefacts()
    with pytest.warns(UserWarning, match=match):
        again = cached_artefact("pairs", {"n": 3}, _square_pair, cache_dir=tmp_path, expect=expect)
    assert again == built
    assert sweep.read_entry(path)[1] == built, "the rebuilt artefact replaced the stale file"


def test_a_plain_type_is_enough_to_refuse_a_foreign_artefact(tmp_path: Path) -> None:
    def build() -> dict[str, list[float]]:
        return {"weights": [1.0]}

    cached_artefact("model", {"n": 1}, build, cache_dir=tmp_path, expect=dict)
    (path,) = (tmp_path / "artefacts").glob("model-*.pkl")
    sweep.write_entry(path, sweep.read_entry(path)[0], ["not", "a", "model"])
    sweep.forget_artefacts()
    with pytest.warns(UserWarning, match="holds list, expected dict"):
        value = cached_artefact("model", {"n": 1}, build, cache_dir=tmp_path, expect=dict)
    assert value == {"weights": [1.0]}


def test_a_built_artefact_that_fails_its_expectation_is_refused_and_not_cached(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="'model' was built but not cached, as it holds list, expected dict"):
        cached_artefact("model", {"n": 1}, lambda: [1.0], cache_dir=tmp_path, expect=dict)
    assert not list((tmp_path / "artefacts").glob("*.pkl"))


def test_expect_must_be_types_or_an_expect() -> None:
    with pytest.raises(ValueError, match="expect must be a type, a tuple of types, an Expect or None, got 3"):
        cached_artefact("model", {"n": 1}, dict, cache_dir=False, expect=3)  # type: ignore[arg-type]
