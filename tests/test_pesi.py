"""PESI: the soft cross-entropy of Eq. 2 / Eq. 3, the standard-CE ablation, and Algorithm 2 via ask/tell."""

import math

import numpy as np
import pytest
import torch
from torch import nn

from hipref.learners.losses import log_probs, pesi_loss, pesi_loss_n, standard_ce_loss
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import DESK_HEIGHT, PretrainConfig, SIModel, pretrain
from hipref.teachers.preference import PreferenceQuery, ScriptedPreferenceTeacher
from tests._clips import shown


class LogitTable(nn.Module):
    """A model that is nothing but its logits, so a gradient step acts on the distribution directly."""

    def __init__(self, logits: torch.Tensor) -> None:
        super().__init__()
        self.logits = nn.Parameter(logits.clone())

    def forward(self) -> torch.Tensor:
        return torch.log_softmax(self.logits, dim=-1)


def _sgd_steps(table: LogitTable, pair: list[int], y: float, p: float, steps: int = 1) -> None:
    optimiser = torch.optim.SGD(table.parameters(), lr=0.5)
    for _ in range(steps):
        loss = pesi_loss(log_probs(table.logits[None], torch.tensor([pair])), torch.tensor([y]), p)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("y", [1.0, -1.0])
def test_eq2_step_moves_mass_toward_the_preferred_candidate_and_away_from_the_other(
    seed: int, y: float
) -> None:
    rng = np.random.default_rng(seed)
    table = LogitTable(torch.as_tensor(rng.normal(size=41), dtype=torch.float32))
    pair = [int(i) for i in rng.choice(41, size=2, replace=False)]
    preferred, other = (pair[0], pair[1]) if y == 1 else (pair[1], pair[0])
    before = table().exp().detach()
    _sgd_steps(table, pair, y, p=0.25)
    after = table().exp().detach()
    assert after[preferred] > before[preferred]
    assert after[other] < before[other]


@pytest.mark.parametrize("seed", range(5))
def test_zero_encouragement_ignores_the_label_and_leaves_the_distribution_unchanged(seed: int) -> None:
    # With p = 0 the targets are the model's own Pr over the query: the gradient is zero, whatever the label,
    # so the argmax (indeed every probability) stays where it was.
    rng = np.random.default_rng(seed)
    logits = torch.as_tensor(rng.normal(size=41), dtype=torch.float32)
    leaf = logits.clone().requires_grad_()
    for y in (1.0, -1.0):
        loss = pesi_loss(log_probs(leaf[None], torch.tensor([[3, 9]])), torch.tensor([y]), 0.0)
        torch.testing.assert_close(torch.autograd.grad(loss, leaf)[0], torch.zeros(41))
    table = LogitTable(logits)
    mode = int(table().argmax())
    for _ in range(20):
        other = int(rng.choice([i for i in range(41) if i != mode]))
        pair = [mode, other] if rng.random() < 0.5 else [other, mode]
        _sgd_steps(table, pair, float(rng.choice([-1.0, 1.0])), p=0.0)
        assert int(table().argmax()) == mode
    torch.testing.assert_close(table.logits.detach(), logits)


def test_eq2_gradient_moves_the_pair_logits_by_p_and_leaves_the_others() -> None:
    leaf = torch.randn(41, requires_grad=True)
    loss = pesi_loss(log_probs(leaf[None], torch.tensor([[7, 2]])), torch.tensor([1.0]), 0.25)
    (grad,) = torch.autograd.grad(loss, leaf)
    expected = torch.zeros(41)
    expected[7], expected[2] = -0.25, 0.25
    torch.testing.assert_close(grad, expected)


def test_eq3_with_two_candidates_equals_eq2_in_value_and_gradient() -> None:
    logits = torch.randn(8, 41, requires_grad=True)
    pairs = torch.stack([torch.randperm(41)[:2] for _ in range(8)])
    y = torch.tensor([1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0])
    queried = log_probs(logits, pairs)
    eq2 = pesi_loss(queried, y, 0.25)
    (grad_eq2,) = torch.autograd.grad(eq2, logits, retain_graph=True)
    eq3 = pesi_loss_n(queried, torch.stack([y, -y], dim=1), 0.25)
    (grad_eq3,) = torch.autograd.grad(eq3, logits)
    torch.testing.assert_close(eq2, eq3)
    torch.testing.assert_close(grad_eq2, grad_eq3)


