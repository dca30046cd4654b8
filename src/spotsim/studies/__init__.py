"""Studies over many runs of one scenario: accuracy against run time, numerical stability, and
ensembles over perturbed starts."""
