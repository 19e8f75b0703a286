"""Device laws shared by the circuit models (one module per device)."""
