"""estim command line (click), a thin layer over :mod:`core`."""
