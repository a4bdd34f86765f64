"""SKT template families: PCA(2) + seeded k-means on flattened SKTs (paper §V-B, Fig. 4).

Plain numpy, deterministic under a ``numpy.random.Generator``; no empty clusters.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Pca:
    mean: np.ndarray  # (D,)
    components: np.ndarray  # (2, D), rows orthonormal

    def transform(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) - self.mean) @ self.components.T


def fit_pca(x: np.ndarray, n_components: int = 2) -> Pca:
    x = np.asarray(x, dtype=np.float64)
    mean = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - mean, full_matrices=False)
    comps = vt[:n_components]
    # sign convention: the largest-magnitude entry of each component is positive
    signs = np.sign(comps[np.arange(len(comps)), np.abs(comps).argmax(axis=1)])
    return Pca(mean, comps * signs[:, None])


def _kmeans_once(x, k, rng, max_iter):
    centres = [x[rng.integers(len(x))]]
    for _ in range(1, k):  # k-means++
        d2 = np.min([((x - c) ** 2).sum(1) for c in centres], axis=0)
        centres.append(x[rng.choice(len(x), p=d2 / d2.sum())] if d2.sum() > 0 else x[rng.integers(len(x))])
    centres = np.array(centres)
    for _ in range(max_iter):
        labels = ((x[:, None] - centres[None]) ** 2).sum(2).argmin(1)
        new = centres.copy()
        for j in range(k):
            members = x[labels == j]
            if len(members):
                new[j] = members.mean(0)
            else:  # empty: take the point farthest from its centre
                far = ((x - centres[labels]) ** 2).sum(1).argmax()
                new[j] = x[far]
                labels[far] = j
        if np.allclose(new, centres):
            break
        centres = new
    labels = ((x[:, None] - centres[None]) ** 2).sum(2).argmin(1)
    return centres, labels, float(((x - centres[labels]) ** 2).sum())


def kmeans(x: np.ndarray, k: int, rng: np.random.Generator, n_init: int = 10,
           max_iter: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """(centres (k, D), labels (N,)) of the best of ``n_init`` k-means++ runs; every
    cluster non-empty. Clusters are renumbered by their centre's first coordinate so the
    numbering does not depend on initialisation order."""
    x = np.asarray(x, dtype=np.float64)
    if not 1 <= k <= len(x):
        raise ValueError(f"k: need 1 <= k <= {len(x)} points, got {k}")
    best = min((_kmeans_once(x, k, rng, max_iter) for _ in range(n_init)), key=lambda r: r[2])
    centres, labels, _ = best
    if len(np.unique(labels)) < k:
        raise ValueError(f"k-means left a cluster empty (k={k}, {len(x)} points)")
    order = np.lexsort(centres.T[::-1])
    rank = np.empty(k, dtype=int)
    rank[order] = np.arange(k)
    return centres[order], rank[labels]


def silhouette(x: np.ndarray, labels: np.ndarray) -> float:
    """Mean silhouette coefficient (Euclidean); 0 for a single cluster."""
    x, labels = np.asarray(x, float), np.asarray(labels)
    ks = np.unique(labels)
    if len(ks) < 2:
        return 0.0
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    s = np.zeros(len(x))
    for i in range(len(x)):
        same = labels == labels[i]
        n_same = same.sum() - 1
        if n_same == 0:
            continue
        a = d[i, same].sum() / n_same
        b = min(d[i, labels == k].mean() for k in ks if k != labels[i])
        s[i] = (b - a) / max(a, b)
    return float(s.mean())
