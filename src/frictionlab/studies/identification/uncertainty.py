r"""Uncertainty of a limit-cycle fit's estimate and its identifiability
(:mod:`frictionlab.studies.identification.limit_cycle`).

Uncertainty and identifiability
-------------------------------
With J the Jacobian of the residuals at the optimum (m residuals, n keys),
the covariance is estimated as

.. math::

    \frac{\nu}{\nu - 2}\,(s^2 + s_j^2)\,(J^T J)^{-1},
    \qquad s^2 = C/\nu, \quad \nu = m - n.

* J comes from straight-line fits of each residual through the optimum and
  the points 1 and 2 steps (``rel_step``) to either side of it along each
  key (``LimitCycleProblem.line_fit``), not from one central difference:
  a single step can land on a jump of the piecewise-constant features and
  set a column of J several times too steep, which made the standard error
  of that key several times too small.
* :math:`s_j^2` is the simulator's own feature jitter: the pooled variance
  of the residuals about those lines.  It limits how well even noise-free
  features determine the parameters, and the optimiser partly fits it away
  from :math:`C`.
* :math:`\nu/(\nu - 2)`: with :math:`s^2` estimated from :math:`\nu`
  degrees of freedom, the standardised error is Student-t distributed, and
  this factor makes the reported value its standard deviation (the
  marginal posterior standard deviation under a flat prior on the
  parameters and on :math:`\log\sigma`).  With :math:`\nu \le 2` that
  variance is infinite: no standard error is reported (``None``), as with a
  singular :math:`J^T J`, and a warning says why.

The identifiability check takes the singular value decomposition of the
Jacobian scaled to relative parameter changes, :math:`J\,\mathrm{diag}(|p|)`:
a relative change :math:`\delta` of the parameters along the singular vector
:math:`v_i` moves the (weighted, relative) features by :math:`\sigma_i\delta`
in Euclidean norm.  A direction with :math:`\sigma_i <` :data:`FLAT_SENSITIVITY`
(a 20 % parameter change moving the features by less than 1 % in all), or
below :data:`FLAT_RATIO` times the largest singular value (numerically flat),
is flat: the parameters dominating its singular vector are named in a warning
(the features cannot determine them, or only a combination of them).  The
criterion is absolute, not relative to the best-determined direction, because
a very sensitive parameter such as ``plant.omega0`` must not make a merely
less sensitive one look unidentifiable.  A parameter whose
relative standard error exceeds 50 % is reported as poorly determined.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["FLAT_RATIO", "FLAT_SENSITIVITY", "POOR_RELATIVE_STDERR", "covariance",
           "identifiability"]

#: Singular value of the relatively scaled Jacobian below which a direction
#: counts as flat (not identifiable): a 20 % parameter change along it moves
#: the weighted relative features by under 1 % (Euclidean norm over all).
FLAT_SENSITIVITY = 0.05
#: Singular-value ratio (to the largest) below which a direction is
#: numerically flat whatever its absolute size.
FLAT_RATIO = 1e-4
#: Relative standard error above which a parameter is reported as poorly determined.
POOR_RELATIVE_STDERR = 0.5


def covariance(J: np.ndarray, cost: float, m: int, n: int, jitter: float = 0.0):
    """Covariance of the estimate, or None and the reason it is not estimable.

    ``nu/(nu - 2) (s^2 + jitter) (J^T J)^-1`` with ``nu = m - n`` and
    ``s^2 = cost/nu`` (see the module docstring), via the SVD of J.
    """
    nu = m - n
    if nu <= 2:
        return None, f"{m} known feature(s) for {n} fitted key(s): {max(nu, 0)} residual " \
                     "degree(s) of freedom, standard errors need at least 3"
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    if s[0] <= 0 or s[-1] <= 1e-10 * s[0]:
        return None, "J^T J is singular at the optimum: standard errors not estimated"
    s2 = nu / (nu - 2) * (cost / nu + jitter)
    cov = s2 * (vt.T / s**2) @ vt
    return cov, None


def identifiability(J: np.ndarray, p: np.ndarray, keys: Sequence[str],
                    sensitivity: float = FLAT_SENSITIVITY,
                    ratio: float = FLAT_RATIO) -> tuple[list[float], list[str]]:
    """Singular values of the relatively scaled Jacobian and flat-direction warnings.

    Parameters
    ----------
    J : ndarray (m, n)
        Residual Jacobian in parameter units.
    p : ndarray (n,)
        Parameter values (the scale of each column).
    keys : names of the parameters.
    sensitivity : singular value below which a direction is flat.
    ratio : singular-value ratio (to the largest) below which a direction is flat.

    Returns
    -------
    (singular values, warnings)
    """
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    Js = J * scale
    warnings = []
    col = np.linalg.norm(Js, axis=0)
    for k, c in zip(keys, col, strict=True):
        if c == 0.0:
            warnings.append(f"{k} does not affect the given features: not identifiable")
    if Js.shape[0] == 0:
        return [], warnings
    _, s, vt = np.linalg.svd(Js, full_matrices=True)
    sv = [float(x) for x in s]
    smax = s[0] if len(s) else 0.0
    n = len(keys)
    # directions beyond the number of residuals are flat too (m < n)
    svals = np.concatenate([s, np.zeros(max(0, n - len(s)))])
    for i in range(n):
        if smax > 0 and svals[i] >= max(ratio * smax, sensitivity):
            continue
        v = vt[i]
        big = [k for k, c in sorted(zip(keys, v, strict=True), key=lambda t: -abs(t[1]))
               if abs(c) >= 0.5 * np.max(np.abs(v))]
        if len(big) == 1 and any(big[0] in w for w in warnings):
            continue
        warnings.append(
            "not identifiable from the given features: flat direction dominated by "
            f"{', '.join(big)} (a 20 % change along it moves the features by "
            f"{20.0 * svals[i]:.2g} %)"
            + ("" if len(big) == 1 else "; only a combination of them is determined"))
    return sv, warnings
