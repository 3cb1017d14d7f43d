"""The losses preferences fine-tune SI with (Algorithm 2's "update SI by Eqn. 2"): Eq. 2 / Eq. 3, the
standard cross-entropy of A.8, and two losses robust to flipped labels, all on SI's log Pr over the queried
candidates (`log_probs`).

What Eq. 2 does to a robust loss. With Pr over the queried pair (`log_probs`, 'query') and the weights
Pr + p y detached, Eq. 2's gradient on the pair's logits is (-p y, p y): linear in y. Any loss that mixes
L(y) and L(-y) with fixed weights therefore only rescales the step:

- label smoothing / conservative DPO, (1 - eps) L(y) + eps L(-y), is Eq. 2 with p (1 - 2 eps);
- the unbiased loss of robust DPO, [(1 - e) L(y) - e L(-y)] / (1 - 2 e), is Eq. 2 with p / (1 - 2 e).

Both keep the sign of every update, so neither can undo a flipped label: the first takes smaller steps, the
second larger ones, and what they change is how far a run of flipped labels moves SI. The filters
(`hipref.learners.filters`, `hipref.learners.coteaching`) decide per preference and can.
"""

from __future__ import annotations

import torch

from hipref.validation import check_choice, check_range

SI_LOSSES: tuple[str, ...] = ("soft", "standard", "smoothed", "unbiased")
"""'soft': Eq. 2 (two candidates) / Eq. 3 (N), the method 'pesi'; 'standard': cross-entropy, the pesi_ce
ablation of A.8; 'smoothed': Eq. 2 with a smoothed label (`conservative_pesi_loss`, pairs only);
'unbiased': Eq. 2 made unbiased under the flip rate e (`unbiased_pesi_loss`, pairs only)."""
PAIR_LOSSES: frozenset[str] = frozenset({"smoothed", "unbiased"})
"""Losses that mix y and -y, defined on pairs only."""
PR_DOMAINS: tuple[str, ...] = ("query", "all")
"""Over what Pr in Eq. 2/3 is a distribution: the queried candidates, or all of Phi (see `log_probs`)."""


def log_probs(logits: torch.Tensor, indices: torch.Tensor, pr_domain: str = "query") -> torch.Tensor:
    """log Pr(phi_i) of the queried candidates (B, N), from SI's logits (B, |Phi|) and the query (B, N).

    'query': SI's distribution renormalised over the queried candidates, as the Bradley-Terry preference
    model of Christiano et al. (2017) that A.8 sets Eq. 2 against: Pr(phi_i) is the probability that phi_i
    is the best of the N shown. The weights Pr(phi_i) + p y_i then sum to one and an update only moves mass
    between the queried candidates. 'all': SI's distribution over all of Phi, the literal Pr(phi in Phi) of
    section 4; the weights then sum to less than one, and every update also drains the unqueried candidates
    onto the queried ones, whatever the label.
    """
    check_choice("pr_domain", pr_domain, PR_DOMAINS)
    if pr_domain == "query":
        return torch.log_softmax(logits.gather(1, indices), dim=1)
    return torch.log_softmax(logits, dim=1).gather(1, indices)


def pesi_loss(log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float) -> torch.Tensor:
    """Eq. 2: soft cross-entropy over a queried pair, averaged over the batch.

    L = -[log Pr(phi_0) (Pr(phi_0) + p y) + log Pr(phi_1) (Pr(phi_1) - p y)]

    log_probs_pair: (B, 2) from `log_probs` (log-probabilities rather than probabilities so a
    vanishing Pr keeps a usable gradient). y: (B,) in {-1, 1}, 1 meaning phi_0 preferred. The weights
    Pr + p y are constants (detached): the target is the model's own current belief with p moved from the
    dispreferred to the preferred candidate. The gradient on the pair's logits is then exactly -p y and
    p y, so p sets the update size (section 4), and with p = 0 there is no update at all.
    """
    if not torch.all((y == 1) | (y == -1)):
        raise ValueError(f"y must contain only -1 and 1, got {y.tolist()!r}")
    probs = log_probs_pair.detach().exp()
    weight_0 = probs[:, 0] + encourage_percentage * y
    weight_1 = probs[:, 1] - encourage_percentage * y
    return -(log_probs_pair[:, 0] * weight_0 + log_probs_pair[:, 1] * weight_1).mean()


