"""Fisher vectors (Perronnin, Sánchez & Mensink 2010): a picture's local descriptors as the
gradient of their log-likelihood under a diagonal Gaussian mixture, and the improved Fisher
vector's normalisation (`fisher-bovw`'s module docstring, 3)."""

from __future__ import annotations

import numpy as np


def power_l2(vectors: np.ndarray) -> np.ndarray:
    """The improved Fisher vector's normalisation: signed square root, then unit length."""
    rooted = np.sign(vectors) * np.sqrt(np.abs(vectors))
    return rooted / (np.linalg.norm(rooted, axis=-1, keepdims=True) + 1e-12)


def fisher_vectors(
    descriptors: np.ndarray, weights: np.ndarray, means: np.ndarray, variances: np.ndarray
) -> np.ndarray:
    """(n, 2·K·d) Fisher vectors of n pictures' (n, P, d) descriptors under a diagonal Gaussian
    mixture (K weights, (K, d) means and variances): per component, the normalised gradients
    with respect to its mean, then to its standard deviation (Perronnin et al. 2010, eq. 16–17),
    each averaged over the P descriptors. Not yet power- or L2-normalised."""
    x = np.asarray(descriptors, dtype=np.float32)
    n, p, d = x.shape
    sigma = np.sqrt(variances).astype(np.float32)
    inv_var = (1.0 / variances).astype(np.float32)
    # log N(x | μ_k, σ_k²) + log w_k, expanded so that no (n, P, K, d) array is formed
    log_p = (
        -0.5 * ((x**2) @ inv_var.T - 2 * x @ (means * inv_var).T.astype(np.float32))
        - 0.5 * np.sum(means**2 * inv_var, axis=1)
        - np.sum(np.log(sigma), axis=1)
        + np.log(weights)
    ).astype(np.float32)
    log_p -= log_p.max(axis=2, keepdims=True)
    gamma = np.exp(log_p)
    gamma /= gamma.sum(axis=2, keepdims=True)
    s0 = gamma.sum(axis=1)  # (n, K)
    s1 = np.einsum("npk,npd->nkd", gamma, x)
    s2 = np.einsum("npk,npd->nkd", gamma, x**2)
    mu = means[None].astype(np.float32)
    g_mean = (s1 - mu * s0[..., None]) / sigma[None]
    g_sigma = (s2 - 2 * mu * s1 + mu**2 * s0[..., None]) * inv_var[None] - s0[..., None]
    g_mean /= (p * np.sqrt(weights))[None, :, None]
    g_sigma /= (p * np.sqrt(2 * weights))[None, :, None]
    return np.concatenate([g_mean.reshape(n, -1), g_sigma.reshape(n, -1)], axis=1)
