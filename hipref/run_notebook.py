"""Execute one notebook with a profile's parameters: what `make reproduce` and `make notebooks` run for each.

    python -m hipref.run_notebook -f params/quick/06_noise_estimation.yaml [-p repetitions 2] [--committed] \\
        notebooks/06_noise_estimation.ipynb results/quick/notebooks/06_noise_estimation.ipynb

- papermill executes into a temporary file beside the output, which replaces the output only once every cell
  has run: a failed or interrupted run leaves the output as it was (papermill itself saves after every cell);
- the kernel runs in the notebook's folder and listens on sockets of its own (`hipref.kernel`), so notebooks
  executed side by side never compete for a port;
- an absolute path of this machine in an output is written relative to the kernel's working directory
  (`../results/quick/figures/fig2c.png`), or as what it stands for (`$HIPREF_RESULTS_DIR`, `~`, `$TMPDIR`);
- `--committed` writes a notebook as it is committed: without papermill's cell of injected parameters, whose
  values the parameters cell already holds (the quick profile is the defaults), and with its cells numbered
  from 1, so that a person who runs it top to bottom gets this notebook, and an edit of the parameters cell
  is not overridden. Without it the injected cell stays: it records which parameters the run used;
- ended by SIGTERM (as make and xargs end a job) or an interrupt, it stops the kernel and the kernel's
  sweep workers before it exits: nothing is left running.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import os
import re
import signal
import sys
import tempfile
import uuid
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import nbformat
import papermill
import psutil
import yaml

from hipref.kernel import IPCKernelManager

KERNEL = "hipref"
"""The Jupyter kernel `make install` registers in the virtualenv."""

ROOT = Path(__file__).resolve().parents[1]
"""The checkout the notebooks belong to."""

INJECTED = "injected-parameters"
"""The tag of the cell papermill adds after the parameters cell."""

TEXT_MEDIA = ("text/", "image/svg+xml", "application/json")
"""Output data that are text, and may name a path (PNG and the like are base64)."""


def temporary_beside(output: Path) -> Path:
    """A hidden file in the output's folder (so that the final rename stays on one file system), ending in
    .ipynb as papermill wants, and matched by no notebook glob."""
    return output.with_name(f".{output.stem}.{uuid.uuid4().hex[:8]}.partial.ipynb")


def load_parameters(path: Path | None) -> dict[str, Any]:
    if path is None:
        return {}
    loaded = yaml.safe_load(path.read_text()) or {}
    if not isinstance(loaded, dict):
        kind = type(loaded).__name__
        raise ValueError(f"{path}: parameters must be a mapping of name to value, got a {kind}")
    return loaded


def path_replacements(cwd: Path, root: Path = ROOT) -> dict[str, str]:
    """Absolute path -> what an output shows instead, for the places of this machine an output can name."""
    cwd, root = cwd.resolve(), root.resolve()
    found: dict[str, str] = {}

    def add(path: Path | str, shown: str) -> None:
        for form in {str(path), str(Path(path).resolve())}:
            if len(form) > 1:
                found.setdefault(form, shown)

    add(cwd, ".")
    if cwd.is_relative_to(root):
        add(root, os.path.relpath(root, cwd))
    if results := os.environ.get("HIPREF_RESULTS_DIR"):
        within = Path(results).resolve()
        add(results, os.path.relpath(within, cwd) if within.is_relative_to(root) else "$HIPREF_RESULTS_DIR")
    add(tempfile.gettempdir(), "$TMPDIR")
    add(Path.home(), "~")
    return found


def shown_path(path: Path, root: Path = ROOT) -> str:
    """`path` as a notebook's metadata records it: relative to the checkout when it lies inside it."""
    absolute, checkout = path.absolute(), root.absolute()
    return str(absolute.relative_to(checkout)) if absolute.is_relative_to(checkout) else str(path)


def relative_text(text: str, replacements: Mapping[str, str]) -> str:
    """`text` with each absolute path of `replacements` replaced, the longest first, where it is a whole path
    or the start of one (`/work/main` is not replaced inside `/work/main2`)."""
    for absolute in sorted(replacements, key=len, reverse=True):
        pattern = rf"(?<![\w.-]){re.escape(absolute)}(?![\w.-])"
        text = re.sub(pattern, replacements[absolute].replace("\\", "\\\\"), text)
    return text


def output_texts(output: dict[str, Any]) -> Iterator[tuple[Any, str | int]]:
    """(container, key) of every text of a cell output that may hold a path: a dict of the notebook's JSON
    and its key, or a list and its index (Any: JSON's nodes are either)."""
    if output.get("output_type") == "stream":
        yield output, "text"
    elif output.get("output_type") == "error":
        yield output, "evalue"
        yield from ((output["traceback"], i) for i in range(len(output.get("traceback", []))))
    for media in output.get("data", {}):
        if media.startswith(TEXT_MEDIA):
            yield output["data"], media


