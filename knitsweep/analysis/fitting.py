"""Straight-line least-squares fits with the error columns of paper Table S4.

Used for the offset stress σ0 (a line through the softened part of σ(ε), docs/model.md §9)
and for the linear fit to the jammed regime of an energy gap against L/r (paper
Fig. 4a, SI "Tolerance and Error", Table S4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._common import PlainDict, check_array, check_same_length


@dataclass(frozen=True)
class LinearFit(PlainDict):
    """Least-squares line y = intercept + slope·x and its residuals (paper Table S4).

    Units follow the data: ``slope`` in [y]/[x], ``intercept``, the residual
    statistics in [y], ``mse`` in [y]². Residuals are y_i − (intercept + slope·x_i).

    Attributes:
        slope: fitted slope.
        intercept: fitted value at x = 0 (Table S4 "Y-Intercept").
        n_points: number of points fitted (≥ 2).
        max_abs_residual: max |residual| (Table S4 "Max Abs(Residual)").
        mean_abs_residual: mean |residual| (Table S4 "Mean Abs(Residual)").
        mse: mean squared residual, Σ residual² / n_points (Table S4 "MSE"; the
            paper does not say whether it divides by n or n − 2; we divide by n).
    """

    slope: float
    intercept: float
    n_points: int
    max_abs_residual: float
    mean_abs_residual: float
    mse: float

    @property
    def x_intercept(self) -> float | None:
        """Where the line crosses y = 0, −intercept/slope; None for a zero slope."""
        if self.slope == 0.0:
            return None
        return -self.intercept / self.slope


def fit_line(x: np.ndarray, y: np.ndarray) -> LinearFit:
    """Ordinary least-squares straight line through (x, y).

    Args:
        x: shape (n,), n ≥ 2, not all equal.
        y: shape (n,), same units as the wanted intercept.

    Returns:
        The :class:`LinearFit`. The centred normal equations are used
        (slope = Σ(x−x̄)(y−ȳ)/Σ(x−x̄)², intercept = ȳ − slope·x̄), so that noiseless
        points on a line are recovered to a few ulps.

    Raises:
        ValueError: fewer than 2 points, unequal lengths, non-finite values, or
            all x equal.
    """
    x = check_array("x", x, min_size=2)
    y = check_array("y", y, min_size=2)
    n = check_same_length(x=x, y=y)
    x_mean = float(np.mean(x))
    y_mean = float(np.mean(y))
    dx = x - x_mean
    sxx = float(np.dot(dx, dx))
    if sxx == 0.0:
        raise ValueError("x: all values are equal; a line cannot be fitted")
    slope = float(np.dot(dx, y - y_mean)) / sxx
    intercept = y_mean - slope * x_mean
    residuals = y - (intercept + slope * x)
    abs_res = np.abs(residuals)
    return LinearFit(
        slope=slope,
        intercept=intercept,
        n_points=n,
        max_abs_residual=float(np.max(abs_res)),
        mean_abs_residual=float(np.mean(abs_res)),
        mse=float(np.mean(residuals**2)),
    )
