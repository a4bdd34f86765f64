"""Assign supports to SKT template families and pick one template per family.

Fit on the training split only: each SKT resampled to ``T`` waypoints, positions relative
to ξ_0, flattened → PCA(2); k-means(k) on the training *supports* (each the mean embedding
of its SKTs), so that a family groups supports, not the individual SKTs of one support
(clustering SKTs let one support's SKTs straddle a boundary: agreement 0.90 vs 0.94 on the
same SKTs). A support's family is the majority vote of its SKTs' nearest centres (ties:
lowest family). The template of family k is the SKT, among the training
support whose mean embedding is nearest centre k (and that belongs to k), nearest that
centre. Val/test supports are labelled with the fitted PCA and centres.

A family is only learnable if the support's shape decides it: ``agreement`` is, per
support, the share of its SKTs that fall in its majority family (1.0: every SKT agrees).
"""

from collections import Counter
from dataclasses import dataclass

import numpy as np

from skt_lib.labels.templates import Pca, fit_pca, kmeans, silhouette
from skt_lib.geometry.skt import resample


def skt_features(keypoints: np.ndarray, T: int) -> np.ndarray:
    """(T·3,) flattened positions relative to ξ_0 after equal-arc resampling."""
    r = resample(np.asarray(keypoints, float), T)
    return (r - r[0]).reshape(-1)


@dataclass(frozen=True, eq=False)
class Families:
    pca: Pca
    centres: np.ndarray  # (k, 2)
    labels: dict[str, int]  # support_id -> family, every support given
    embeddings: dict[str, np.ndarray]  # support_id -> mean embedding (2,)
    skt_embeddings: dict[str, np.ndarray]  # support_id -> (G, 2) one row per SKT
    agreement: dict[str, float]  # support_id -> share of its SKTs in its majority family
    templates: np.ndarray  # (k, T, 3) relative to ξ_0
    template_support_ids: list[str]
    train_xy: np.ndarray  # (M, 2) embeddings of training SKTs
    train_labels: np.ndarray  # (M,)
    silhouette: float


def fit_families(skts: dict[str, list[np.ndarray]], train: set[str], T: int, k: int,
                 rng: np.random.Generator, n_init: int, max_iter: int) -> Families:
    """``skts``: support_id -> list of dense keypoint paths (ξ_0 first)."""
    ids = sorted(skts)
    feats = {sid: np.stack([skt_features(s, T) for s in skts[sid]]) for sid in ids}
    train_ids = [sid for sid in ids if sid in train]
    if not train_ids:
        raise ValueError("train: no training support has an SKT")
    x = np.vstack([feats[sid] for sid in train_ids])
    pca = fit_pca(x)
    xy = pca.transform(x)
    means = np.stack([pca.transform(feats[sid]).mean(0) for sid in train_ids])
    centres, _ = kmeans(means, k, rng, n_init, max_iter)
    train_labels = ((xy[:, None] - centres[None]) ** 2).sum(2).argmin(1)
    labels, emb, skt_emb, agreement = {}, {}, {}, {}
    for sid in ids:
        e = pca.transform(feats[sid])
        votes = ((e[:, None] - centres[None]) ** 2).sum(2).argmin(1)
        counts = Counter(votes.tolist())
        labels[sid] = min(counts, key=lambda c: (-counts[c], c))
        agreement[sid] = counts[labels[sid]] / len(votes)
        emb[sid], skt_emb[sid] = e.mean(0), e
    templates, template_ids = [], []
    for j in range(k):
        members = [sid for sid in train_ids if labels[sid] == j] or train_ids
        best = min(members, key=lambda sid: (np.linalg.norm(emb[sid] - centres[j]), sid))
        e = pca.transform(feats[best])
        pick = int(np.linalg.norm(e - centres[j], axis=1).argmin())
        templates.append(feats[best][pick].reshape(T, 3))
        template_ids.append(best)
    return Families(pca, centres, labels, emb, skt_emb, agreement, np.stack(templates), template_ids, xy,
                    train_labels, silhouette(xy, train_labels))
