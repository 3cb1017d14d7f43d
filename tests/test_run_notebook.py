"""The notebook executor (`hipref/run_notebook.py`) and the kernels it and nbval start (`hipref/kernel.py`).

A failed or interrupted execution leaves the output notebook as it was; an executed notebook names no absolute
path of the machine; `--committed` removes papermill's injected cell; every kernel listens on sockets of its
own rather than on TCP ports, which two kernels starting together could both pick.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import nbformat
import psutil
import pytest
from nbformat.v4 import new_code_cell, new_notebook
from papermill.exceptions import PapermillExecutionError

from hipref import run_notebook
from hipref.run_notebook import INJECTED, as_committed, execute, relative_text

ROOT = Path(__file__).resolve().parents[1]

TRANSPORT = "import ipykernel.kernelapp\nprint(ipykernel.kernelapp.IPKernelApp.instance().transport)"


def tiny_notebook(path: Path, *cells: str) -> Path:
    """A notebook of a parameters cell (`value: int = 1`) and `cells`, on the kernel `make install` adds."""
    parameters = new_code_cell("value: int = 1  # a parameter", metadata={"tags": ["parameters"]})
    notebook = new_notebook(cells=[parameters, *(new_code_cell(source) for source in cells)])
    notebook.metadata["kernelspec"] = {"name": "hipref", "display_name": "hipref", "language": "python"}
    nbformat.write(notebook, str(path))
    return path


def texts(notebook: nbformat.NotebookNode) -> list[str]:
    return [
        "".join(o.get("text", "")) + "".join(o.get("data", {}).get("text/plain", ""))
        for c in notebook.cells
        if c.cell_type == "code"
        for o in c.outputs
    ]


def test_a_failed_execution_leaves_the_output_as_it_was(tmp_path: Path) -> None:
    source = tiny_notebook(
        tmp_path / "fails.ipynb", "print('half way')", "raise RuntimeError('a cell fails')"
    )
    output = tmp_path / "out" / "fails.ipynb"
    output.parent.mkdir()
    output.write_text("the previous execution")
    with pytest.raises(PapermillExecutionError, match="a cell fails"):
        execute(source, output, {"value": 2}, root=tmp_path, progress_bar=False)
    assert output.read_text() == "the previous execution"
    assert [p.name for p in output.parent.iterdir()] == ["fails.ipynb"], "a partial file was left behind"


def test_an_interrupted_execution_leaves_the_output_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    partials: list[Path] = []

    def interrupted(source: str, partial: str, **_: Any) -> None:
        # As papermill does: the notebook is saved after each cell, then Ctrl-C arrives in the middle.
        Path(partial).write_text("half an execution")
        partials.append(Path(partial))
        raise KeyboardInterrupt

    monkeypatch.setattr(run_notebook.papermill, "execute_notebook", interrupted)
    output = tmp_path / "notebook.ipynb"
    output.write_text("the previous execution")
    with pytest.raises(KeyboardInterrupt):
        execute(tmp_path / "source.ipynb", output, {}, committed=True)
    assert output.read_text() == "the previous execution"
    assert partials and partials[0].parent == tmp_path, "papermill did not write beside the output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notebook.ipynb"], "a partial file was left behind"


def test_an_execution_runs_on_its_own_sockets_and_names_no_absolute_path(tmp_path: Path) -> None:
    source = tiny_notebook(
        tmp_path / "tiny.ipynb",
        "print(value)",
        TRANSPORT,
        "from pathlib import Path\nPath.cwd() / 'figures' / 'fig.png'",
    )
    output = tmp_path / "executed.ipynb"
    execute(source, output, {"value": 2}, root=tmp_path, progress_bar=False)
    written = output.read_text()
    assert str(tmp_path) not in written
    executed = nbformat.read(str(output), as_version=4)
    assert texts(executed) == ["2\n", "ipc\n", "PosixPath('./figures/fig.png')"]
    # Without --committed the injected cell stays: it records the parameters of the run.
    injected = [INJECTED in c.metadata.get("tags", []) for c in executed.cells]
    assert injected == [False, True, False, False, False]
    assert (executed.metadata.papermill.input_path, executed.metadata.papermill.output_path) == (
        "tiny.ipynb",
        "executed.ipynb",
    )

    executed.metadata.papermill.parameters = {"value": 7}  # as an earlier run with other values left it
    as_committed(executed)
    assert executed.metadata.papermill.parameters == {"value": 1}  # what the committed notebook runs with
    assert not any(INJECTED in c.metadata.get("tags", []) for c in executed.cells)
    assert [c.execution_count for c in executed.cells] == [1, 2, 3, 4]
    assert executed.cells[-1].outputs[0].execution_count == 4


def test_a_path_is_replaced_where_it_is_whole() -> None:
    replacements = {"/work/main": "..", "/work/main/notebooks": "."}
    text = "/work/main/notebooks/x.png /work/main/results/a.csv /work/main2/b /work/mainly '/work/main'"
    assert relative_text(text, replacements) == "./x.png ../results/a.csv /work/main2/b /work/mainly '..'"


def test_nbval_starts_its_kernels_on_sockets_of_their_own(tmp_path: Path) -> None:
    notebook = tiny_notebook(tmp_path / "transport.ipynb", "# NBVAL_CHECK_OUTPUT\n" + TRANSPORT)
    executed = nbformat.read(str(notebook), as_version=4)
    executed.cells[1].outputs = [nbformat.v4.new_output("stream", name="stdout", text="ipc\n")]
    executed.cells[1].execution_count = 1
    nbformat.write(executed, str(notebook))
    # As `make nbval` runs it; a kernel on TCP prints "tcp" and fails the checked cell.
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "tests.nbval_kernel",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:xdist",
            "--nbval-lax",
            "-q",
            str(notebook),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]


def test_a_terminated_execution_leaves_no_kernel_or_worker_running(tmp_path: Path) -> None:
    notebook = tmp_path / "sleeps.ipynb"
    cell = (
        "import subprocess, sys, time\n"
        "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
        "time.sleep(120)"
    )
    nbformat.write(new_notebook(cells=[new_code_cell(cell)]), str(notebook))
    output = tmp_path / "o.ipynb"
    runner = subprocess.Popen([sys.executable, "-m", "hipref.run_notebook", str(notebook), str(output)])
    try:
        descendants: list[psutil.Process] = []
        deadline = time.monotonic() + 120
        # The kernel and the process its cell started (as a sweep starts its workers).
        while len(descendants) < 2 and time.monotonic() < deadline and runner.poll() is None:
            time.sleep(0.5)
            descendants = psutil.Process(runner.pid).children(recursive=True)
        assert len(descendants) >= 2, "the kernel did not start its cell"
        runner.terminate()
        assert runner.wait(timeout=60) != 0
        _, alive = psutil.wait_procs(descendants, timeout=10)
        assert not alive, f"left running: {[p.cmdline() for p in alive]}"
    finally:
        runner.kill()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sleeps.ipynb"], "a partial file was left behind"
