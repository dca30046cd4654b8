"""The multi-point contact model of paper Sec. 3.1, one module per stage."""
