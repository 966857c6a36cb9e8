"""The compensator contract and the registry of methods by command-line name.

A compensator is a scikit-learn estimator on records: ``fit(train)`` learns the drift model,
``transform(record)`` returns the compensated record (``rate_dps`` compensated, the input's in
``rate_raw_dps``, every other channel and the metadata copied), ``compensate_rate_dps(record)``
the compensated rate alone as an array. Before ``fit`` both raise scikit-learn's
``NotFittedError``.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from ..errors import InputError
from ..record import Record

#: Compensator classes by their ``--method`` name.
METHODS: dict[str, type["Compensator"]] = {}


def register(name: str) -> Callable[[type], type]:
    """Class decorator: make a compensator available as ``--method name``.

    Parameters
    ----------
    name : str
        The command-line name, e.g. ``"poly-baseline"``.

    Returns
    -------
    callable
        The decorator, which returns the class unchanged.
    """
    def deco(cls: type) -> type:
        cls.method_name = name
        METHODS[name] = cls
        return cls
    return deco


def get_method(name: str) -> type["Compensator"]:
    """The compensator class registered as ``name``.

    Parameters
    ----------
    name : str
        A ``--method`` name.

    Returns
    -------
    type
        The compensator class.

    Raises
    ------
    InputError
        When no method has that name (the message lists the known ones).
    """
    _load_builtin_methods()
    if name not in METHODS:
        raise InputError(f"unknown method {name!r}; expected one of {sorted(METHODS)}", "--method")
    return METHODS[name]


def _load_builtin_methods() -> None:
    """Import the modules that register the built-in methods (lazy: they pull heavy libraries)."""
    import importlib
    for mod in ("poly", "emd_rbf", "vmd_wflp_cssvr", "physics"):
        try:
            importlib.import_module(f"{__package__}.{mod}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__package__}.{mod}":
                raise


class Compensator(BaseEstimator):
    """Base class of drift compensators (scikit-learn estimator contract on records).

    Subclasses implement :meth:`fit` and :meth:`transform`; constructor arguments are
    their hyper-parameters (so ``get_params``/``set_params``/``clone`` work).
    """

    method_name = "base"
    #: Whether the method accepts records with uneven time steps (gaps).
    handles_gaps = False

    def fit(self, record: Record) -> "Compensator":
        """Learn the drift model from a training record.

        Parameters
        ----------
        record : Record
            Training data with ``time_s``, ``temperature_C`` and ``rate_dps``.

        Returns
        -------
        Compensator
            ``self``.
        """
        raise NotImplementedError

    def compensate_rate_dps(self, record: Record) -> np.ndarray:
        """The compensated rate output in deg/s, one value per record row (NaN where a row is missing).

        Parameters
        ----------
        record : Record
            The record to compensate.

        Returns
        -------
        ndarray
            Compensated ``rate_dps``.
        """
        raise NotImplementedError

    def transform(self, record: Record) -> Record:
        """The compensated record: ``rate_dps`` compensated, the input's in ``rate_raw_dps``.

        Parameters
        ----------
        record : Record
            The record to compensate.

        Returns
        -------
        Record
            Every channel and metadata line of ``record`` copied, ``rate_dps`` replaced by
            :meth:`compensate_rate_dps`, ``rate_raw_dps`` added, and the metadata line
            ``compensation_method``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        check_is_fitted(self)
        return compensated_record(record, self.compensate_rate_dps(record), self.method_name)

    def selection_report(self) -> dict | None:
        """What the fitted method chose by validation, and every option's score (None if it chose nothing).

        Returns
        -------
        dict or None
            :meth:`fmvmg_sim.compensation.selection.Selection.report` of the fit.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        check_is_fitted(self)
        d = getattr(self, "diagnostics_", None) or getattr(self, "fit_diagnostics_", None) or {}
        return d.get("selection") or (d.get("drift_model") or {}).get("selection")

    def _fit_compensate_rate_dps(self, record: Record) -> np.ndarray:
        """Fit on ``record`` and compensate it (a method that can share work between the two overrides this)."""
        return self.fit(record).compensate_rate_dps(record)

    def fit_transform(self, record: Record) -> Record:
        """Fit on ``record`` and compensate the same record (in-sample).

        Parameters
        ----------
        record : Record
            Data to fit on and compensate.

        Returns
        -------
        Record
            As :meth:`transform`.
        """
        return compensated_record(record, self._fit_compensate_rate_dps(record), self.method_name)


def compensated_record(record: Record, rate_dps: np.ndarray, method: str) -> Record:
    """``record`` with ``rate_dps`` replaced by a compensated rate and the input's kept as ``rate_raw_dps``.

    Parameters
    ----------
    record : Record
        The record that was compensated.
    rate_dps : ndarray
        Its compensated rate, one value per row.
    method : str
        The method's name, written to the ``compensation_method`` metadata line.

    Returns
    -------
    Record
        A new record (the input is not changed).
    """
    cols = dict(record.columns)
    cols["rate_raw_dps"] = record["rate_dps"]
    cols["rate_dps"] = np.asarray(rate_dps, dtype=float)
    return Record(cols, {**record.metadata, "compensation_method": method}, record.path)
