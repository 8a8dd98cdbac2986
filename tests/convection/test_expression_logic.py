"""Config expressions combine conditions as users write them: ``and``, ``or``, ``not`` and chained
comparisons act elementwise on the points (Python's own would refuse arrays)."""

import numpy as np
import pytest

from convection.expressions import Expression

POINTS = np.array([[0.1, 0.5, 0.9, 0.5], [0.2, 0.5, 0.8, 0.95], [0.0, 0.0, 0.0, 0.0]])


@pytest.mark.parametrize("text, expected", [
    ("x > 0.3 and y < 0.6", [0, 1, 0, 0]),
    ("x < 0.3 or y > 0.7", [1, 0, 1, 1]),
    ("0.2 < x < 0.6", [0, 1, 0, 1]),
    ("0.2 < x < 0.6 < y", [0, 0, 0, 1]),
    ("not x > 0.3 and y < 1", [1, 0, 0, 0]),
    ("x > 0.3 and y < 0.9 and not x > 0.8", [0, 1, 0, 0]),
    ("(x > 0.3 and y < 0.6) * 2 + 1", [1, 3, 1, 1]),
    ("abs(x - 0.5) <= 0.1 and abs(z - 0.5) <= 0.1", [0, 1, 0, 0]),  # z is y in 2D
])
def test_conditions_elementwise(text, expected):
    assert Expression(text, gdim=2)(POINTS).tolist() == expected


def test_scalar_conditions_unchanged():
    assert Expression("1 < 2 and 3 > 2", gdim=2)(POINTS).tolist() == [1, 1, 1, 1]
    assert Expression("1 - z", gdim=2)(POINTS).tolist() == pytest.approx([0.8, 0.5, 0.2, 0.05])
