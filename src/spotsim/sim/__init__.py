"""The compiled core: Model, Data, the kinematic tree, the step and its stages, the integrators,
the record loop, and coal's broad phase between its calls (`run.simulate` drives it)."""
