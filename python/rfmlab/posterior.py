"""A study's posterior density for external samplers (emcee, nutpie, blackjax, PyMC)."""

from __future__ import annotations

from typing import Sequence

import numpy as np


def _vec(x) -> list[float]:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"expected a 1-d array of coordinates, got shape {a.shape}")
    return a.tolist()


class Posterior:
    """``log p(x | data)`` over unconstrained coordinates ``x`` in R^d (``Study.posterior``).

    The physical parameters (SI) are a fixed transform of ``x`` per coordinate, given by
    each coordinate's prior: log for log-uniform and log-normal priors, a logit of the log for
    bounded ones (``to_constrained`` / ``to_unconstrained``); the prior density in ``x``
    includes the transform's log-Jacobian, so a sampler never meets a boundary. ``logp`` is
    the log posterior up to the log evidence: log prior + log likelihood (the likelihood is
    normalised over the data).

    Coordinates (``names``): the law's parameters, then free declared effects, then noise
    parameters (per-channel scales, a Student-t nu) when the noise model infers them.
    """

    def __init__(self, native):
        self._native = native

    model = property(lambda self: self._native.model)
    level = property(lambda self: self._native.level)
    dim = property(lambda self: self._native.dim, doc="Number of coordinates.")
    names = property(lambda self: list(self._native.names), doc="Coordinate names.")
    n_law = property(
        lambda self: self._native.n_law,
        doc="Number of law (and free effect) parameters, before the noise coordinates.",
    )
    priors = property(
        lambda self: dict(zip(self.names, self._native.priors)),
        doc="Per coordinate: (family, the prior with its bounds or moments).",
    )
    linearised = property(
        lambda self: self._native.linearised,
        doc="True when the H1 measurement bias is linearised (built with `at`).",
    )
    freq_hz = property(lambda self: np.asarray(self._native.freq_hz), doc="The level's lines (Hz).")

    def __repr__(self) -> str:
        return f"<rfmlab.Posterior {self.model} at {self.level}: {self.names}>"

    def logp(self, x: Sequence[float] | np.ndarray) -> float:
        """Log posterior density (up to log Z) at ``x``; -inf where it cannot be evaluated."""
        return self._native.logp(_vec(x))

    __call__ = logp

    def logp_and_grad(self, x: Sequence[float] | np.ndarray) -> tuple[float, np.ndarray]:
        """Log posterior density and its gradient with respect to ``x`` (float64 array)."""
        v, g = self._native.logp_and_grad(_vec(x))
        return v, np.asarray(g, dtype=np.float64)

    def log_prior(self, x) -> float:
        """Log prior density in ``x`` (transform's log-Jacobian included)."""
        return self._native.log_prior(_vec(x))

    def log_likelihood(self, x) -> float:
        """Log likelihood of the level's data at ``x``."""
        return self._native.log_likelihood(_vec(x))

    def log_jacobian(self, x) -> float:
        """``ln |det dp/dx|`` of the transform at ``x``."""
        return self._native.log_jacobian(_vec(x))

    def to_constrained(self, x) -> np.ndarray:
        """Physical values (SI) of ``x``; a 2-d array is transformed row by row."""
        a = np.asarray(x, dtype=np.float64)
        if a.ndim == 2:
            return np.array([self._native.to_constrained(r.tolist()) for r in a])
        return np.asarray(self._native.to_constrained(_vec(a)))

    def to_unconstrained(self, p) -> np.ndarray:
        """Unconstrained coordinates of physical values ``p`` (SI); 2-d row by row; ``p`` may
        be a dict by name."""
        if isinstance(p, dict):
            p = [float(p[n]) for n in self.names]
        a = np.asarray(p, dtype=np.float64)
        if a.ndim == 2:
            return np.array([self._native.to_unconstrained(r.tolist()) for r in a])
        return np.asarray(self._native.to_unconstrained(_vec(a)))

    def pointwise(self, p) -> np.ndarray:
        """Log likelihood per frequency line (summed over channels) at physical values ``p``."""
        if isinstance(p, dict):
            p = [float(p[n]) for n in self.names]
        return np.asarray(self._native.pointwise(_vec(p)))

    def sample_prior(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` draws from the prior in unconstrained coordinates, shape (n, dim)."""
        return np.asarray(self._native.sample_prior(int(n), int(seed)), dtype=np.float64).reshape(
            int(n), self.dim
        )
