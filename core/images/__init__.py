"""Image models and filters of the 2-D sister papers (issue 15)."""
