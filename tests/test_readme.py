"""The README's generated numbers are what results/ gives, and documentation naming a profile's value names
the value params/ holds."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest
import yaml

from hipref import readme
from tests.test_notebooks import parameter_sources

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


@pytest.fixture(scope="module")
def sections() -> dict[str, str]:
    return readme.render(ROOT / "results", ROOT)


def test_every_generated_number_of_the_readme_is_what_results_give(sections: dict[str, str]) -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme.differences(text, sections) == [], "run `make readme` after the results change"


def test_one_changed_number_in_a_copy_of_the_readme_fails_the_check(
    sections: dict[str, str], tmp_path: Path
) -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    start = text.index("<!-- generated: findings -->")
    # The first number of the findings table: the force of admittance at its lowest.
    table = text.index("| admittance gives", start)
    number = re.compile(r"\d+").search(text, text.index("|", table + 2))
    assert number is not None
    changed = text[: number.start()] + str(int(number[0]) + 1) + text[number.end() :]
    assert readme.differences(changed, sections) != []
    copy = tmp_path / "README.md"
    copy.write_text(changed, encoding="utf-8")
    assert readme.main(["--check", "--readme", str(copy)]) == 1
    copy.write_text(text, encoding="utf-8")
    assert readme.main(["--check", "--readme", str(copy)]) == 0
    # `make readme` restores the number from results/.
    copy.write_text(changed, encoding="utf-8")
    assert readme.main(["--readme", str(copy)]) == 0 and copy.read_text(encoding="utf-8") == text


PROFILE_VALUE = re.compile(r"\b(full|quick) profile:? (\d+(?:\.\d+)?)\b(?! ?%)")
"""'full profile: 4', 'quick profile 2': documentation naming a profile's value of the parameter it
documents (for a list, its number of values)."""


def _parameter_docs(notebook: Path) -> dict[str, str]:
    """Each parameter of the notebook's parameters cell with its comment."""
    cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
    (cell,) = [c for c in cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    docs = {}
    for line in "".join(cell["source"]).splitlines():
        found = re.match(r"(\w+)\s*:[^=]+=[^#]*#(.*)$", line)
        if found:
            docs[found[1]] = found[2]
    return docs


def _field_docs(config: type) -> dict[str, str]:
    """Each field of a config dataclass (and its bases) with the docstring below it."""
    import inspect

    docs: dict[str, str] = {}
    for klass in reversed(config.__mro__[:-1]):
        try:
            body = ast.parse(inspect.getsource(klass)).body[0]
        except (OSError, TypeError):
            continue
        assert isinstance(body, ast.ClassDef)
        for field, doc in zip(body.body, body.body[1:], strict=False):
            if (
                isinstance(field, ast.AnnAssign)
                and isinstance(field.target, ast.Name)
                and isinstance(doc, ast.Expr)
                and isinstance(doc.value, ast.Constant)
                and isinstance(doc.value.value, str)
            ):
                docs[field.target.id] = doc.value.value
    return docs


def _documented(notebook: Path) -> list[tuple[str, str, str, str]]:
    """(where, parameter, profile, value) for every profile value the notebook's parameters name."""
    found = []
    for name, doc in _parameter_docs(notebook).items():
        found += [(f"{notebook.name} parameter", name, p, v) for p, v in PROFILE_VALUE.findall(doc)]
    for source in parameter_sources(notebook):
        prefix, config = source if isinstance(source, tuple) else ("", source)
        for field, doc in _field_docs(config).items():
            found += [
                (f"{config.__name__}.{field}", prefix + field, p, v) for p, v in PROFILE_VALUE.findall(doc)
            ]
    return found


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_documentation_naming_a_profiles_value_names_what_params_holds(notebook: Path) -> None:
    wrong = []
    for where, name, profile, value in _documented(notebook):
        params = yaml.safe_load((ROOT / "params" / profile / f"{notebook.stem}.yaml").read_text())
        if name not in params:
            continue  # the profile keeps the default; the config's own test checks defaults
        held = params[name]
        held = len(held) if isinstance(held, list) else held
        if float(value) != float(held):
            wrong.append(
                f"{where} says {profile} profile {value}, params/{profile}/{notebook.stem}.yaml has {held}"
            )
    assert wrong == []


def test_the_check_of_profile_values_reads_every_kind_of_documentation() -> None:
    # Notebook 01's seeds are documented in its parameters cell and in R1Config's docstring.
    found = {(where.split()[-1], name, profile) for where, name, profile, _ in _documented(NOTEBOOKS[0])}
    assert ("parameter", "seeds", "full") in found and ("R1Config.seeds", "seeds", "full") in found


ALLOWED_DIGITS = re.compile(
    r"`[^`]*`"  # file names: results/tables/08_si_sensitivity.csv
    r"|\(Figs?\. [^)]*\)|Table 3|Eq\. \d|A\.\d|Algorithm \d"  # the paper: figures, tables, equations
    r"|[Nn]otebooks? \d\d(?:-\d\d)?(?:, \d\d)*"  # the study's notebooks
    r"|per 100 episodes"  # the unit of a slope over the episodes
)
"""What a findings template may write in digits: references to the paper and to the study's notebooks and
files, and units. Every other number is a placeholder filled from `results/`."""


def _typed_numbers(template: str) -> list[str]:
    """The digits of a template outside its placeholders, the allowed references and each table row's first
    cell (the paper's claim, quoted)."""
    text = re.sub(r"\{[a-z0-9_]+\}", "", template)
    text = re.sub(r"^\| [^|]* \|", "|", text, flags=re.M)
    text = ALLOWED_DIGITS.sub("", text)
    return [m.group(0) for m in re.finditer(r".{0,30}\d.{0,10}", text)]


@pytest.mark.parametrize("name", readme.SECTIONS)
def test_the_findings_templates_type_no_number(name: str) -> None:
    template = (ROOT / "hipref" / f"readme_{name}.md").read_text(encoding="utf-8")
    assert _typed_numbers(template) == []


def test_a_typed_number_in_a_template_is_found() -> None:
    allowed = "| claim at 10 % (Fig. 2c) | {verdict}: notebook 02's {n} cells (Eq. 2, `12_task.csv`) |"
    assert _typed_numbers(allowed) == []
    typed = _typed_numbers(allowed.replace("{n}", "72"))
    assert len(typed) == 1 and "72" in typed[0]


def test_every_reading_of_algorithm_4_has_its_name_in_the_readme() -> None:
    from hipref.learners.sysid import PRETRAIN_LOSSES
    from hipref.readme_beyond import LOSSES

    assert set(LOSSES) == set(PRETRAIN_LOSSES)
