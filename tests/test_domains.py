"""The domain registry (`hipref.experiments.domains`): SI's candidates cover exactly the range each task
accepts, a run learns in its domain's batches (Table 2), the outcome metric a study shows is the measure
that decides the task's success, and a study's per-domain fields are read from the right place."""

from __future__ import annotations

import numpy as np
import pytest

from hipref.experiments import si_methods
from hipref.experiments.controllers import ControllersConfig
from hipref.experiments.domains import DOMAINS, domain_spec, estimate_error_grids, truth_grids
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_run import SIRun
from hipref.learners.sysid import SIModel


def test_an_unknown_domain_is_refused_naming_the_known_ones() -> None:
    with pytest.raises(ValueError, match="juggling") as refused:
        domain_spec("juggling")
    assert all(name in str(refused.value) for name in DOMAINS)
    assert [domain_spec(name).name for name in DOMAINS] == list(DOMAINS)


@pytest.mark.parametrize("domain", list(DOMAINS))
def test_si_candidates_span_exactly_the_range_the_task_accepts(domain: str) -> None:
    spec = domain_spec(domain)
    task = spec.make_task()
    values = spec.candidates.values
    assert (values[0], values[-1]) == pytest.approx(task.parameter_range)
    assert np.all(np.diff(values) > 0)
    # Every candidate can be executed in every world of the range, and nothing past either end.
    layout = task.sample_layout(np.random.default_rng(0))
    low, high = task.parameter_range
    task.episode_metrics(low, high, layout)
    task.episode_metrics(high, low, layout)
    step = values[1] - values[0]
    for outside in (low - step, high + step):
        with pytest.raises(ValueError):
            task.episode_metrics((low + high) / 2, outside, layout)


ACCEPTABLE = {
    "wiping": lambda task, force: task.config.force_band[0] <= force <= task.config.force_band[1],
    "pushing": lambda task, distance: 0.0 <= distance <= task.config.scene.goal_tolerance,
}
"""Where each domain's outcome must lie for the task to succeed: wiping's contact force inside the safe
band, pushing's distance of the cube to its goal within the goal's tolerance."""


@pytest.mark.parametrize("domain", list(DOMAINS))
def test_the_outcome_metric_is_the_measure_a_wrong_estimate_pushes_out_of_bounds(domain: str) -> None:
    spec = domain_spec(domain)
    task = spec.make_task()
    low, high = task.parameter_range
    truth, off = (low + high) / 2, (high - low) / 4
    layout = task.sample_layout(np.random.default_rng(2))  # in pushing, the true mass stops the cube short
    outcome = {
        e: task.episode_metrics(truth, e, layout)[spec.outcome_metric]
        for e in (truth - off, truth, truth + off)
    }
    assert ACCEPTABLE[domain](task, outcome[truth])
    assert not ACCEPTABLE[domain](task, outcome[truth - off])
    assert not ACCEPTABLE[domain](task, outcome[truth + off])


@pytest.mark.parametrize("domain", list(DOMAINS))
def test_a_run_learns_in_its_domains_batches_and_refreshes_at_its_domains_frequency(domain: str) -> None:
    spec = domain_spec(domain)
    cell = SIRun(
        domain, "co_pesi", float(spec.candidates.values[len(spec.candidates.values) // 2]), noise=0.2
    )
    learner = si_methods.make_learner(cell, SIModel(9, spec.candidates, hidden_sizes=(8,)), 0)
    assert learner.config.batch_size == learner.config.start_size == spec.batch_size
    assert learner.filter.setting.refresh_frequency == spec.refresh_frequency


def test_table_2s_batch_sizes_differ_by_domain() -> None:
    assert (DOMAINS["wiping"].batch_size, DOMAINS["wiping"].refresh_frequency) == (16, 16)
    assert (DOMAINS["pushing"].batch_size, DOMAINS["pushing"].refresh_frequency) == (32, 32)


def test_a_studys_truths_and_estimate_errors_are_read_from_each_domains_own_field() -> None:
    study = SIStudy(heights=(0.55, 0.85), masses=(9.0,))
    assert truth_grids(study) == {"wiping": (0.55, 0.85), "pushing": (9.0,)}
    config = ControllersConfig(height_errors=(-0.05, 0.0, 0.05), mass_errors=(-4.0, 0.0, 4.0, 5.0))
    assert estimate_error_grids(config) == {"wiping": (-0.05, 0.0, 0.05), "pushing": (-4.0, 0.0, 4.0, 5.0)}