def pesi_loss_n(log_probs_n: torch.Tensor, y_vec: torch.Tensor, encourage_percentage: float) -> torch.Tensor:
    """Eq. 3: the soft cross-entropy over N queried candidates, averaged over the batch.

    L = -sum_i log Pr(phi_i) (Pr(phi_i) + p y_i),   y_i in {-1/(N-1), 1}, one y_i = 1.

    Our reading of Eq. 3: as printed, the weight is '(sum_{i=1}^{N-1} Pr(phi_i) + p y(phi_i))', an inner sum
    that reuses the outer index. We read the weight as Pr(phi_i) + p y_i, the per-candidate weight of Eq. 2:
    with N = 2 and y_vec = (y, -y) it is then exactly Eq. 2, and since the y_i sum to zero the weights
    still sum to one, p being moved from the N - 1 dispreferred candidates to the preferred one, as in
    Eq. 2. (Summing all N probabilities into every weight would not reduce to Eq. 2.)

    log_probs_n: (B, N) from `log_probs`; y_vec: (B, N) label vectors.
    """
    weights = log_probs_n.detach().exp() + encourage_percentage * y_vec
    return -(log_probs_n * weights).sum(dim=1).mean()


def standard_ce_loss(log_probs_n: torch.Tensor, y_vec: torch.Tensor) -> torch.Tensor:
    """The pesi_ce ablation (A.8): cross-entropy with the preferred candidate as the positive class.

    log_probs_n: (B, N) from `log_probs`, so this is the Bradley-Terry loss of Christiano et al.
    (2017) that A.8 contrasts with: L = -log Pr(preferred). Unlike Eq. 2 it pushes toward certainty in the
    preferred candidate however sure the model already is.
    """
    preferred = y_vec.argmax(dim=1, keepdim=True)
    return -log_probs_n.gather(1, preferred).mean()


def conservative_pesi_loss(
    log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float, smoothing: float
) -> torch.Tensor:
    """Label smoothing of Eq. 2's target (conservative DPO, Mitchell 2023; Szegedy et al. 2016):

        L_eps(y) = (1 - eps) L(y) + eps L(-y),

    L being Eq. 2 (`pesi_loss`): the label is trusted with probability 1 - eps. Its gradient is Eq. 2's
    times (1 - 2 eps) (module docstring)."""
    check_range("smoothing", smoothing, 0.0, 0.5)
    return (1.0 - smoothing) * pesi_loss(log_probs_pair, y, encourage_percentage) + smoothing * pesi_loss(
        log_probs_pair, -y, encourage_percentage
    )


def unbiased_pesi_loss(
    log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float, rate: float
) -> torch.Tensor:
    """The unbiased loss under flips of rate e (Natarajan et al. 2013; robust DPO, Chowdhury et al. 2024):

        L~(y) = [(1 - e) L(y) - e L(-y)] / (1 - 2 e),

    L being Eq. 2. Its expectation over a label flipped with probability e is the clean loss:
    (1 - e) L~(y) + e L~(-y) = L(y). Needs e < 1/2."""
    check_range("rate", rate, 0.0, 0.5 - 1e-9)
    clean = pesi_loss(log_probs_pair, y, encourage_percentage)
    reversed_ = pesi_loss(log_probs_pair, -y, encourage_percentage)
    return ((1.0 - rate) * clean - rate * reversed_) / (1.0 - 2.0 * rate)


def preference_nll(log_probs_pair: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Per preference, -log Pr(preferred candidate) under SI's Pr over the pair (Bradley-Terry): large when
    the label contradicts what SI believes. The loss the filters rank by."""
    preferred = (y < 0).long().unsqueeze(1)  # y = 1 -> phi_0, y = -1 -> phi_1
    return -log_probs_pair.gather(1, preferred).squeeze(1)


def si_loss(
    loss: str,
    log_probs_n: torch.Tensor,
    y_vec: torch.Tensor,
    encourage_percentage: float,
    smoothing: float,
    rate: float,
) -> torch.Tensor:
    """The loss `loss` (one of SI_LOSSES) of a batch: SI's log Pr over the queried candidates (B, N) and
    their label vectors (B, N); `smoothing` is eps of 'smoothed', `rate` the flip rate e of 'unbiased'."""
    check_choice("loss", loss, SI_LOSSES)
    if loss == "standard":
        return standard_ce_loss(log_probs_n, y_vec)  # A.8 ablation
    if loss == "smoothed":
        return conservative_pesi_loss(log_probs_n, y_vec[:, 0], encourage_percentage, smoothing)
    if loss == "unbiased":
        return unbiased_pesi_loss(log_probs_n, y_vec[:, 0], encourage_percentage, rate)
    if log_probs_n.shape[1] == 2:
        return pesi_loss(log_probs_n, y_vec[:, 0], encourage_percentage)  # Eq. 2
    return pesi_loss_n(log_probs_n, y_vec, encourage_percentage)  # Eq. 3
