"""Estimators: every one takes its settings in the constructor and returns an Estimate."""
