"""Importers that turn third-party logs into records (docs/formats.md section 2).

Modules
-------
bmi270 : Bosch BMI270 PuTTY serial logs (50 Hz, no time column)
"""

from .bmi270 import Bmi270Import, SkippedLine, read_bmi270_log

__all__ = ["Bmi270Import", "SkippedLine", "read_bmi270_log"]
