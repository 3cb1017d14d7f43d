"""The myopic teacher's picture as a hidden chain: properties that fail when the algorithm is wrong."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hipref.learners import pictures
from hipref.learners.answer_models import AnswerModel, model_family, told
from hipref.learners.bayes import BayesConfig, BayesLearner, PreferencePosterior
from hipref.learners.pictures import PictureChain
from hipref.learners.sysid import CandidateSet
from hipref.teachers.models import TeacherModel
from hipref.teachers.preference import ScriptedPreferenceTeacher

SMALL = CandidateSet(low=0.0, high=1.0, resolution=0.25)  # 5 candidates
GRID = CandidateSet(low=0.5, high=0.9, resolution=0.01)


def test_without_memory_the_chain_gives_each_answer_its_marginal_law() -> None:
    cells = np.linspace(GRID.low, GRID.high, 161)
    chain = PictureChain(AnswerModel("myopic", spread=0.3, memory=1e-9), GRID, cells)
    for candidates in [(0.6, 0.7), (0.7, 0.6), (0.55, 0.62, 0.8)]:
        values = np.array(candidates)
        marginal = AnswerModel("myopic", spread=0.3).probabilities((values[None, :] - cells[:, None]) / 0.4)
        for column in range(values.size):
            log_p, _ = chain.step(values, column)
            np.testing.assert_allclose(np.exp(log_p), marginal[:, column], atol=6e-4)


def test_the_chains_likelihood_of_answers_is_the_sum_over_every_path_of_the_picture(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(pictures, "BINS", 7)
    cells = np.linspace(SMALL.low, SMALL.high, 9)
    model = AnswerModel("myopic", spread=0.2, memory=0.7, flip=0.1, lapse=0.05)
    chain = PictureChain(model, SMALL, cells)
    answers = [((0.0, 1.0), 0), ((0.25, 0.5, 0.75), 2), ((0.75, 0.5), 1)]
    total = np.zeros(cells.size)
    for candidates, column in answers:
        log_p, chain.state = chain.step(np.array(candidates), column)
        total += log_p
    fresh = PictureChain(model, SMALL, cells)
    start = fresh.state[0]
    likelihoods = [fresh.probabilities(np.array(c))[..., column] for c, column in answers]  # (cells, bins)
    brute = np.zeros(cells.size)
    for path in itertools.product(range(7), repeat=len(answers) + 1):
        weight = start[path[0]] * np.prod([fresh.transition[a, b] for a, b in itertools.pairwise(path)])
        brute += weight * np.prod([lik[:, j] for lik, j in zip(likelihoods, path[1:], strict=True)], axis=0)
    np.testing.assert_allclose(np.exp(total), brute, rtol=1e-10)


def test_a_run_of_answers_on_one_side_is_likelier_with_memory_than_read_as_independent() -> None:
    cells = np.array([0.7])
    pair = np.array([0.65, 0.75])  # the truth on the midpoint: either answer alone is as likely
    chain = PictureChain(AnswerModel("myopic", spread=0.3, memory=0.9), GRID, cells)
    run = 0.0
    for _ in range(10):
        log_p, chain.state = chain.step(pair, 0)
        run += float(log_p[0])
    assert run > 10 * np.log(0.5) + 3.0


def test_memory_is_for_the_myopic_model_and_the_learner_told_the_myopic_teacher_is_told_its_memory() -> None:
    with pytest.raises(ValueError, match="memory is for kind 'myopic' only"):
        AnswerModel("stochastic", memory=0.5)
    with pytest.raises(ValueError, match="picture chain is for a myopic answer model with memory"):
        PictureChain(AnswerModel("myopic"), GRID, np.array([0.7]))
    assert told(TeacherModel("myopic", memory=0.8), 0.0).memory == 0.8
    assert {m.memory for m in model_family() if m.kind == "myopic"} == {0.0, TeacherModel("myopic").memory}


def test_an_impossible_answer_leaves_the_pictures_chain_as_it_was() -> None:
    models = (AnswerModel("myopic", spread=0.3, memory=0.9),)
    posterior = PreferencePosterior(GRID, models)
    posterior.update((0.6, 0.8), 0)
    state = posterior.chains[0].state.copy()
    with pytest.raises(ValueError, match="impossible under every answer model"):
        posterior.update((0.6, 0.8), 3)  # 'equally good': no myopic teacher says it
    np.testing.assert_array_equal(posterior.chains[0].state, state)
    assert len(posterior.answers) == 1


@pytest.mark.parametrize("seed", [0, 1])
def test_the_learner_told_nothing_finds_the_myopic_teacher_from_its_answers(seed: int) -> None:
    teacher_model = TeacherModel("myopic")
    teacher = ScriptedPreferenceTeacher(0.75, 0.0, np.random.default_rng(seed), teacher_model, scale=0.4)
    config = BayesConfig(query_rule="information_gain", answer_models=model_family())
    learner = BayesLearner(GRID, config, seed)
    for _ in range(150):
        query = learner.ask()
        learner.tell(query, teacher.answer(query))
    assert learner.posterior.model_posterior()["myopic"] > 0.5
