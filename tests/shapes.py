"""Random obstacle shapes for the tests that compare compiled kernels with their numpy
references (one draw rule, so both suites cover the same shapes)."""

import numpy as np

from mpcdrive.scene.obstacles import Circle, Polygon, rectangle


def random_shape(rng: np.random.Generator):
    """A circle (radius 0.3-1.5 m), a rectangle (1-5 m by 0.5-2 m) or a convex pentagon (radius
    0.5-1.5 m), each a third of the time."""
    kind = rng.integers(3)
    if kind == 0:
        return Circle(float(rng.uniform(0.3, 1.5)))
    if kind == 1:
        return rectangle(float(rng.uniform(1.0, 5.0)), float(rng.uniform(0.5, 2.0)))
    a = np.sort(rng.uniform(0.0, 2 * np.pi, 5))
    return Polygon(np.column_stack([np.cos(a), np.sin(a)]) * rng.uniform(0.5, 1.5))
