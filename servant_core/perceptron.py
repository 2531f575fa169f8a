"""A multi-layer perceptron's forward pass in NumPy, over the weights scikit-learn fitted.

The action learner's and the learned fusion's nets predict through it, before and after they are
saved: a net loaded from a file needs neither pickle nor scikit-learn, and does what was tested.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "tanh": np.tanh,
    "relu": lambda a: np.maximum(a, 0.0),
    "logistic": lambda a: 1.0 / (1.0 + np.exp(-a)),
    "identity": lambda a: a,
}


def forward(
    x: np.ndarray, coefs: Sequence[np.ndarray], intercepts: Sequence[np.ndarray], activation: str
) -> np.ndarray:
    """The network's output for rows `x`: hidden layers through `activation`, a linear output."""
    a = x
    for i, (w, b) in enumerate(zip(coefs, intercepts, strict=True)):
        a = a @ w + b
        if i < len(coefs) - 1:
            a = ACTIVATIONS[activation](a)
    return a
