"""A notebook's parameters are checked against its config, and its results directory, before any compute."""

from __future__ import annotations

import ast
import json
import math
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from hipref.experiments.controllers import ControllersConfig
from hipref.experiments.r2_noise import R2Config
from hipref.experiments.r3_copesi import R3Config
from hipref.notebook import check_parameters, check_value, config_from, config_from_parameters
from hipref.results import RESULT_FOLDERS, check_writable
from tests.test_notebooks import first_code_cell

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


@dataclass(frozen=True)
class Study:
    """A config with one field of each kind a notebook sets."""

    rates: tuple[float, ...] = (0.1, 0.2)
    """A list parameter of floats."""
    names: tuple[str, ...] = ("wiping",)
    """A list parameter of strings."""
    seeds: int = 2
    """An integer parameter."""
    rate: float = 0.5
    """A float parameter."""
    domain: str = "wiping"
    """A string parameter."""

    def __post_init__(self) -> None:
        if self.seeds < 1:
            raise ValueError(f"seeds must be an integer >= 1, got {self.seeds!r}")


@dataclass(frozen=True)
class Extra:
    """Fields a notebook sets through a prefix."""

    seeds: int = 3
    """Set by `extra_seeds`."""


def namespace(annotations: dict[str, Any], **values: Any) -> dict[str, Any]:
    """A notebook's globals after its parameters cell (and papermill's injected overrides) ran."""
    return {"__annotations__": dict(annotations), "__name__": "__main__", "In": [""], "Out": {}, **values}


STUDY = {"rates": list[float], "names": list[str], "seeds": int, "rate": float, "domain": str}
DEFAULTS = {"rates": [0.1, 0.2], "names": ["wiping"], "seeds": 2, "rate": 0.5, "domain": "wiping"}


def test_checked_parameters_build_the_config_and_convert_ints_to_floats() -> None:
    ns = namespace(STUDY, **{**DEFAULTS, "rates": [0, 1], "rate": 1})
    config = config_from_parameters(Study, ns)
    assert config == Study(rates=(0.0, 1.0), seeds=2, rate=1.0)
    assert all(isinstance(r, float) for r in config.rates) and isinstance(config.rate, float)
    # Later cells see the converted values, lists still lists.
    assert ns["rates"] == [0.0, 1.0] and isinstance(ns["rates"], list) and isinstance(ns["rate"], float)


def test_a_misspelt_parameter_is_refused_with_the_notebooks_parameters() -> None:
    ns = namespace(STUDY, **DEFAULTS, seed=4)
    with pytest.raises(
        ValueError, match=r"unknown parameter\(s\) seed \(did you mean seeds\?\).*rates, names"
    ):
        check_parameters(ns, Study)


@pytest.mark.parametrize("injected", ["SEEDS = 5", "_seeds = 5", "seed = 5"])
def test_a_name_papermill_injected_that_the_notebook_does_not_declare_is_refused(injected: str) -> None:
    # What the kernel's input history holds after papermill ran the parameters cell and its injected one.
    ns = namespace(STUDY, **DEFAULTS)
    ns["In"] = ["", "seeds: int = 2", f"# Parameters\n{injected}\n"]
    name = injected.split(" = ")[0]
    with pytest.raises(ValueError, match=rf"unknown parameter\(s\) {name} \(did you mean seeds\?\)"):
        check_parameters(ns, Study)


def test_an_injected_declared_parameter_is_taken() -> None:
    ns = namespace(STUDY, **{**DEFAULTS, "seeds": 5})
    ns["In"] = ["", "seeds: int = 2", "# Parameters\nseeds = 5\n"]
    assert check_parameters(ns, Study)["seeds"] == 5


def test_modules_functions_classes_and_private_names_are_not_parameters() -> None:
    ns = namespace(STUDY, **DEFAULTS, json=json, sqrt=math.sqrt, Study=Study, _hidden=3, __doc__="x")
    ns["exit"] = object()
    assert check_parameters(ns, Study)["seeds"] == 2


