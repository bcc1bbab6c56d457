"""Experiments: config schema (config.py), the runner (runner.py) and the paper's configs (configs/)."""
