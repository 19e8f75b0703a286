"""Fields on a 3-D grid (thesis Chapter 5): sparse operators, time steppers, the dipole."""
