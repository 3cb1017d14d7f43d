"""Executing a notebook the way `make test` and the quick profile do leaves every tracked file as it was.

The notebooks write through `hipref.results.results_dir()`: `make test` points `HIPREF_RESULTS_DIR` at a
temporary directory and `make reproduce PROFILE=quick` at the ignored `results/quick/`, so only the full
profile rewrites the committed `results/`. The test executes notebook 06 end-to-end as `make reproduce` does
(`hipref/run_notebook.py`, papermill) with the environment it was started in (as `make test` starts it) at a
tiny scale, and compares the checkout before and after.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = Path("notebooks") / "06_noise_estimation.ipynb"
# Every cell still runs, and every writer (CSVs, figures, claims) still writes, on 2 datasets per noise level
# and one CO-PESI run per method and noise level with a single evaluation.
TINY = {"repetitions": 2, "copesi_seeds": 1, "copesi_episodes": 33, "copesi_eval_episodes": 1}


def git(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", "-C", str(cwd), *args], capture_output=True, text=True, check=False)


def checkout_state() -> dict[str, str]:
    """Each path `git status --porcelain` lists, with its status and a digest of its content.

    The digest catches a file that was already modified before the run and is rewritten by it.
    """
    out = git("status", "--porcelain=v1", "-z", "--untracked-files=all")
    assert out.returncode == 0, out.stderr
    entries = iter(out.stdout.split("\0"))
    state: dict[str, str] = {}
    for entry in entries:
        if not entry:
            continue
        status, path = entry[:2], entry[3:]
        if status[0] in "RC":
            next(entries)  # a rename or copy is followed by its source path
        file = ROOT / path
        digest = hashlib.sha256(file.read_bytes()).hexdigest() if file.is_file() else "absent"
        state[path] = f"{status} {digest}"
    return state


def writes_to_a_checkout(directory: Path) -> bool:
    """Whether a results file under `directory` would show in some git checkout (inside one, not ignored)."""
    existing = directory
    while not existing.is_dir():
        existing = existing.parent
    top = git("rev-parse", "--show-toplevel", cwd=existing)
    if top.returncode != 0:
        return False
    # claims.md is the file every notebook updates; a tracked file is never reported as ignored.
    ignored = git("check-ignore", "-q", str(directory / "claims.md"), cwd=Path(top.stdout.strip()))
    return ignored.returncode != 0


@pytest.mark.slow
def test_executing_a_notebook_changes_no_tracked_file(tmp_path: Path) -> None:
    if git("rev-parse", "--show-toplevel").returncode != 0:
        pytest.skip(f"{ROOT} is not a git checkout, so there are no tracked files to protect")
    env = dict(os.environ)
    # The kernel's view of where results go: the same interpreter, environment and working directory.
    where = subprocess.run(
        [sys.executable, "-c", "from hipref.results import results_dir; print(results_dir().resolve())"],
        cwd=ROOT / "notebooks",
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    destination = Path(where.stdout.strip())
    # Checked before executing, so that a wrong set-up fails without overwriting the committed results.
    assert not writes_to_a_checkout(destination), (
        f"results would be written to {destination}, inside a git checkout and not ignored; run the tests "
        "through `make test`, which points HIPREF_RESULTS_DIR at a temporary directory, or set it yourself"
    )
    before = checkout_state()
    tiny = [arg for name, value in TINY.items() for arg in ("-p", name, str(value))]
    subprocess.run(
        [
            sys.executable,
            "-m",
            "hipref.run_notebook",
            "--no-progress-bar",
            "-f",
            f"params/quick/{NOTEBOOK.stem}.yaml",
            *tiny,
            str(NOTEBOOK),
            str(tmp_path / NOTEBOOK.name),
        ],
        cwd=ROOT,
        env=env,
        check=True,
    )
    assert (destination / "claims.md").is_file(), f"the notebook wrote no claims to {destination}"
    after = checkout_state()
    changed = sorted(path for path in before.keys() | after.keys() if before.get(path) != after.get(path))
    assert not changed, f"executing the notebook changed these files of the checkout: {changed}"
