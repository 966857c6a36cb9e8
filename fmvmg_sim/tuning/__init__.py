"""PI tuning of the drive amplitude loop (AGC): linearised loop, robust gains, checks in simulation.

* :mod:`.linear_loop` -- the amplitude loop linearised around the averaged steady state,
  built from the diagram's blocks as python-control systems; margins and step metrics.
* :mod:`.robust` -- Kp, Ki minimising the worst-case settling time over temperature
  and a Q_d tolerance (CasADi NLP, IPOPT), checked afterwards with python-control.
* :mod:`.verify` -- the carrier engine's start-up and a Vref step with given gains,
  measured with the same step metrics as the linear model.
* :mod:`.startup` -- the start-up (PI saturated) on the averaged large-signal model.
* :mod:`.report` -- robust gains beside the pole-zero rule and the scenario's gains (``fmvmg tune``).
* :mod:`.sweep` -- a gain grid evaluated on Dask (``fmvmg tune --sweep``).
* :mod:`.plots` -- Bode, step, start-up and sweep heat-map PNGs.
"""

from .linear_loop import LinearLoop, LoopMetrics, PlantParameters, analyze_loop, build_loop, plant_parameters

__all__ = ["LinearLoop", "LoopMetrics", "PlantParameters", "analyze_loop", "build_loop", "plant_parameters"]