def test_names_a_later_cell_defines_do_not_stop_a_rerun_of_the_first_cell() -> None:
    ns = namespace(STUDY, **DEFAULTS)
    check_parameters(ns, Study)
    ns["rows"] = [1, 2]  # a later cell of an interactive session
    ns["seeds"] = 5  # the parameters cell edited and run again
    assert check_parameters(ns, Study)["seeds"] == 5


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("rates", 1.5, r"rates must be list\[float\], got 1.5 \(float\)"),
        ("names", "wiping", r"names must be list\[str\], got 'wiping' \(str\)"),
        ("rates", [0.1, "x"], r"rates must be list\[float\], got \[0.1, 'x'\] \(list\): item 1 is 'x'"),
        ("seeds", True, r"seeds must be int, got True \(bool\)"),
        ("seeds", 2.0, r"seeds must be int, got 2.0 \(float\)"),
        ("rate", "0.5", r"rate must be float, got '0.5' \(str\)"),
        ("rates", [True], r"item 0 is True \(bool\)"),
        ("domain", ["wiping"], r"domain must be str, got \['wiping'\] \(list\)"),
    ],
)
def test_a_value_of_the_wrong_type_is_refused_naming_parameter_type_and_value(
    name: str, value: object, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        check_parameters(namespace(STUDY, **{**DEFAULTS, name: value}), Study)


def test_optional_fields_accept_none_or_their_type() -> None:
    assert check_value("cap", None, float | None) is None
    assert check_value("cap", 3, float | None) == 3.0
    with pytest.raises(ValueError, match=r"cap must be float \| None, got 'x'"):
        check_value("cap", "x", float | None)


def test_a_parameters_cell_annotation_must_match_its_config_field() -> None:
    with pytest.raises(ValueError, match=r"rates is annotated list\[int\].*asks for list\[float\]"):
        check_parameters(namespace({**STUDY, "rates": list[int]}, **DEFAULTS), Study)
    with pytest.raises(ValueError, match="notebook parameter colour sets no field of Study"):
        check_parameters(namespace({**STUDY, "colour": str}, **DEFAULTS, colour="red"), Study)


def test_prefixed_parameters_set_a_second_config() -> None:
    ns = namespace({**STUDY, "extra_seeds": int}, **DEFAULTS, extra_seeds=7)
    values = check_parameters(ns, Study, ("extra_", Extra))
    assert config_from(Extra, values, prefix="extra_") == Extra(seeds=7)
    assert config_from(Study, values) == Study()
    ns = namespace({**STUDY, "extra_seeds": int}, **DEFAULTS, extra_seeds=7, extra_seed=1)
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) extra_seed \(did you mean extra_seeds\?\)"):
        check_parameters(ns, Study, ("extra_", Extra))


def test_the_configs_own_validation_runs_when_it_is_built() -> None:
    with pytest.raises(ValueError, match="seeds must be an integer >= 1, got 0"):
        config_from_parameters(Study, namespace(STUDY, **{**DEFAULTS, "seeds": 0}))


# The cases met on the study's notebooks: `-p noise_levels 1.5` (03), `-p domains wiping` (04),
# `-p episodes 0` (03), a claim error outside notebook 05's grid.


def test_a_scalar_noise_levels_is_refused_for_r2() -> None:
    ns = namespace({"noise_levels": list[float]}, noise_levels=1.5)
    with pytest.raises(ValueError, match=r"noise_levels must be list\[float\], got 1.5 \(float\)"):
        config_from_parameters(R2Config, ns)


def test_a_string_domains_is_refused_for_r3() -> None:
    ns = namespace({"domains": list[str]}, domains="wiping")
    with pytest.raises(ValueError, match=r"domains must be list\[str\], got 'wiping' \(str\)"):
        config_from_parameters(R3Config, ns)


