"""Temperature-drift compensators that act on records (docs/formats.md section 3).

Every method is an estimator with scikit-learn's contract (``fit(record)``,
``transform(record)`` giving the compensated record, ``get_params``; ``NotFittedError`` before
``fit``), registered under its command-line name with :func:`register`. Compensation knows
nothing of how a record was made.
"""

from .base import METHODS, Compensator, compensated_record, get_method, register

__all__ = ["METHODS", "Compensator", "compensated_record", "get_method", "register"]
