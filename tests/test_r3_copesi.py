"""The R3 study's plumbing: paired cells, refused bad parameters, and the bootstrap verdicts."""

import pandas as pd
import pytest

from hipref.experiments.r3_copesi import R3Config, cells, final_difference, run_seeds, verdict


def test_both_methods_share_every_environment_seed() -> None:
    config = R3Config(domains=("pushing",), noise_levels=(0.2,), seeds=3)
    grid = cells(config)
    assert len(grid) == 2 * 3
    by_method = {m: sorted(c.seed for c in grid if c.method == m) for m in ("pesi", "co_pesi")}
    assert by_method["pesi"] == by_method["co_pesi"] == sorted(run_seeds(config))
    assert run_seeds(config) == run_seeds(R3Config(seeds=3))


@pytest.mark.parametrize(
    ("field", "value"),
    [("domains", ("kitchen",)), ("noise_levels", (20,)), ("seeds", 0), ("eval_every", 500)],
)
def test_a_bad_parameter_is_refused_with_its_name(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        R3Config(**{field: value})


def _rows(co_error: list[float], co_success: list[float]) -> pd.DataFrame:
    pesi = [("pesi", s, 1.0, 0.5) for s in range(len(co_error))]
    co = [("co_pesi", s, e, r) for s, (e, r) in enumerate(zip(co_error, co_success, strict=True))]
    return pd.DataFrame(
        [
            {
                "domain": "pushing",
                "method": m,
                "noise": 0.2,
                "seed": s,
                "episode": 99,
                "metric": k,
                "value": v,
            }
            for m, s, e, r in pesi + co
            for k, v in (("param_error", e), ("success_rate", r))
        ]
    )


def test_a_consistent_improvement_is_better_and_a_mixed_one_is_no_difference() -> None:
    better = _rows([0.5, 0.6, 0.4, 0.5], [0.8, 0.9, 0.7, 0.8])
    assert final_difference(better, "pushing", 0.2, "param_error")[:1] == pytest.approx((-0.5,))
    assert verdict(better, "pushing", 0.2, "better")[0] == "yes"
    mixed = _rows([0.5, 1.5, 0.8, 1.2], [0.8, 0.2, 0.6, 0.4])
    assert verdict(mixed, "pushing", 0.2, "better")[0] == "no"
    assert verdict(mixed, "pushing", 0.2, "no difference")[0] == "yes"
