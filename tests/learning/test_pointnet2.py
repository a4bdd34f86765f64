import pytest
import torch

from skt_lib.learning.pointnet2 import (
    _fps_torch, ball_query, ball_query_naive, fps, fps_naive, gather,
)


@pytest.mark.parametrize("n,npoint", [(64, 16), (500, 128)])
def test_fps_fast_and_torch_match_naive(n, npoint):
    xyz = torch.randn(2, n, 3, generator=torch.Generator().manual_seed(n))
    ref = fps_naive(xyz, npoint)
    assert torch.equal(fps(xyz, npoint), ref)
    assert torch.equal(_fps_torch(xyz, npoint), ref)


def test_ball_query_matches_naive():
    g = torch.Generator().manual_seed(0)
    xyz = torch.rand(2, 80, 3, generator=g)
    centres = xyz[:, :10]
    assert torch.equal(ball_query(0.3, 8, xyz, centres), ball_query_naive(0.3, 8, xyz, centres))
    idx = ball_query(1e-6, 4, xyz, centres)  # only the centre itself
    assert torch.equal(idx, torch.arange(10).expand(2, 10)[..., None].expand(2, 10, 4))


def test_gather_shapes():
    pts = torch.arange(24.0).reshape(2, 4, 3)
    idx = torch.tensor([[[0, 3]], [[1, 1]]])
    out = gather(pts, idx)
    assert out.shape == (2, 1, 2, 3) and torch.equal(out[1, 0, 0], pts[1, 1])
