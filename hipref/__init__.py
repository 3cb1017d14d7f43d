"""hipref: learning robot control from human advice.

Feedback trains a high-level goal selector on a grid over the desk; noisy preferences fine-tune a
system-identification model whose estimate parameterises the low-level force controller.
"""

__version__ = "0.1.0"
