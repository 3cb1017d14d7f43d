"""The multilayer perceptron of SI (`sysid`) and of Algorithm 3's pi^l (`imitation`)."""

from __future__ import annotations

import torch
from torch import nn


def tanh_mlp(inputs: int, hidden: tuple[int, ...], outputs: int, seed: int) -> nn.Sequential:
    """Linear layers of widths `hidden`, each followed by tanh, then a linear output layer. Its weights are
    drawn from a private stream seeded by `seed`: same seed, same network, torch's global generator
    untouched."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        layers: list[nn.Module] = []
        width = inputs
        for size in hidden:
            layers += [nn.Linear(width, size), nn.Tanh()]
            width = size
        layers.append(nn.Linear(width, outputs))
        return nn.Sequential(*layers)
