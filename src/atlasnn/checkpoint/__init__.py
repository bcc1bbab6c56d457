"""atlasnn.checkpoint._single."""
