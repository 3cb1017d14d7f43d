"""The Bayesian preference learner, its answer models and the query rules: properties that fail when the
algebra is wrong."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from hipref.learners.answer_models import (
    ANSWER_KINDS,
    PERSON_LAPSE,
    AnswerModel,
    model_family,
    person_family,
    told,
)
from hipref.learners.bayes import BayesConfig, BayesLearner, PreferencePosterior, answer_column
from hipref.learners.estimates import expected_success, most_expected, most_within
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.queries import all_pairs, choose_pair, pair_scores, worth_asking
from hipref.learners.sysid import CandidateSet, SIModel
from hipref.teachers.models import TeacherModel
from hipref.teachers.preference import EQUAL, SKIP, PreferenceQuery, ScriptedPreferenceTeacher

SMALL = CandidateSet(low=0.0, high=1.0, resolution=0.25)  # 5 candidates
GRID = CandidateSet(low=0.5, high=0.9, resolution=0.01)


def _models() -> list[AnswerModel]:
    return [
        AnswerModel("flip", flip=0.2),
        AnswerModel("stochastic", beta=5.0, flip=0.1),
        AnswerModel("skip", skip_distance=0.3, flip=0.1),
        AnswerModel("equal", equal_margin=0.1),
        AnswerModel("myopic", spread=0.2),
        AnswerModel("distance", confusion_max=0.4, confusion_width=0.1),
        AnswerModel("equal", equal_margin=0.05, flip=0.1, lapse=0.05),
        AnswerModel("stochastic", beta=5.0, lapse=0.2),
    ]


@pytest.mark.parametrize("model", _models(), ids=lambda m: m.kind)
def test_every_answer_models_probabilities_sum_to_one_over_labels_skip_and_equal(model: AnswerModel) -> None:
    rng = np.random.default_rng(0)
    n = 2 if model.kind == "distance" else 3
    offsets = rng.uniform(-1, 1, size=(200, n))
    probs = model.probabilities(offsets)
    assert probs.shape == (200, n + 2)
    assert np.all(probs >= 0)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, atol=1e-12)


def test_the_posterior_is_the_normalised_product_of_the_answers_likelihoods() -> None:
    models = (AnswerModel("flip", flip=0.1), AnswerModel("stochastic", beta=4.0))
    posterior = PreferencePosterior(SMALL, models, refine=2)
    answers = [((0.0, 1.0), 0), ((0.25, 0.75), 1), ((0.5, 1.0), 0), ((0.0, 0.5), 1)]
    for candidates, column in answers:
        posterior.update(candidates, column)
    # Brute force: for each model and point, the product of each answer's probability, priors 1/2 each.
    brute = np.ones((2, posterior.cells.size)) / 2
    for m, model in enumerate(models):
        for c, phi in enumerate(posterior.cells):
            for candidates, column in answers:
                offsets = (np.array(candidates) - phi) / (SMALL.high - SMALL.low)
                brute[m, c] *= model.probabilities(offsets[None, :])[0, column]
    np.testing.assert_allclose(posterior.joint(), brute / brute.sum(), rtol=1e-10)


@pytest.mark.parametrize("kind", ["skip", "equal"])
def test_a_truth_on_a_rules_boundary_allows_the_teachers_answer(kind: str) -> None:
    # Truths on Phi, every pair of Phi: distances land exactly on skip_distance or equal_margin, where the
    # teacher's rounding and the posterior cell's differ; the model must allow whatever the teacher says.
    teacher_model = TeacherModel(kind)
    model = told(teacher_model, 0.0)
    cells = PreferencePosterior(GRID, (model,)).cells
    values = GRID.values
    pairs = np.stack(np.triu_indices(values.size, k=1), axis=1)
    on_boundary = 0
    for truth in np.round(values, 10):
        cell = cells[np.abs(cells - truth).argmin()]
        probs = model.probabilities((values[pairs] - cell) / (GRID.high - GRID.low))
        teacher = ScriptedPreferenceTeacher(truth, 0.0, np.random.default_rng(0), teacher_model, scale=0.4)
        for pair, row in zip(pairs, probs, strict=True):
            query = PreferenceQuery(tuple(float(v) for v in values[pair]), features=np.zeros(0))
            assert row[answer_column(teacher.answer(query), 2)] > 0, (truth, values[pair])
        on_boundary += int(np.sum(probs[:, 2:] == 0.5))
    assert on_boundary > 100  # the boundaries are met, not avoided


def test_with_no_flips_the_support_is_exactly_what_the_answers_allow() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("flip", flip=0.0),))
    truth = 0.6731
    rng = np.random.default_rng(3)
    low, high = GRID.low, GRID.high
    for _ in range(25):
        a, b = rng.choice(GRID.values, size=2, replace=False)
        preferred, other = (a, b) if abs(a - truth) < abs(b - truth) else (b, a)
        posterior.update((a, b), 0 if preferred == a else 1)
        # The truth is on the preferred candidate's side of the midpoint.
        midpoint = (a + b) / 2
        if preferred < other:
            high = min(high, midpoint)
        else:
            low = max(low, midpoint)
    weights = posterior.phi()
    support = posterior.cells[weights > 0]
    inside = (posterior.cells > low + 1e-12) & (posterior.cells < high - 1e-12)
    assert low < truth < high
    assert support.min() >= low - 1e-12 and support.max() <= high + 1e-12
    assert np.all(weights[inside] > 0), "every point strictly inside the allowed interval keeps its mass"
    # And uniform on it: the flip model with e = 0 cannot tell apart points the answers do not separate.
    np.testing.assert_allclose(weights[inside], weights[inside][0])


def test_information_gain_is_largest_for_a_pair_whose_midpoint_is_the_posterior_median() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("flip", flip=0.1),))
    for candidates, column in [((0.5, 0.9), 1), ((0.6, 0.9), 1), ((0.8, 0.6), 1)]:
        posterior.update(candidates, column)
    pairs, scores = pair_scores("information_gain", GRID, posterior.query_points, posterior.query_beliefs())
    weights = posterior.phi()
    median = posterior.cells[np.searchsorted(np.cumsum(weights), 0.5)]
    best = pairs[int(np.argmax(scores))]
    midpoint = GRID.values[best].mean()
    assert abs(midpoint - median) <= GRID.resolution, (midpoint, median)
    # A pair whose midpoint is far from the median tells less.
    far = np.flatnonzero(np.abs(GRID.values[pairs].mean(axis=1) - median) > 0.1)
    assert scores[far].max() < scores.max() - 0.05


def test_a_cant_tell_answer_moves_mass_towards_the_pairs_midpoint() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("equal", equal_margin=0.05),))
    before = posterior.phi()
    posterior.update((0.6, 0.8), answer_column(EQUAL, 2))
    after = posterior.phi()
    near = np.abs(posterior.cells - 0.7) <= 0.01
    far = np.abs(posterior.cells - 0.7) > 0.05
    assert after[near].sum() > before[near].sum()
    assert after[far].sum() == 0.0


def test_a_skipped_answer_says_the_truth_is_far_from_both_candidates() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("skip", skip_distance=0.2),))
    posterior.update((0.85, 0.9), answer_column(SKIP, 2))
    support = posterior.cells[posterior.phi() > 0]
    assert support.max() < 0.85 - 0.2 * 0.4 + 1e-9


def test_an_impossible_answer_under_a_teacher_that_never_errs_is_refused_by_name() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("flip", flip=0.0),))
    posterior.update((0.5, 0.9), 0)  # truth below 0.7
    with pytest.raises(ValueError, match="impossible under every answer model"):
        posterior.update((0.6, 0.9), 1)  # truth above 0.75


def test_a_lapse_gives_every_answer_a_person_can_press_its_share() -> None:
    lapse = 0.06
    rule = AnswerModel("equal", equal_margin=0.05, flip=0.1)
    offsets = np.array([[-0.3, 0.2], [-0.01, 0.01], [0.1, 0.4]])  # outside, inside, outside the window
    plain, slipping = (
        rule.probabilities(offsets),
        AnswerModel("equal", equal_margin=0.05, flip=0.1, lapse=lapse).probabilities(offsets),
    )
    # Each of the two candidates and 'equally good' gets lapse / 3 on top of (1 - lapse) times the rule's.
    np.testing.assert_allclose(slipping[:, [0, 1, -1]], (1 - lapse) * plain[:, [0, 1, -1]] + lapse / 3)
    np.testing.assert_allclose(slipping[:, -2], 0.0)  # no 'skip' button


def test_a_persons_cant_tell_to_pairs_far_apart_is_never_impossible() -> None:
    # Two "can't tell" answers whose midpoints (0.75, 0.6) no truth lies near at once: every model without a
    # lapse refuses the second; the person's learner weighs it and goes on.
    strict = PreferencePosterior(GRID, model_family())
    strict.update((0.6, 0.9), answer_column(EQUAL, 2))
    with pytest.raises(ValueError, match="impossible under every answer model"):
        strict.update((0.5, 0.7), answer_column(EQUAL, 2))
    person = PreferencePosterior(GRID, person_family())
    for pair in ((0.6, 0.9), (0.5, 0.7), (0.8, 0.85), (0.52, 0.55)):
        person.update(pair, answer_column(EQUAL, 2))
    assert np.all(np.isfinite(person.phi())) and person.phi().sum() == pytest.approx(1.0)
    assert {m.lapse for m in person_family()} == {PERSON_LAPSE}
    assert [replace(m, lapse=0.0) for m in person_family()] == list(model_family())


def test_uniform_queries_are_pesis_queries_from_the_same_seed() -> None:
    model = SIModel(4, GRID)
    pesi = PESILearner(model, PESIConfig(), seed=11)
    bayes = BayesLearner(GRID, BayesConfig(), seed=11)
    for _ in range(5):
        # observe draws from the rng as a replayed clip does, so the streams stay in step.
        def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
            return np.full(model.input_dim, phi + rng.random())

        assert pesi.ask(observe).candidates == bayes.ask(observe).candidates


def test_perfect_answers_with_chosen_queries_bisect_to_one_grid_step() -> None:
    # Told the teacher never errs, six answers halve 40 steps of Phi below one: log2(40) = 5.3.
    for truth in (0.537, 0.70, 0.861):
        config = BayesConfig(query_rule="information_gain", answer_models=(AnswerModel(),))
        learner = BayesLearner(GRID, config, seed=2)
        teacher = ScriptedPreferenceTeacher(truth, 0.0, np.random.default_rng(0), scale=0.4)
        for _ in range(6):
            query = learner.ask()
            learner.tell(query, teacher.answer(query))
        assert abs(learner.estimate() - truth) <= GRID.resolution


def test_chosen_pairs_have_their_midpoint_within_the_beliefs_central_half() -> None:
    # A belief spread evenly over [0.6, 0.8] m has its quartiles at 0.65 and 0.75 m.
    posterior = PreferencePosterior(GRID, (AnswerModel(flip=0.1),))
    cells = posterior.query_points
    weights = ((cells >= 0.6) & (cells <= 0.8)).astype(float)
    beliefs = [(posterior.models[0], weights / weights.sum())]
    midpoints = GRID.values[all_pairs(GRID.size)].mean(axis=1)
    asked = worth_asking(GRID, cells, beliefs)
    assert asked is not None
    half_step = GRID.resolution / 2 + 1e-9
    assert midpoints[asked].min() >= 0.65 - half_step and midpoints[asked].max() <= 0.75 + half_step
    # Every pair whose midpoint is at most half a step outside, counted in whole steps (i + j half-steps from
    # 0.5 m): from 0.645 m (29) to 0.755 m (51), none lost to rounding.
    steps = all_pairs(GRID.size).sum(axis=1)
    np.testing.assert_array_equal(asked, np.flatnonzero((steps >= 29) & (steps <= 51)))
    for seed in range(5):
        first, second = choose_pair("information_gain", GRID, cells, beliefs, np.random.default_rng(seed))
        assert abs((GRID.values[first] + GRID.values[second]) / 2 - 0.7) <= half_step


def test_information_gain_asks_about_phi_not_about_the_teacher() -> None:
    # Two flip models (0 and 40 %) weighed alike on two cells, each side of 0.7. A pair whose midpoint lies
    # between the cells tells phi; a pair with both cells on one side tells only which model holds (the
    # answer is right for sure under one, in 60 % under the other), which is worth nothing here.
    posterior = PreferencePosterior(GRID, (AnswerModel(flip=0.0), AnswerModel(flip=0.4)))
    cells = posterior.query_points
    weights = np.zeros(cells.size)
    weights[[np.argmin(np.abs(cells - 0.65)), np.argmin(np.abs(cells - 0.75))]] = 0.25
    beliefs = [(posterior.models[0], weights), (posterior.models[1], weights)]
    pairs, scores = pair_scores("information_gain", GRID, cells, beliefs)
    midpoints = GRID.values[pairs].mean(axis=1)
    separating = (midpoints > 0.65) & (midpoints < 0.75)
    assert scores[separating].min() > 0.1
    on_a_cell = np.isclose(midpoints, 0.65) | np.isclose(midpoints, 0.75)
    assert np.abs(scores[~separating & ~on_a_cell]).max() < 1e-9


def test_told_maps_each_scripted_teacher_to_its_answer_model() -> None:
    assert told(TeacherModel("mistake"), 0.2) == AnswerModel("flip", flip=0.2)
    assert told(TeacherModel("oracle"), 0.0).kind == "flip"
    myopic = told(TeacherModel("myopic", memory=0.9, glimpse_noise=1.3), 0.0)
    assert myopic.spread == pytest.approx(1.3 * np.sqrt(0.1 / 1.9))
    assert {told(TeacherModel(k), 0.0).kind for k in ("stochastic", "skip", "equal", "distance")} <= set(
        ANSWER_KINDS
    )


def test_the_model_family_covers_every_kind_and_its_flip_rates() -> None:
    family = model_family()
    assert {m.kind for m in family} == set(ANSWER_KINDS)
    assert len(set(family)) == len(family)
    assert {m.flip for m in family if m.kind == "flip"} >= {0.0, 0.2, 0.4}


def test_marginal_likelihood_prefers_the_teacher_that_answered() -> None:
    learner = BayesLearner(GRID, BayesConfig(), seed=4)
    teacher = ScriptedPreferenceTeacher(0.66, 0.0, np.random.default_rng(1), TeacherModel("skip"), scale=0.4)
    for _ in range(60):
        query = learner.ask()
        learner.tell(query, teacher.answer(query))
    kinds = learner.posterior.model_posterior()
    assert max(kinds, key=kinds.__getitem__) == "skip"


def test_the_estimate_is_the_value_most_probably_within_one_step_of_the_truth() -> None:
    # 0.4 of the mass on one point, 0.6 spread thinly above: the median lies in the thin part, where no
    # value is within a step of much mass; the default estimate takes the heavy point.
    cells = PreferencePosterior(GRID, (AnswerModel(),)).cells
    weights = np.where(cells >= 0.7 - 1e-9, 1.0, 0.0)
    weights *= 0.6 / weights.sum()
    weights[np.abs(cells - 0.55).argmin()] = 0.4
    assert most_within(cells, weights, GRID.resolution) == pytest.approx(0.55)
    median = cells[np.searchsorted(np.cumsum(weights), 0.5)]
    assert median > 0.7
    # A flat posterior over [0.60, 0.70] (answers of a teacher that never errs): its centre.
    learner = BayesLearner(GRID, BayesConfig(answer_models=(AnswerModel(),)), seed=0)
    learner.tell(PreferenceQuery((0.5, 0.7), features=np.zeros(0)), -1)  # truth above 0.60
    learner.tell(PreferenceQuery((0.6, 0.8), features=np.zeros(0)), 1)  # truth below 0.70
    assert learner.config.estimate == "within_step"
    assert learner.estimate() == pytest.approx(0.65)


def test_a_cell_between_midpoints_is_its_whole_interval_half_of_it_one_step_away() -> None:
    # Most of the mass on the cell standing for (0.70, 0.705), a tail below: read as points, the estimate
    # sits one step below the cell to gather the tail, and misses a truth in the interval's upper half.
    posterior = PreferencePosterior(GRID, (AnswerModel(),))
    cells, stretches = posterior.cells, posterior.stretches
    bulk = int(np.abs(cells - 0.7025).argmin())
    assert (stretches[0][bulk], stretches[1][bulk]) == pytest.approx((0.70, 0.705))
    weights = np.zeros(cells.size)
    weights[bulk] = 0.9
    weights[(cells > 0.68) & (cells < 0.6925)] = 0.1 / 4
    assert most_within(cells, weights, GRID.resolution) == pytest.approx(0.6925)
    estimate = most_within(cells, weights, GRID.resolution, stretches)
    assert abs(estimate - 0.7049) <= GRID.resolution  # every truth of the interval within one step
    # The learner reads its own posterior so.
    learner = BayesLearner(GRID, BayesConfig(answer_models=(AnswerModel(),)), seed=0)
    with np.errstate(divide="ignore"):
        learner.posterior.log_likelihood = np.log(weights)[None, :]
    assert learner.estimate() == pytest.approx(estimate)


def test_expected_success_averages_the_curve_over_each_cells_stretch() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel(),))
    cells, (low, high) = posterior.cells, posterior.stretches
    weights = np.random.default_rng(3).dirichlet(np.full(cells.size, 0.3))
    curve = (np.array([-0.03, -0.01, 0.0, 0.02]), np.array([0.2, 0.9, 1.0, 0.4]))
    # Brute force: each stretch as 2,000 equally spaced points (a point cell as itself).
    fractions = (np.arange(2000) + 0.5) / 2000
    phis = low[:, None] + (high - low)[:, None] * fractions[None, :]
    success = np.interp(cells[:, None, None] - phis[None], *curve, left=0.0, right=0.0).mean(axis=2)
    computed = expected_success(cells, weights, curve, (low, high))
    np.testing.assert_allclose(computed, success @ weights, atol=1e-6)
    # Within one step: a cell's stretch one step away counts half.
    box = (np.array([-1.0, 1.0]) * GRID.resolution * (1 + 1e-9), np.ones(2))
    bulk = int(np.abs(cells - 0.7025).argmin())
    one = np.zeros(cells.size)
    one[bulk] = 1.0
    within = expected_success(cells, one, box, (low, high))
    assert within[np.abs(cells - 0.6925).argmin()] == pytest.approx(0.5, abs=1e-6)
    assert within[np.abs(cells - 0.695).argmin()] == pytest.approx(1.0)


def test_the_most_mass_within_a_step_is_the_expected_success_of_a_box() -> None:
    cells = PreferencePosterior(GRID, (AnswerModel(),)).cells
    step = GRID.resolution
    box = (np.array([-step, step]) * (1 + 1e-9), np.ones(2))
    rng = np.random.default_rng(0)
    stretches = PreferencePosterior(GRID, (AnswerModel(),)).stretches
    for _ in range(50):
        weights = rng.dirichlet(np.full(cells.size, 0.05))
        assert most_within(cells, weights, step) == most_expected(cells, weights, box)
        assert most_within(cells, weights, step, stretches) == most_expected(cells, weights, box, stretches)


def test_the_estimate_is_read_from_every_answer_model_averaged() -> None:
    models = (AnswerModel("flip", flip=0.1), AnswerModel("flip", flip=0.3), AnswerModel("distance"))
    learner = BayesLearner(SMALL, BayesConfig(answer_models=models), seed=0)
    for pair, label in [((0.0, 1.0), 1), ((0.25, 0.5), 1), ((0.0, 0.25), -1), ((0.5, 0.75), -1)]:
        learner.tell(PreferenceQuery(pair, features=np.zeros(0)), label)
    joint = learner.posterior.joint()
    np.testing.assert_allclose(learner.distribution(), joint.sum(axis=0))
    assert joint.sum(axis=1).min() > 0.01  # every model weighs in


def test_the_filter_flags_the_flipped_answers() -> None:
    # Uniform pairs: most are far from the truth, where a flip contradicts the others plainly.
    learner = BayesLearner(GRID, BayesConfig(), seed=0)
    teacher = ScriptedPreferenceTeacher(0.74, 0.2, np.random.default_rng(0), scale=0.4)
    for _ in range(80):
        query = learner.ask()
        learner.tell(query, teacher.answer(query))
    precision, recall = learner.filter_precision_recall(teacher.wrong_labels)
    assert sum(teacher.wrong_labels) >= 10
    assert precision > 0.85 and recall > 0.85


def test_expected_success_estimate_avoids_the_side_that_fails() -> None:
    # A curve that fails for any estimate below the truth; the answers put the truth in [0.60, 0.62]. Only
    # an estimate in [0.62, 0.63] succeeds whatever the truth there: above the posterior median, 0.61.
    curve = (np.array([-0.001, 0.0, 0.03, 0.031]), np.array([0.0, 1.0, 1.0, 0.0]))
    exact = AnswerModel("flip", flip=0.0)
    learners = [
        BayesLearner(
            GRID, BayesConfig(answer_models=(exact,), estimate=estimate), seed=0, success_curve=curve
        )
        for estimate in ("expected_success", "median")
    ]
    for learner in learners:
        learner.tell(PreferenceQuery((0.5, 0.7), features=np.zeros(0)), -1)  # truth above 0.60
        learner.tell(PreferenceQuery((0.6, 0.64), features=np.zeros(0)), 1)  # truth below 0.62
    best, median = (learner.estimate() for learner in learners)
    assert median == pytest.approx(0.61)
    assert 0.62 - 1e-9 <= best <= 0.63 + 1e-9


@pytest.mark.parametrize("rule", ["thompson", "information_gain", "volume_removal"])
def test_pesi_asks_distinct_candidates_of_phi_under_every_chosen_rule(rule: str) -> None:
    model = SIModel(4, GRID)
    learner = PESILearner(model, PESIConfig(candidate_sampling=rule), seed=1)
    query = learner.ask(lambda phi, rng: np.zeros(model.input_dim))
    a, b = query.candidates
    assert a != b and {GRID.index_of(a), GRID.index_of(b)} <= set(range(GRID.size))


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: BayesConfig(query_rule="bisect"), "query_rule"),
        (lambda: BayesConfig(query_rule="information_gain", n_candidates=3), "n_candidates must be 2"),
        (lambda: BayesConfig(estimate="mode"), "estimate"),
        (lambda: BayesConfig(prior="osi"), "prior"),
        (lambda: AnswerModel("flip", flip=1.0), "flip"),
        (lambda: AnswerModel("guess"), "kind"),
        (lambda: BayesLearner(GRID, BayesConfig(estimate="expected_success")), "success_curve"),
        (lambda: BayesLearner(GRID, BayesConfig(prior="si")), "si_model"),
        (lambda: BayesLearner(GRID).estimate(reading="mode"), "reading"),
        (lambda: BayesLearner(GRID).estimate(reading="expected_success"), "success_curve"),
        (lambda: BayesLearner(GRID, success_curve=(np.array([0.0, 0.0]), np.ones(2))), "strictly increasing"),
        (lambda: BayesLearner(GRID, success_curve=(np.array([0.0, 0.1]), np.ones(3))), "one length"),
        (lambda: BayesLearner(GRID, success_curve=(np.array([0.0, 0.1]), np.array([0.5, 1.5]))), r"\[0, 1\]"),
        (lambda: PESIConfig(candidate_sampling="thompson", n_candidates=3), "n_candidates must be 2"),
    ],
)
def test_bad_options_are_refused_by_name(make, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_a_chosen_pair_is_drawn_among_equally_informative_ones() -> None:
    posterior = PreferencePosterior(GRID, (AnswerModel("flip", flip=0.0),))
    pairs = {
        choose_pair(
            "information_gain",
            GRID,
            posterior.query_points,
            posterior.query_beliefs(),
            np.random.default_rng(seed),
        )
        for seed in range(20)
    }
    assert len(pairs) > 1
    for i, j in pairs:
        assert abs((GRID.values[i] + GRID.values[j]) / 2 - 0.7) <= GRID.resolution


def test_answer_columns_of_every_label() -> None:
    assert answer_column(1, 2) == 0 and answer_column(-1, 2) == 1
    assert answer_column(SKIP, 2) == 2 and answer_column(EQUAL, 2) == 3
    assert answer_column(np.array([-0.5, 1.0, -0.5]), 3) == 1
    for bad in (0, 2, np.array([1.0, 1.0])):
        with pytest.raises(ValueError):
            answer_column(bad, 2)


def test_with_sis_prior_and_no_answer_the_posterior_is_sis_distribution() -> None:
    model = SIModel(4, GRID, seed=3)
    learner = BayesLearner(GRID, BayesConfig(prior="si"), seed=0, si_model=model)
    tau = np.array([0.1, -0.3, 0.7, 0.2])
    weights = learner.distribution(tau)
    nearest = np.rint((learner.posterior.cells - GRID.low) / GRID.resolution).astype(int)
    per_candidate = np.bincount(nearest, weights=weights, minlength=GRID.size)
    with torch.no_grad():
        expected = model.distribution(torch.as_tensor(tau, dtype=torch.float32)).double().numpy()
    np.testing.assert_allclose(per_candidate, expected, rtol=1e-6)
    # An answer then reweighs SI's belief: the truth below 0.7 takes all the mass of a never-erring teacher.
    told = BayesLearner(GRID, BayesConfig(prior="si", answer_models=(AnswerModel(),)), seed=0, si_model=model)
    told.tell(PreferenceQuery((0.6, 0.8), features=np.zeros(0)), 1)
    assert told.distribution(tau)[told.posterior.cells > 0.7 + 1e-9].sum() == 0.0


def test_n_candidate_answers_update_the_posterior_as_eq_3_labels() -> None:
    learner = BayesLearner(GRID, BayesConfig(n_candidates=3), seed=1)
    teacher = ScriptedPreferenceTeacher(0.81, 0.0, np.random.default_rng(0), scale=0.4)
    for _ in range(30):
        query = learner.ask()
        learner.tell(query, teacher.answer(query))
    assert abs(learner.estimate() - 0.81) <= 2 * GRID.resolution
    with pytest.raises(ValueError, match="pairs only"):
        BayesLearner(GRID, BayesConfig(n_candidates=3, answer_models=(AnswerModel("distance"),)))
