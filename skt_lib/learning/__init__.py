"""Learning: pure-PyTorch PointNet++, SCTDN, datasets and the public predictor."""
