"""fmvmg-sim: co-simulation of a four-mass vibratory MEMS gyroscope's drive loop and sense chain.

Sub-packages
------------
device, scenario, profiles : what is simulated (data in ``scenarios/``)
diagram                    : the wiring of paper 000's Figure 3 from ``blocks``
carrier, envelope          : the two engines that run the diagram
analysis, compensation, tuning, diagnosis : what users do with the records
cli                        : the ``fmvmg`` command
"""

__version__ = "0.1.0"
