"""GMM target-model update (Chang 2020, seed 002 eqs. 22-27), vectorised over the bins.

Each histogram bin q(u) is modelled by K Gaussians (mu_k, sigma_k, pi_k), initialised as
mu_k = q(u), sigma_k = `initial_sigma`, pi_k = 1/K. Per frame, with the bin value x(u)
observed at the tracked box:

1. order the components by pi, descending (a, b, c, ...);
2. the bin is gated: only if |x(u) - q(u)| < `diff_threshold` is the mixture updated;
3. the first component in that order with |x(u) - mu_k| < 3 sigma_k is updated
   (eq. 25) mu_k = (1-alpha) mu_k + alpha x; (eq. 26) sigma_k = sqrt((1-alpha) sigma_k^2 +
   alpha (x - mu_k)^2) with the new mu_k, as written; (eq. 27) pi_k = (1-beta) pi_k + beta and
   pi_j = (1-beta) pi_j for j != k;
4. the model is q(u) = A mu_a + B mu_b + C mu_c (eq. 23) in the new order, then normalised
   to sum to one (the per-bin mixes need not sum to one across bins).

The seed is silent on a gated bin that matches no component: like Stauffer-Grimson we
replace the lowest-pi component by (x, initial_sigma, beta) and renormalise that bin's pi.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.config import GmmConfig

FloatArray = NDArray[np.float64]


class GmmTargetModel:
    """K Gaussians per bin; `model` is the current target histogram (sums to one)."""

    def __init__(self, histogram: FloatArray, config: GmmConfig) -> None:
        self._shape: tuple[int, ...] = tuple(
            histogram.shape
        )  # (..., bins): each row is one normalised histogram
        flat = histogram.astype(np.float64).ravel()
        bins = flat.size
        k = config.components
        self._config = config
        self._mix = np.asarray(config.mix, dtype=np.float64)
        self.mu: FloatArray = np.repeat(flat[:, None], k, axis=1)
        self.sigma: FloatArray = np.full((bins, k), config.initial_sigma)
        self.pi: FloatArray = np.full((bins, k), 1.0 / k)
        self._rows = np.arange(bins)
        self._rows_column = self._rows[:, None]  # fancy-index rows with an (bins, k) order
        # components by pi, descending; pi changes only in update(), which renews this
        self._by_pi = self._order()
        self.model: FloatArray = self._mixture(self._by_pi)

    def _order(self) -> NDArray[np.intp]:
        # stable sort: ties keep component order, so hand-computed examples are unambiguous
        return np.argsort(-self.pi, axis=1, kind="stable")

    def _mixture(self, order: NDArray[np.intp]) -> FloatArray:
        mu_sorted = self.mu[self._rows_column, order]
        q = np.maximum(mu_sorted @ self._mix, 0.0).reshape(self._shape)
        total = q.sum(axis=-1, keepdims=True)
        out: FloatArray = np.where(total > 0, q / np.where(total > 0, total, 1.0), 1.0 / q.size)
        return out

    def update(self, observed: FloatArray) -> FloatArray:
        """Fold one observed histogram into the mixtures; return the new model."""
        cfg = self._config
        x = observed.astype(np.float64).ravel()
        gated = np.abs(x - self.model.ravel()) < cfg.diff_threshold
        order = self._by_pi
        rows_column = self._rows_column
        fits = (
            np.abs(x[:, None] - self.mu[rows_column, order]) < 3.0 * self.sigma[rows_column, order]
        )
        first_fit = order[self._rows, np.argmax(fits, axis=1)]
        any_fit = fits.any(axis=1)
        matched = gated & any_fit
        replaced = gated & ~any_fit

        rows = np.flatnonzero(matched)
        k = first_fit[rows]
        xm = x[rows]
        mu_new = (1.0 - cfg.alpha) * self.mu[rows, k] + cfg.alpha * xm
        sigma_new = np.sqrt(
            (1.0 - cfg.alpha) * self.sigma[rows, k] ** 2 + cfg.alpha * (xm - mu_new) ** 2
        )
        self.mu[rows, k] = mu_new
        self.sigma[rows, k] = sigma_new
        self.pi[rows] *= 1.0 - cfg.beta
        self.pi[rows, k] += cfg.beta

        rows = np.flatnonzero(replaced)
        if rows.size:
            weakest = order[rows, -1]
            self.mu[rows, weakest] = x[rows]
            self.sigma[rows, weakest] = cfg.initial_sigma
            self.pi[rows, weakest] = max(cfg.beta, 1e-9)  # > 0 so the row stays normalisable
            self.pi[rows] /= self.pi[rows].sum(axis=1, keepdims=True)

        self._by_pi = self._order()
        self.model = self._mixture(self._by_pi)
        return self.model
