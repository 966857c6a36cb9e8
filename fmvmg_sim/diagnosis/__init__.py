"""Sim-to-real gap diagnosis: calibrate, localise, attribute, report.

Modules, one job each (:mod:`.pipeline` runs them in order; docs/diagnosis_guide.md explains them):

* :mod:`.parameters` - the nominal model's knobs (:mod:`fmvmg_sim.uncertainty`) and the library effects acting on
  a :class:`~fmvmg_sim.device.Device`;
* :mod:`.forward` - the quasi-static forward model: steady states on a temperature grid plus linear sensitivities,
  predicting every channel of a long record in milliseconds;
* :mod:`.data` - a record made ready for diagnosis (checks, gaps, NaNs, blocks, regimes, folds);
* :mod:`.fitting`, :mod:`.model` - linearised weighted least squares of the knobs and of the effects beside them;
* :mod:`.calibrate` - the knobs fitted within their tolerances, with uncertainties and identifiability flags;
* :mod:`.null`, :mod:`.noise_match` - the calibrated unit re-simulated with its noise, with the record's own
  auxiliary-channel noise;
* :mod:`.localize`, :mod:`.windows` - the gap against the null, by channel, Allan band and regime (Holm);
* :mod:`.likelihood`, :mod:`.heldout` - the noise model and the forward-chained held-out scoring;
* :mod:`.evaluation`, :mod:`.criteria`, :mod:`.rules`, :mod:`.attribution` - each candidate's evaluation, the
  acceptance criteria, the decision rules and the attribution that runs them;
* :mod:`.noise_effects`, :mod:`.converter` - a coarser converter and extra flicker;
* :mod:`.detection` - the smallest effect each record would attribute;
* :mod:`.report`, :mod:`.plots` - the report (JSON and Markdown) and its figures.

The labelled benchmarks that check all this live apart, in :mod:`fmvmg_sim.validation`.
"""
