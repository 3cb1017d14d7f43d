"""The sensitivity study's cells (`hipref.experiments.sensitivity`, notebook 08), built without running
them: every variant's runs are paired on the same environments, and a variant that changes only how SI is
fine-tuned shares the default's OSI runs while one that changes pretraining does not."""

from __future__ import annotations

from collections import Counter

from hipref.experiments.sensitivity import COTEACHING_VARIANTS, VARIANTS, SensitivityConfig, cells

CONFIG = SensitivityConfig(variants=tuple(VARIANTS), heights=(0.6, 0.8), masses=(12.0,), seeds=2, noise=0.3)


def test_every_variants_runs_are_paired_on_the_same_environments() -> None:
    for variant in VARIANTS:
        runs = cells(CONFIG, variant)
        settings = {(run.method, run.noise) for run in runs}
        expected = {("osi", 0.0), ("pesi", 0.0)}
        if variant in COTEACHING_VARIANTS:
            expected |= {("pesi", 0.3), ("co_pesi", 0.3)}
        assert settings == expected, variant
        # Each setting on the same (domain, truth, seed): 2 heights + 1 mass, 2 seeds each.
        environments = {
            setting: Counter(
                (r.domain, r.ground_truth, r.seed) for r in runs if (r.method, r.noise) == setting
            )
            for setting in settings
        }
        first = next(iter(environments.values()))
        assert sum(first.values()) == (2 + 1) * 2 and max(first.values()) == 1
        assert all(counts == first for counts in environments.values()), variant


def test_a_fine_tuning_variant_shares_the_defaults_osi_runs_and_a_pretraining_variant_does_not() -> None:
    def osi(variant: str) -> set[object]:
        return {run for run in cells(CONFIG, variant) if run.method == "osi"}

    default = osi("default")
    for variant in (
        "belief_candidates",
        "pr_over_phi",
        "last_layer",
        "learning_rate_0.05",
        "reset_every_step",
    ):
        assert osi(variant) == default, variant  # cache hits: OSI is not fine-tuned by preferences
    for variant in ("paper_a7", "pretrain_expectation", "previous_design"):
        assert not osi(variant) & default, variant  # another pretrained model, so other runs
    # The fine-tuning variants' PESI runs differ from the default's: the variant reaches the runs.
    pesi = {run for run in cells(CONFIG, "default") if run.method == "pesi"}
    assert not {run for run in cells(CONFIG, "last_layer") if run.method == "pesi"} & pesi
