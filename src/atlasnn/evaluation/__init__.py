"""atlasnn.evaluation."""
