"""Notebook 03's claims on one environment per domain say "too few environments to decide", never "yes".

`papermill -y "heights: [0.6]" -y "masses: [11.0]"` once gave all six claims of notebook 03 "yes" from
intervals such as [+0.00895, +0.00895]. The notebook's own code cells run here, up to the one that writes its
claims, with those parameters and its study replaced by rows of one environment per domain (so no physics
runs): every verdict must be "too few environments to decide".
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import pandas as pd
import pytest

from hipref.experiments import r2_noise

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "03_r2_noise.ipynb"


def _one_environment(config: r2_noise.R2Config, **_: object) -> pd.DataFrame:
    """Rows shaped as `r2_noise.run`'s, of one environment per domain, in which PESI's error clearly grows
    with the noise and falls below OSI's: any verdict read from one environment would be 'yes'."""
    rows = []
    for domain, truths in (("wiping", config.heights), ("pushing", config.masses)):
        for truth in truths:
            for episode in range(0, config.episodes + 1, config.eval_every):
                rows.append((domain, "osi", 0.0, episode, 0.05, truth))
                for noise in config.noise_levels:
                    error = 0.05 - 0.0004 * episode * (1 - noise) + 0.0002 * episode * noise
                    rows.append((domain, "pesi", noise, episode, error, truth))
    frame = pd.DataFrame(rows, columns=["domain", "method", "noise", "episode", "value", "ground_truth"])
    return frame.assign(seed=0, metric="param_error", n_candidates=2)[
        ["domain", "method", "noise", "seed", "episode", "metric", "value", "ground_truth", "n_candidates"]
    ]


def _code_cells_up_to_the_claims(notebook: Path) -> tuple[str, list[str]]:
    """The parameters cell, and every later code cell up to the one writing the notebook's claims."""
    cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
    (at,) = [i for i, c in enumerate(cells) if "parameters" in c.get("metadata", {}).get("tags", [])]
    code = ["".join(c["source"]) for c in cells[at + 1 :] if c["cell_type"] == "code"]
    last = next(i for i, source in enumerate(code) if "update_claims(" in source)
    return "".join(cells[at]["source"]), code[: last + 1]


def test_notebook_03_on_one_environment_says_too_few_environments_to_decide(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    matplotlib.use("Agg")
    monkeypatch.setenv("HIPREF_RESULTS_DIR", str(tmp_path))
    monkeypatch.setattr(r2_noise, "run", _one_environment)
    parameters, cells = _code_cells_up_to_the_claims(NOTEBOOK)
    namespace: dict[str, object] = {}
    # Compiled without this module's `from __future__ import annotations`, as IPython runs a cell.
    exec(compile(parameters, str(NOTEBOOK), "exec", dont_inherit=True), namespace)
    # What papermill's -y "heights: [0.6]" -y "masses: [11.0]" injects after the parameters cell.
    exec("heights = [0.6]\nmasses = [11.0]\nnoise_levels = [0.0, 0.3, 0.6]", namespace)
    for source in cells:
        exec(compile(source, str(NOTEBOOK), "exec", dont_inherit=True), namespace)
    claims = (tmp_path / "claims.md").read_text(encoding="utf-8")
    rows = [line for line in claims.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert len(rows) >= 6, claims  # the paper's six claims, then each learner against the constant guess
    assert all(row.endswith("| too few environments to decide |") for row in rows), claims
