"""Studies over many runs of one scenario: accuracy against run time, and numerical stability."""
