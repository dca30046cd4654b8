"""The compiled core (Model, Data, the step and its stages, the integrators, the record loop)
and the run that drives it."""
