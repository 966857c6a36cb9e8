"""Math backends for carrier faces: blocks call ``ops.sqrt`` etc. instead of importing a library.

The default backend is numpy (scalars or arrays). The compiled engine passes an object
with the same attribute names backed by CasADi, so the same block code builds the
symbolic step function.
"""

from __future__ import annotations

import numpy as np


class NumpyOps:
    """Numpy implementation of the operations carrier faces may use."""

    sqrt = staticmethod(np.sqrt)
    fabs = staticmethod(np.abs)
    fmin = staticmethod(np.minimum)
    fmax = staticmethod(np.maximum)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    tan = staticmethod(np.tan)

    @staticmethod
    def if_else(cond, a, b):
        """Element-wise ``a if cond else b``."""
        return np.where(cond, a, b)


numpy_ops = NumpyOps()