def test_a_study_without_learning_episodes_is_refused() -> None:
    ns = namespace({"episodes": int}, episodes=0)
    with pytest.raises(ValueError, match="episodes must be an integer >= 1, got 0"):
        config_from_parameters(R2Config, ns)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("height_errors", (-0.04, 0.0, 0.04), r"height_errors must contain \(0.0, -0.05, 0.05\)"),
        ("mass_errors", (-4.0, 4.0), r"mass_errors must contain \(0.0, -4.0, 4.0\)"),
        ("claim_mass_error", 5.5, r"mass_errors must contain \(0.0, -5.5, 5.5\)"),
        ("claim_height_error", 0.0, "claim_height_error must be a finite number"),
        ("height_errors", (-0.05, 0.0, 0.05, 0.3), r"height_errors must be a finite number in \[-0.2, 0.2\]"),
    ],
)
def test_controllers_claim_errors_must_be_in_the_grid(field: str, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ControllersConfig(**{field: value})


def test_check_writable_creates_the_result_folders_and_leaves_nothing(tmp_path: Path) -> None:
    root = check_writable(tmp_path / "results")
    assert sorted(p.name for p in root.iterdir()) == sorted(RESULT_FOLDERS)
    assert all(not any((root / name).iterdir()) for name in RESULT_FOLDERS)


def test_a_results_directory_that_cannot_be_created_is_refused(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(PermissionError, match=f"results directory {blocker / 'results'} is not writable"):
        check_writable(blocker / "results")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_a_read_only_results_directory_is_refused(tmp_path: Path) -> None:
    (tmp_path / "data").mkdir()
    (tmp_path / "data").chmod(0o500)
    try:
        with pytest.raises(PermissionError, match=r"data is not writable.*HIPREF_RESULTS_DIR"):
            check_writable(tmp_path)
    finally:
        (tmp_path / "data").chmod(0o700)


def run_notebook(tmp_path: Path, results: Path, *args: str) -> tuple[subprocess.CompletedProcess[str], dict]:
    out = tmp_path / "out.ipynb"
    env = {**os.environ, "HIPREF_RESULTS_DIR": str(results), "HIPREF_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run(
        [
            *(sys.executable, "-m", "papermill", "--kernel", "hipref", "--cwd", str(ROOT / "notebooks")),
            *(str(ROOT / "notebooks" / "05_controllers.ipynb"), str(out), *args),
        ],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    return done, json.loads(out.read_text())


def executed_code_cells(notebook: dict) -> list[str]:
    return [
        "".join(c["source"])
        for c in notebook["cells"]
        if c["cell_type"] == "code" and c.get("execution_count") is not None
    ]


@pytest.mark.slow
def test_papermill_run_with_an_unknown_key_in_a_parameters_file_or_an_upper_case_p_fails_before_any_compute(
    tmp_path: Path,
) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("curve_seed: 3\n")
    results = tmp_path / "results"
    done, notebook = run_notebook(tmp_path, results, "-f", str(params), "-p", "DESK_HEIGHT", "0.7")
    assert done.returncode != 0
    assert (
        "unknown parameter(s) curve_seed (did you mean curve_seeds?), DESK_HEIGHT (did you mean desk_height?)"
        in done.stdout + done.stderr
    )
    # The failing cell is the one that builds the config: nothing after it ran, nothing was written.
    assert "config_from_parameters" in executed_code_cells(notebook)[-1]
    assert not results.exists()


@pytest.mark.slow
def test_papermill_python_api_with_an_undeclared_private_parameter_fails_before_any_compute(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import papermill

    results = tmp_path / "results"
    monkeypatch.setenv("HIPREF_RESULTS_DIR", str(results))
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(papermill.PapermillExecutionError, match=r"unknown parameter\(s\) _desk_height"):
        papermill.execute_notebook(
            str(ROOT / "notebooks" / "05_controllers.ipynb"),
            str(tmp_path / "out.ipynb"),
            parameters={"_desk_height": 0.7},
            kernel_name="hipref",
            cwd=str(ROOT / "notebooks"),
            progress_bar=False,
        )
    assert not results.exists()


CHECKS = {"check_parameters", "config_from", "config_from_parameters", "check_writable", "globals"}


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_notebook_checks_parameters_and_results_directory_before_anything_else(notebook: Path) -> None:
    first = {"source": first_code_cell(notebook)}
    body = [
        n for n in ast.parse("".join(first["source"])).body if not isinstance(n, ast.Import | ast.ImportFrom)
    ]
    called = [
        {c.func.id for c in ast.walk(statement) if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)}
        for statement in body
    ]
    checks = 0
    while checks < len(called) and called[checks] and called[checks] <= CHECKS:
        checks += 1
    done = set().union(*called[:checks])
    assert "check_writable" in done, f"{notebook.name}: the results directory is not checked first"
    assert done & {"check_parameters", "config_from_parameters"}, f"{notebook.name}: parameters unchecked"


def test_imported_constants_are_not_taken_for_parameters() -> None:
    cell = namespace({"seeds": int}, seeds=2, DOMAINS={"wiping": 1}, PAPER_TABLE3={0.1: 0.19})
    assert config_from_parameters(R2Config, cell).seeds == 2
    with pytest.raises(ValueError, match="unknown parameter"):
        config_from_parameters(R2Config, namespace({"seeds": int}, seeds=2, DOMAINS={}, domainz=["wiping"]))
