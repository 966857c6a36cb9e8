"""Population studies: many units drawn from a device's tolerances, run over one scenario, judged against a
specification (:func:`fmvmg_sim.population.study.run_population`, ``fmvmg population``)."""
