"""Why the compiled loop returns to Python (`loop.run_intervals`), one code each."""

#: It recorded the rows asked for; the broad phase's skin is used up (refresh coal and go on);
#: the grasp phase completed or timed out; a pair penetrated deeper than a sphere radius; the
#: state became non-finite (nothing recorded); the energy grew in a passive phase, or past what
#: the finger drives could have put in (both recorded); an adaptive step fell below its least
#: size. The last five are divergences.
RAN, REFRESH, STOPPED, TOO_DEEP, NONFINITE, ENERGY, ENERGY_WORK, UNDERFLOW = range(8)