def test_eq3s_gradient_on_the_queried_logits_is_minus_p_y_so_a_step_moves_weight_to_the_preferred() -> None:
    # By hand: with the weights w = Pr + p y held fixed and summing to one (the y_i sum to zero), the gradient
    # of -sum_i w_i log softmax(z)_i with respect to z_j is -(w_j - Pr_j sum_i w_i) = -p y_j, the same for
    # every Pr; averaged over a batch of B it is -p y / B. The unqueried logits get no gradient.
    generator = torch.Generator().manual_seed(4)
    logits = torch.randn(2, 41, generator=generator, requires_grad=True)
    indices = torch.tensor([[0, 1, 2, 3], [40, 7, 9, 5]])
    y_vec = torch.tensor([[-1 / 3, -1 / 3, 1.0, -1 / 3], [1.0, -1 / 3, -1 / 3, -1 / 3]])
    (grad,) = torch.autograd.grad(pesi_loss_n(log_probs(logits, indices), y_vec, 0.25), logits)
    expected = torch.zeros(2, 41).scatter(1, indices, -0.25 * y_vec / 2)
    torch.testing.assert_close(grad, expected)
    # A gradient step therefore raises the preferred candidate's share among the queried and lowers the rest.
    before = torch.softmax(logits.detach().gather(1, indices), dim=1)
    after = torch.softmax((logits.detach() - grad).gather(1, indices), dim=1)
    assert torch.equal((after > before), y_vec > 0)


def test_standard_ce_is_cross_entropy_among_the_queried_candidates() -> None:
    logits = torch.log(torch.tensor([[0.1, 0.3, 0.05, 0.55]]))
    loss = standard_ce_loss(log_probs(logits, torch.tensor([[0, 1, 2]])), torch.tensor([[-0.5, -0.5, 1.0]]))
    torch.testing.assert_close(loss, -torch.log(torch.tensor(0.05 / 0.45)))


def test_eq2_refuses_labels_outside_minus_one_one() -> None:
    with pytest.raises(ValueError, match="y must contain only"):
        pesi_loss(torch.zeros(2, 2), torch.tensor([1.0, 0.0]), 0.25)


def _learner(seed: int = 0, **config: object) -> PESILearner:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(32, 16), seed=seed)
    return PESILearner(model, PESIConfig(**{"history": 1, **config}), seed=seed)


@pytest.mark.parametrize("label", [0, 2, -2, 0.5, math.nan, True, None, "1", [1, 1]])
def test_tell_refuses_a_label_outside_minus_one_one(label: object) -> None:
    learner = _learner()
    query = learner.ask(shown(np.ones(4)))
    with pytest.raises(ValueError, match="preference over 2 candidates"):
        learner.tell(query, label)
    assert len(learner) == 0


def test_tell_refuses_queries_it_cannot_have_asked() -> None:
    learner = _learner()
    with pytest.raises(ValueError, match="candidate"):
        learner.tell(PreferenceQuery((0.5, 0.555), np.ones(4)), 1)
    with pytest.raises(ValueError, match="n_candidates=2"):
        learner.tell(PreferenceQuery((0.5, 0.6, 0.7), np.ones(4)), np.array([1.0, -0.5, -0.5]))
    with pytest.raises(ValueError, match="features"):
        learner.tell(PreferenceQuery((0.5, 0.6), np.ones(3)), 1)


def test_queries_are_distinct_candidates_from_phi_and_reproducible() -> None:
    queries = []
    for _ in range(2):
        learner = _learner(seed=7, n_candidates=3)
        queries.append([learner.ask(shown(np.full(4, float(i)))).candidates for i in range(20)])
    assert queries[0] == queries[1]
    for candidates in queries[0]:
        assert len(set(candidates)) == 3
        for c in candidates:
            DESK_HEIGHT.index_of(c)


