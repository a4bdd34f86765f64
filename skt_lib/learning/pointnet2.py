"""PointNet++ (single-scale grouping) in pure PyTorch: CPU-first, CUDA when present.

Shapes: ``xyz (B, N, 3)`` float32 (normalised cloud coordinates), features ``(B, C, N)``.
Farthest-point sampling runs in Open3D's C++ sampler on CPU tensors (the points never need
gradients) and in a vectorised torch loop elsewhere; ball query and grouping are vectorised.
Each op has a ``_naive`` reference used by the tests.
"""

import numpy as np
import open3d as o3d
import torch
from scipy.spatial import cKDTree
from torch import nn


def fps(xyz: torch.Tensor, npoint: int) -> torch.Tensor:
    """Farthest-point sample indices ``(B, npoint)`` int64, each started at index 0."""
    with torch.profiler.record_function("pointnet2.fps"):
        return _fps(xyz, npoint)


def _fps(xyz: torch.Tensor, npoint: int) -> torch.Tensor:
    if xyz.device.type != "cpu":
        return _fps_torch(xyz, npoint)
    out = np.empty((xyz.shape[0], npoint), dtype=np.int64)
    arr = xyz.detach().double().numpy()
    for b in range(arr.shape[0]):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(arr[b]))
        picked = np.asarray(pcd.farthest_point_down_sample(npoint).points)
        out[b] = np.sort(cKDTree(arr[b]).query(picked)[1])
    return torch.from_numpy(out)


def _fps_torch(xyz: torch.Tensor, npoint: int) -> torch.Tensor:
    b, n, _ = xyz.shape
    idx = torch.zeros(b, npoint, dtype=torch.long, device=xyz.device)
    dist = torch.full((b, n), float("inf"), device=xyz.device)
    far = torch.zeros(b, dtype=torch.long, device=xyz.device)
    rows = torch.arange(b, device=xyz.device)
    for i in range(npoint):
        idx[:, i] = far
        d = ((xyz - xyz[rows, far][:, None]) ** 2).sum(-1)
        dist = torch.minimum(dist, d)
        far = dist.argmax(-1)
    return idx.sort(dim=1).values


def fps_naive(xyz: torch.Tensor, npoint: int) -> torch.Tensor:
    """Reference: plain loops, sorted indices like :func:`fps`."""
    out = []
    for cloud in xyz:
        chosen, d = [0], ((cloud - cloud[0]) ** 2).sum(-1)
        for _ in range(npoint - 1):
            k = int(d.argmax())
            chosen.append(k)
            d = torch.minimum(d, ((cloud - cloud[k]) ** 2).sum(-1))
        out.append(sorted(chosen))
    return torch.tensor(out)


def ball_query(radius: float, nsample: int, xyz: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """Indices ``(B, S, nsample)`` of the first ``nsample`` points (in index order) within
    ``radius`` of each centre; short groups are padded with their first index. A centre is
    always one of the points, so no group is empty."""
    with torch.profiler.record_function("pointnet2.ball_query"):
        return _ball_query(radius, nsample, xyz, centres)


def _ball_query(radius, nsample, xyz, centres):
    b, n, _ = xyz.shape
    # exact differences: the matrix-product form leaves a point slightly off itself
    d2 = torch.cdist(centres, xyz, compute_mode="donot_use_mm_for_euclid_dist") ** 2
    idx = torch.arange(n, device=xyz.device).expand(b, centres.shape[1], n).clone()
    idx[d2 > radius**2] = n
    idx = idx.sort(dim=-1).values[..., :nsample]
    first = torch.where(idx[..., :1] == n, d2.argmin(-1, keepdim=True), idx[..., :1])
    return torch.where(idx == n, first.expand_as(idx), idx)


def ball_query_naive(radius, nsample, xyz, centres):
    out = torch.zeros(centres.shape[0], centres.shape[1], nsample, dtype=torch.long)
    for b in range(xyz.shape[0]):
        for s in range(centres.shape[1]):
            inside = [j for j in range(xyz.shape[1])
                      if float(((xyz[b, j] - centres[b, s]) ** 2).sum()) <= radius**2][:nsample]
            inside += [inside[0]] * (nsample - len(inside))
            out[b, s] = torch.tensor(inside)
    return out


def gather(points: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``points (B, N, C)``, ``idx (B, ...)`` -> ``(B, ..., C)``."""
    b = points.shape[0]
    flat = idx.reshape(b, -1)
    out = torch.gather(points, 1, flat[..., None].expand(-1, -1, points.shape[-1]))
    return out.reshape(*idx.shape, points.shape[-1])


def _mlp2d(widths):
    layers = []
    for a, c in zip(widths[:-1], widths[1:]):
        layers += [nn.Conv2d(a, c, 1), nn.BatchNorm2d(c), nn.ReLU()]
    return nn.Sequential(*layers)


def _mlp1d(widths):
    layers = []
    for a, c in zip(widths[:-1], widths[1:]):
        layers += [nn.Conv1d(a, c, 1), nn.BatchNorm1d(c), nn.ReLU()]
    return nn.Sequential(*layers)


class SetAbstraction(nn.Module):
    """Sample ``npoint`` centres, group ``nsample`` neighbours within ``radius``, shared MLP,
    max-pool. ``npoint=None`` groups everything around the origin (global feature)."""

    def __init__(self, npoint: int | None, radius: float, nsample: int, widths: list[int]):
        super().__init__()
        self.npoint, self.radius, self.nsample = npoint, radius, nsample
        self.mlp = _mlp2d(widths)

    def forward(self, xyz, feats):
        if self.npoint is None:
            grouped = xyz[:, None]  # (B, 1, N, 3)
            new_xyz = torch.zeros(xyz.shape[0], 1, 3, device=xyz.device)
            g_feats = feats.transpose(1, 2)[:, None] if feats is not None else None
        else:
            new_xyz = gather(xyz, fps(xyz, self.npoint).to(xyz.device))
            idx = ball_query(self.radius, self.nsample, xyz, new_xyz)
            grouped = gather(xyz, idx) - new_xyz[:, :, None]
            g_feats = gather(feats.transpose(1, 2), idx) if feats is not None else None
        x = grouped if g_feats is None else torch.cat([grouped, g_feats], -1)
        x = self.mlp(x.permute(0, 3, 2, 1))  # (B, C, K, S)
        return new_xyz, x.max(dim=2).values  # (B, S, 3), (B, C', S)


class FeaturePropagation(nn.Module):
    """Inverse-distance interpolation from 3 nearest coarse points, concat skip, MLP."""

    def __init__(self, widths: list[int]):
        super().__init__()
        self.mlp = _mlp1d(widths)

    def forward(self, xyz_fine, xyz_coarse, feats_fine, feats_coarse):
        d = torch.cdist(xyz_fine, xyz_coarse)
        k = min(3, xyz_coarse.shape[1])
        dist, idx = d.topk(k, dim=-1, largest=False)
        w = 1.0 / (dist + 1e-8)
        w = w / w.sum(-1, keepdim=True)
        interp = (gather(feats_coarse.transpose(1, 2), idx) * w[..., None]).sum(2).transpose(1, 2)
        x = interp if feats_fine is None else torch.cat([interp, feats_fine], 1)
        return self.mlp(x)
