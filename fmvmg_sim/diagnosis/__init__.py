"""Sim-to-real gap diagnosis (issue 7): calibrate, localise, attribute, report, benchmark.

Modules, one job each:

* :mod:`.parameters` - the nominal parameters the calibration may move (device tolerances) and
  the effect parameters, as *knobs* that act on a :class:`~fmvmg_sim.device.Device`;
* :mod:`.forward` - the quasi-static forward model: steady states on a temperature grid plus
  linear sensitivities, predicting every channel of a long record in milliseconds;
* :mod:`.data` - a record made ready for diagnosis (checks, gaps, NaNs, blocks, regimes, folds);
* :mod:`.likelihood` - AR(1) Gaussian likelihood per channel (residuals of slow records are coloured);
* :mod:`.calibrate` - MAP calibration of the nominal parameters with uncertainties and identifiability flags;
* :mod:`.candidates` - each library effect as a fittable candidate;
* :mod:`.localize` - the gap against a re-simulated null, by channel, Allan band and regime (Holm);
* :mod:`.attribute` - joint fits, forward-chained held-out scoring, acceptance, selection, ambiguity;
* :mod:`.pipeline` - the whole diagnosis of one record; :mod:`.report`, :mod:`.plots` - outputs;
* :mod:`.cases`, :mod:`.benchmark` - labelled cases and their scoring on Dask.
"""
