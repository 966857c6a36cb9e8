"""The block library of the FMVMG drive loop and sense chain (paper 000, Figure 3, blocks 1-14).

Each block is small and knows nothing of the engine that runs it. A block has up to
three faces, all derived from the same parameters:

* linear face: ``linear_model()`` returns a python-control ``StateSpace`` with named
  signals (linear blocks only); the carrier engine discretises it exactly;
* envelope face: ``frequency_response(omega)`` (linear blocks) or a describing
  function (rectifier, multiplier) used by the averaged model and the tuning tools;
* carrier face: for nonlinear blocks, a ``carrier_*`` function written with plain
  arithmetic and an ``ops`` backend (numpy by default, CasADi in the compiled engine).
"""

from .amplifier import DifferentialAmplifier
from .base import Block, LinearBlock
from .electrostatic import ElectrostaticDrive
from .filters import LowPass1, LowPass2
from .junction import SummingJunction
from .multiplier import Multiplier
from .phase_shifter import AllPassPhaseShifter
from .pi import PIController
from .pickoff import CapacitivePickoff
from .rebalance import QuadratureTuningElectrodes, RebalanceController
from .rectifier import FullWaveRectifier
from .resonator import TwoModeResonator

__all__ = [
    "Block", "LinearBlock", "DifferentialAmplifier", "AllPassPhaseShifter", "FullWaveRectifier",
    "LowPass1", "LowPass2", "SummingJunction", "PIController", "Multiplier", "ElectrostaticDrive",
    "CapacitivePickoff", "TwoModeResonator", "RebalanceController", "QuadratureTuningElectrodes",
]
