"""How the README writes a verdict, a signed number and a difference with its interval."""

from __future__ import annotations

import ast
import json
from pathlib import Path
from typing import Any

import pandas as pd

from hipref import verdicts

WORDS = {
    "yes": "holds",
    "no": "no",
    "no difference detected": "no difference detected",
    "too few environments to decide": "too few environments to decide",
}
"""How each verdict of `hipref.verdicts` reads at the start of a finding."""


def signed(value: float, digits: int) -> str:
    """`value` with its sign, as the README writes it (a true minus sign)."""
    return f"{value:+.{digits}f}".replace("-", "\N{MINUS SIGN}")


def interval(d: verdicts.Difference, unit: str, digits: int, scale: float = 1.0) -> str:
    """'−1.9 cm (CI −2.8 to −1.2)', or without the interval over too few environments to draw one."""
    mean = f"{signed(scale * d.mean, digits)}{unit}"
    if d.n < verdicts.MIN_ENVIRONMENTS:
        return f"{mean}, no interval over {d.n} environments"
    return f"{mean} (CI {signed(scale * d.low, digits)} to {signed(scale * d.high, digits)})"


def slope_text(t: verdicts.Trend, unit: str, digits: int, scale: float) -> str:
    """A slope with its interval, as `interval` writes a difference."""
    return interval(verdicts.Difference(t.slope, t.low, t.high, t.n), unit, digits, scale)


def significant_steps(table: pd.DataFrame, *, increasing: bool) -> str:
    """'k of K': the steps whose whole interval lies on the claimed side of zero."""
    held = (table["low"] > 0) if increasing else (table["high"] < 0)
    return f"{int(held.sum())} of {len(table)}"


def csv(results: Path, name: str) -> pd.DataFrame:
    """A CSV file of the results directory."""
    return pd.read_csv(results / name)


UNITS = {"wiping": (" cm", 100.0, 1), "pushing": (" kg", 1.0, 2)}
"""How each domain's parameter error is written: unit, scale from SI units and digits."""
FINE_UNITS = {"wiping": (" mm", 1000.0, 2), "pushing": (" kg", 1.0, 3)}
"""How each domain's small differences of error are written (notebook 11's learners against PESI)."""


def percent(level: float) -> str:
    """'20 %': a share as the README writes it."""
    return f"{100 * level:.0f} %"


def ran_with(results: Path, notebook: str) -> dict[str, Any]:
    """The parameters the committed results of `notebook` were run with: its executed copy's parameters
    cell, overridden by the cell papermill injected."""
    cells = json.loads((results / "notebooks" / f"{notebook}.ipynb").read_text(encoding="utf-8"))["cells"]
    out: dict[str, Any] = {}
    for tag in ("parameters", "injected-parameters"):
        for cell in cells:
            if tag not in cell.get("metadata", {}).get("tags", []):
                continue
            for node in ast.parse("".join(cell["source"])).body:
                if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    for target in targets:
                        if isinstance(target, ast.Name):
                            out[target.id] = ast.literal_eval(node.value)
    return out


def in_domains(values: dict[str, str]) -> str:
    """'X in wiping and Y in pushing'."""
    return f"{values['wiping']} in wiping and {values['pushing']} in pushing"
