"""The 5 cm circle the path tests send (docs/tracking.md): in the y-z plane
through ``start`` at 0.25 Hz, its phase rising smoothly from rest over the
first second, with its exact velocity and acceleration."""

from __future__ import annotations

import math

#: Radius, m, and angular rate, rad/s.
RADIUS: float = 0.05
RATE: float = 2 * math.pi * 0.25


def circle_sample(start: list[float], t: float) -> tuple[list[float], list[float], list[float]]:
    """The circle's point at ``t`` s, its velocity and its acceleration."""
    x = min(t, 1.0)
    if t <= 1.0:
        phase = x**6 - 3 * x**5 + 2.5 * x**4
        dphase = 6 * x**5 - 15 * x**4 + 10 * x**3
        ddphase = 30 * x**4 - 60 * x**3 + 30 * x**2
    else:
        phase, dphase, ddphase = t - 0.5, 1.0, 0.0
    a, da, dda = RATE * phase, RATE * dphase, RATE * ddphase
    s, c, r = math.sin(a), math.cos(a), RADIUS
    return (
        [start[0], start[1] + r * s, start[2] + r * (1 - c)],
        [0.0, r * da * c, r * da * s],
        [0.0, r * dda * c - r * da * da * s, r * dda * s + r * da * da * c],
    )


def circle_knots(start: list[float], seconds: float, step: float = 0.02) -> tuple[list[float], list[list[float]]]:
    """The circle's knots every ``step`` s for ``seconds``: times and points."""
    times, points = [], []
    for k in range(int(round(seconds / step)) + 1):
        t = k * step
        times.append(t)
        points.append(circle_sample(start, t)[0])
    return times, points
