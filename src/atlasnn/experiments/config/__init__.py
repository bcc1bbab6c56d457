"""atlasnn.experiments.config._config."""
