"""The R3 study's plumbing: paired cells, refused bad parameters, and the bootstrap verdicts."""

import pandas as pd
import pytest

from hipref.experiments.r3_copesi import R3Config, cells, final_difference, verdict


def test_both_methods_share_every_environment() -> None:
    config = R3Config(domains=("pushing",), noise_levels=(0.2,), seeds=3)
    grid = cells(config)
    environments = sorted(config.environments("pushing"))
    assert len(environments) == len(config.masses) * 3
    assert len(grid) == 2 * len(environments)
    for method in ("pesi", "co_pesi"):
        assert sorted((c.ground_truth, c.seed) for c in grid if c.method == method) == environments


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("domains", ("kitchen",)),
        ("noise_levels", (20,)),
        ("seeds", 0),
        ("eval_every", 500),
        ("claim_episodes", (50,)),
        ("claim_episodes", (99,)),
        ("claim_episodes", (33, 33)),
    ],
)
def test_a_bad_parameter_is_refused_with_its_name(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        R3Config(**{field: value})


TRUTHS = (11.0, 17.0)


def _rows(co_error: list[float], co_success: list[float]) -> pd.DataFrame:
    """PESI at error 1.0 and success 0.5 everywhere; CO-PESI's values listed per environment. Seeds repeat
    across the true masses, as in `R3Config.environments`, so only (truth, seed) identifies a run."""
    environments = [(truth, s) for truth in TRUTHS for s in range(len(co_error) // len(TRUTHS))]
    pesi = [("pesi", truth, s, 1.0, 0.5) for truth, s in environments]
    co = [("co_pesi", t, s, e, r) for (t, s), e, r in zip(environments, co_error, co_success, strict=True)]
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
                "ground_truth": truth,
            }
            for m, truth, s, e, r in pesi + co
            for k, v in (("param_error", e), ("success_rate", r))
        ]
    )


def test_a_consistent_improvement_is_better_and_a_mixed_one_is_no_difference_detected() -> None:
    better = _rows([0.5, 0.6, 0.4, 0.5, 0.45, 0.55], [0.8, 0.9, 0.7, 0.8, 0.75, 0.85])
    assert final_difference(better, "pushing", 0.2, "param_error")[:1] == pytest.approx((-0.5,))
    assert final_difference(better, "pushing", 0.2, "param_error")[3] == 6
    assert verdict(better, "pushing", 0.2, "better")[0] == "yes"
    assert verdict(better, "pushing", 0.2, "no difference")[0] == "no"
    mixed = _rows([0.5, 1.5, 0.8, 1.2, 0.7, 1.3], [0.8, 0.2, 0.6, 0.4, 0.7, 0.3])
    assert verdict(mixed, "pushing", 0.2, "better")[0] == "no difference detected"
    assert verdict(mixed, "pushing", 0.2, "no difference")[0] == "yes"


def test_equal_runs_are_not_better_and_one_metric_alone_is_not_enough() -> None:
    equal = _rows([1.0] * 6, [0.5] * 6)
    assert verdict(equal, "pushing", 0.2, "better")[0] == "no difference detected"
    assert verdict(equal, "pushing", 0.2, "no difference")[0] == "yes"
    error_only = _rows([0.5, 0.6, 0.4, 0.5, 0.45, 0.55], [0.5] * 6)
    assert verdict(error_only, "pushing", 0.2, "better")[0] == "no difference detected"
    # A lower error bought with a lower success contradicts 'better on both'.
    worse_success = _rows([0.5, 0.6, 0.4, 0.5, 0.45, 0.55], [0.3, 0.2, 0.3, 0.25, 0.3, 0.2])
    assert verdict(worse_success, "pushing", 0.2, "better")[0] == "no"


def test_fewer_than_five_environments_are_too_few_to_decide() -> None:
    clear = _rows([0.5, 0.6, 0.4, 0.5], [0.8, 0.9, 0.7, 0.8])
    assert verdict(clear, "pushing", 0.2, "better")[0] == "too few environments to decide"
    assert verdict(clear, "pushing", 0.2, "no difference")[0] == "too few environments to decide"


def test_the_verdict_pairs_runs_by_environment_whatever_the_row_order() -> None:
    rows = _rows([0.5, 0.6, 0.4, 0.5, 0.45, 0.55], [0.8, 0.9, 0.7, 0.8, 0.75, 0.85])
    shuffled = rows.sample(frac=1.0, random_state=0)
    assert verdict(shuffled, "pushing", 0.2, "better") == verdict(rows, "pushing", 0.2, "better")
    with pytest.raises(ValueError, match="no rows for domain='wiping'"):
        final_difference(rows, "wiping", 0.2, "param_error")
    with pytest.raises(ValueError, match="co_pesi_estimated"):
        final_difference(rows, "pushing", 0.2, "param_error", baseline="co_pesi_estimated")


def test_a_claim_is_tested_at_the_horizon_it_names() -> None:
    # CO-PESI better than PESI after 99 episodes, the same after 33: each horizon gets its own verdict.
    late = _rows([0.5, 0.6, 0.4, 0.5, 0.45, 0.55], [0.8, 0.9, 0.7, 0.8, 0.75, 0.85])
    early = late.assign(episode=33)
    early.loc[early.method == "co_pesi", "value"] = early.loc[early.method == "pesi", "value"].to_numpy()
    rows = pd.concat([early, late], ignore_index=True)
    assert verdict(rows, "pushing", 0.2, "better", episode=99)[0] == "yes"
    assert verdict(rows, "pushing", 0.2, "better")[0] == "yes"
    held, text = verdict(rows, "pushing", 0.2, "better", episode=33)
    assert held == "no difference detected" and "after 33 episodes" in text
    assert R3Config(episodes=66, claim_episodes=(33, 66)).claim_episodes == (33, 66)
