"""The thesis tables as printed (CSV data, read with importlib.resources)."""
