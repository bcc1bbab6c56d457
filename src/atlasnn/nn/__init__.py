"""atlasnn.nn."""
