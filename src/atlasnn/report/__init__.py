"""atlasnn.report._tables."""
