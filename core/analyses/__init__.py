"""Analyses: each turns a validated Experiment into result tables and figure data."""
