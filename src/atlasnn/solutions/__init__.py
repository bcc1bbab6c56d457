"""atlasnn.solutions."""
