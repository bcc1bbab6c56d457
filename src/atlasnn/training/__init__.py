"""atlasnn.training."""
