"""Numerics both engines share, which know nothing of the gyro.

Modules
-------
discretize : exact discretisation of linear systems (zero- and first-order hold, noise covariances, their factors)
layout     : named fields packed into flat vectors (states, parameters, inputs of a compiled step)
"""
