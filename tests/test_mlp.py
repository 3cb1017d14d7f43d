"""The multilayer perceptron of SI and of pi^l (`hipref.learners.mlp`): its layers computed by hand, its
weights set by its seed alone, and torch's global generator left as it was."""

from __future__ import annotations

import torch
from torch import nn

from hipref.learners.mlp import tanh_mlp


def test_the_network_is_tanh_after_each_hidden_layer_and_linear_at_the_output() -> None:
    net = tanh_mlp(3, (5, 4), 2, seed=0)
    linears = [layer for layer in net if isinstance(layer, nn.Linear)]
    assert [(layer.in_features, layer.out_features) for layer in linears] == [(3, 5), (5, 4), (4, 2)]
    x = torch.randn(7, 3, generator=torch.Generator().manual_seed(1))
    by_hand = x
    for k, layer in enumerate(linears):
        by_hand = by_hand @ layer.weight.T + layer.bias
        if k < len(linears) - 1:
            by_hand = torch.tanh(by_hand)
    torch.testing.assert_close(net(x), by_hand)
    # Linear output: scaled far enough, an output leaves [-1, 1], which a tanh would bound.
    with torch.no_grad():
        linears[-1].weight.mul_(100.0)
    assert net(x).abs().max() > 1.0


def test_no_hidden_layer_is_one_linear_map() -> None:
    net = tanh_mlp(4, (), 3, seed=2)
    assert len(net) == 1 and isinstance(net[0], nn.Linear) and net[0].in_features == 4


def test_the_seed_alone_sets_the_weights() -> None:
    def weights(seed: int) -> list[torch.Tensor]:
        return [p.detach().clone() for p in tanh_mlp(3, (8,), 2, seed).parameters()]

    torch.manual_seed(123)
    first = weights(5)
    torch.manual_seed(456)  # another global state: the same network all the same
    assert all(torch.equal(a, b) for a, b in zip(first, weights(5), strict=True))
    assert not torch.equal(first[0], weights(6)[0])


def test_building_a_network_leaves_torchs_global_generator_untouched() -> None:
    torch.manual_seed(9)
    expected = torch.rand(4)
    torch.manual_seed(9)
    tanh_mlp(3, (16, 16), 2, seed=0)
    torch.testing.assert_close(torch.rand(4), expected)