def relative_outputs(notebook: nbformat.NotebookNode, replacements: Mapping[str, str]) -> None:
    """Replace, in place, the absolute paths of `replacements` in every text output of `notebook`."""
    for cell in notebook.cells:
        for output in cell.get("outputs", []):
            for container, key in output_texts(output):
                value = container[key]
                if isinstance(value, list):
                    container[key] = [relative_text(line, replacements) for line in value]
                elif isinstance(value, str):
                    container[key] = relative_text(value, replacements)


def as_committed(notebook: nbformat.NotebookNode) -> None:
    """Remove papermill's injected-parameters cell, number the executed cells from 1 and record the
    parameters it ran with, its parameters cell's defaults, in place (papermill keeps those of the notebook
    it read, which may be of an earlier run)."""
    notebook.cells = [c for c in notebook.cells if INJECTED not in c.get("metadata", {}).get("tags", [])]
    (cell,) = (c for c in notebook.cells if "parameters" in c.get("metadata", {}).get("tags", []))
    notebook.metadata.papermill["parameters"] = {
        node.target.id: ast.literal_eval(node.value)
        for node in ast.parse(cell.source).body
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None
    }
    count = 0
    for cell in notebook.cells:
        if cell.cell_type != "code" or cell.get("execution_count") is None:
            continue
        count += 1
        cell.execution_count = count
        for output in cell.get("outputs", []):
            if output.get("output_type") == "execute_result":
                output["execution_count"] = count


def execute(
    notebook: Path,
    output: Path,
    parameters: Mapping[str, Any],
    *,
    committed: bool = False,
    kernel: str = KERNEL,
    root: Path = ROOT,
    progress_bar: bool = True,
) -> None:
    """Execute `notebook` with `parameters` in its own folder and write it to `output` once it has run
    through; a failure or an interrupt raises and leaves `output` untouched."""
    output.parent.mkdir(parents=True, exist_ok=True)
    partial = temporary_beside(output)
    _PARTIALS.add(partial)
    try:
        executed = papermill.execute_notebook(
            str(notebook),
            str(partial),
            parameters=dict(parameters),
            kernel_name=kernel,
            cwd=str(notebook.parent),
            progress_bar=progress_bar,
            kernel_manager_class=f"{IPCKernelManager.__module__}.{IPCKernelManager.__name__}",
        )
        if committed:
            as_committed(executed)
        relative_outputs(executed, path_replacements(notebook.parent, root))
        # papermill records the paths it was given: the output's is the temporary file.
        executed.metadata.papermill["input_path"] = shown_path(notebook, root)
        executed.metadata.papermill["output_path"] = shown_path(output, root)
        nbformat.write(executed, str(partial))
        os.replace(partial, output)
    finally:
        _PARTIALS.discard(partial)
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()


_PARTIALS: set[Path] = set()
"""The temporary files of the executions under way, removed by `_terminate`."""


def end_descendants(grace: float = 5.0) -> None:
    """Stop every process this one started, and theirs: the kernel and the workers of its sweep. A kernel
    manager ended by a signal does not shut its kernel down, and the kernel's workers live as long as it."""
    children = psutil.Process().children(recursive=True)
    for child in children:
        with contextlib.suppress(psutil.NoSuchProcess):
            child.terminate()
    _, alive = psutil.wait_procs(children, timeout=grace)
    for child in alive:
        with contextlib.suppress(psutil.NoSuchProcess):
            child.kill()


def _terminate(signum: int, _frame: object) -> None:
    # xargs and make end a job with SIGTERM: stop the kernel and its workers, remove the partial output and
    # leave at once (papermill's own clean-up would wait for the stopped kernel's reply).
    end_descendants()
    for partial in _PARTIALS:
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
    os._exit(128 + signum)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hipref.run_notebook", description=__doc__.split("\n")[0])
    parser.add_argument("notebook", type=Path, help="the notebook to execute")
    parser.add_argument("output", type=Path, help="where the executed notebook goes (may be the notebook)")
    parser.add_argument("-f", "--parameters", type=Path, help="YAML file of parameters (params/<profile>/)")
    parser.add_argument(
        "-p",
        "--parameter",
        nargs=2,
        action="append",
        default=[],
        metavar=("NAME", "VALUE"),
        help="a parameter, its value read as YAML; overrides the file's",
    )
    parser.add_argument(
        "--committed",
        action="store_true",
        help="write it as committed: no injected-parameters cell, cells numbered from 1",
    )
    parser.add_argument("--kernel", default=KERNEL, help=f"Jupyter kernel name (default {KERNEL})")
    parser.add_argument(
        "--no-progress-bar",
        action="store_true",
        help="no progress bar on stderr (there is none when stderr is no terminal)",
    )
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, _terminate)
    overrides = {name: yaml.safe_load(value) for name, value in args.parameter}
    parameters = load_parameters(args.parameters) | overrides
    try:
        execute(
            args.notebook,
            args.output,
            parameters,
            committed=args.committed,
            kernel=args.kernel,
            progress_bar=not args.no_progress_bar and sys.stderr.isatty(),  # no overlong line in a log
        )
    except BaseException:
        end_descendants()  # Ctrl-C interrupts the kernel's cell but leaves the kernel running
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