@pytest.mark.parametrize(("loss", "n_candidates"), [("soft", 2), ("soft", 3), ("standard", 2)])
def test_noise_free_preferences_reduce_the_estimate_error(loss: str, n_candidates: int) -> None:
    true_height = 0.843
    learner = _learner(seed=1, loss=loss, n_candidates=n_candidates, learning_rate=0.1)
    teacher = ScriptedPreferenceTeacher(true_height, 0.0, np.random.default_rng(2))
    features = np.array([0.3, -1.0, 2.0, 0.5])
    initial_error = abs(learner.estimate(features) - true_height)
    for _ in range(200):
        query = learner.ask(shown(features))
        learner.tell(query, teacher.answer(query))
    final_error = abs(learner.estimate(features) - true_height)
    assert len(learner) == 200
    assert initial_error > 0.1
    assert final_error < 0.5 * initial_error


def test_the_learner_fine_tunes_a_copy_of_the_model() -> None:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    learner = PESILearner(model, PESIConfig(history=1), seed=0)
    features = np.ones(4)
    before = model.predict(features)
    teacher = ScriptedPreferenceTeacher(0.9, 0.0, np.random.default_rng(0))
    for _ in range(5):
        query = learner.ask(shown(features))
        learner.tell(query, teacher.answer(query))
    assert model.predict(features) == before
    assert learner.estimate(features) != float(before)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"loss": "hinge"}, "loss must be one of"),
        ({"encourage_percentage": -0.1}, "encourage_percentage"),
        ({"batch_size": 0}, "batch_size"),
        ({"n_candidates": 1}, "n_candidates"),
        ({"query_uniform_mix": 0.0}, "query_uniform_mix"),
    ],
)
def test_invalid_config_is_refused(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PESIConfig(**kwargs)


def test_ask_slices_tau_from_a_uniformly_chosen_candidates_clip() -> None:
    # Algorithm 2: tau is a slice of the clip pi^l executes with one of the candidates, chosen uniformly.
    model = SIModel(input_dim=6, candidates=DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    learner = PESILearner(model, PESIConfig(history=3, n_candidates=3), seed=4)
    observed: list[tuple[float, np.ndarray]] = []

    def observe(phi: float, rng: np.random.Generator) -> np.ndarray:
        first = int(rng.integers(8))
        tau = (phi + np.arange(20.0).reshape(10, 2))[first : first + 3].reshape(-1)
        observed.append((phi, tau))
        return tau

    sliced = []
    for _ in range(300):
        observed.clear()
        query = learner.ask(observe)
        assert len(observed) == 1
        phi, tau = observed[0]
        assert np.array_equal(query.features, tau)
        sliced.append(query.candidates.index(phi))
    counts = np.bincount(sliced, minlength=3)
    assert counts.min() > 70, counts  # each of the three places about 100 times


def test_ask_refuses_a_slice_that_does_not_fit_the_si_input() -> None:
    learner = _learner(history=2)  # SI input 4 = h 2 x 2 features
    with pytest.raises(ValueError, match=r"features must have shape \(4,\)"):
        learner.ask(lambda phi, rng: np.zeros(6))


def test_a_perfect_teacher_moves_a_brier_pretrained_estimate_towards_the_truth() -> None:
    # SI pretrained on its distribution (Algorithm 4, Brier); on held-out slices the teacher's truth is put
    # 8 cm from SI's estimate, and the default PESI learns 20 perfect preferences on that fixed slice.
    # Eq. 2 only moves mass within the queried pair, so a pair on the far side of the truth moves the
    # expectation away a little: no slice may end more than one candidate step (1 cm) further away, and
    # on average the error must fall.
    rng = np.random.default_rng(5)
    features = rng.normal(loc=3.0, scale=[1.0, 5.0, 0.1, 2.0, 1.0, 1.0], size=(1040, 6))
    latent = 1.0 / (1.0 + np.exp(-(features - 3.0) @ np.array([1.0, 0.2, 5.0, -0.5, 0.0, 0.0]) / 2.0))
    heights = np.clip(DESK_HEIGHT.denormalise(latent) + rng.normal(0.0, 0.01, size=1040), 0.5, 0.9)
    model = SIModel(6, DESK_HEIGHT, hidden_sizes=(32, 16), seed=0)
    pretrain(model, features[:1000], heights[:1000], PretrainConfig(batch_size=64, n_steps=600), seed=0)
    changes = []
    for i in range(1000, 1040):
        tau = features[i]
        estimate = float(model.predict(tau))
        for truth in (estimate - 0.08, estimate + 0.08):
            if not 0.5 <= truth <= 0.9:
                continue
            learner = PESILearner(model, PESIConfig(history=1), seed=i)
            teacher = ScriptedPreferenceTeacher(truth, 0.0, np.random.default_rng(i))
            for _ in range(20):
                query = learner.ask(shown(tau))
                learner.tell(query, teacher.answer(query))
            changes.append(abs(learner.estimate(tau) - truth) - abs(estimate - truth))
    assert len(changes) >= 40
    assert max(changes) <= DESK_HEIGHT.resolution
    assert np.mean(changes) < -0.002


def test_the_fine_tuned_parameters_are_the_only_ones_that_move() -> None:
    features = np.array([0.3, -1.0, 2.0, 0.5])
    teacher = ScriptedPreferenceTeacher(0.85, 0.0, np.random.default_rng(0))
    for fine_tuned in ("last_layer", "output_bias"):
        learner = _learner(seed=2, fine_tuned=fine_tuned, learning_rate=0.1)
        before = {name: p.detach().clone() for name, p in learner.model.named_parameters()}
        for _ in range(20):
            query = learner.ask(shown(features))
            learner.tell(query, teacher.answer(query))
        moved = {name for name, p in learner.model.named_parameters() if not torch.equal(p, before[name])}
        last = len(learner.model.net) - 1
        expected = {f"net.{last}.bias"} | ({f"net.{last}.weight"} if fine_tuned == "last_layer" else set())
        assert moved == expected


def test_uniform_sampling_asks_about_the_whole_of_phi_and_belief_sampling_near_the_mode() -> None:
    features = np.array([0.3, -1.0, 2.0, 0.5])
    spread = {}
    for sampling in ("uniform", "belief"):
        learner = _learner(seed=3, candidate_sampling=sampling)
        with torch.no_grad():
            learner.model.net[-1].weight.zero_()
            learner.model.net[-1].bias.copy_(torch.where(torch.arange(41) == 30, 20.0, 0.0))
        asked = [c for _ in range(200) for c in learner.ask(shown(features)).candidates]
        spread[sampling] = np.mean(np.isclose(asked, DESK_HEIGHT.values[30]))
    assert spread["uniform"] < 0.1  # 2 of 41 candidates per query: about 5 %
    assert spread["belief"] > 0.4


def test_pr_over_all_of_phi_is_the_full_softmax_at_the_queried_candidates() -> None:
    # Brute force in numpy: Pr over all of Phi divides by the sum over the 41 candidates, Pr over the query
    # by the sum over the queried pair only.
    logits = torch.randn(3, 41, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    pairs = torch.tensor([[0, 5], [7, 2], [40, 39]])
    z, rows = logits.numpy(), np.arange(3)[:, None]
    queried = np.exp(z[rows, pairs.numpy()])
    over_all = np.log(queried / np.exp(z).sum(axis=1, keepdims=True))
    over_pair = np.log(queried / queried.sum(axis=1, keepdims=True))
    np.testing.assert_allclose(log_probs(logits, pairs, "all").numpy(), over_all, rtol=1e-12)
    np.testing.assert_allclose(log_probs(logits, pairs, "query").numpy(), over_pair, rtol=1e-12)
    with pytest.raises(ValueError, match="pr_domain must be one of"):
        log_probs(logits, pairs, "some")
