"""Temperature and rate profiles: piecewise holds, ramps, steps and sines, evaluated at any time.

A profile is given either as ``segments`` (holds, ramps, steps, sines, in order) or as
``points`` (``[[t_s, value], ...]`` with strictly increasing times, linear in between).
Both evaluate vectorised: ``profile(t_s)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError


@dataclass
class PiecewiseProfile:
    """Breakpoints with linear interpolation, plus optional sine terms on intervals.

    Parameters
    ----------
    times_s, values : ndarray
        Breakpoints (times non-decreasing; equal times make a step).
    sines : list of tuple
        ``(t_start_s, t_end_s, amplitude, frequency_Hz, phase_rad)`` added on top.
    """

    times_s: np.ndarray
    values: np.ndarray
    sines: list

    def __call__(self, t_s):
        """Profile value at ``t_s`` (held constant after the last breakpoint).

        Parameters
        ----------
        t_s : float or ndarray

        Returns
        -------
        float or ndarray
        """
        return self._evaluate(np.asarray(t_s, dtype=float), "right")

    def left_limit(self, t_s):
        """Value just before ``t_s`` (the value before a step at ``t_s``; sines included).

        Parameters
        ----------
        t_s : float or ndarray

        Returns
        -------
        float or ndarray
        """
        return self._evaluate(np.asarray(t_s, dtype=float), "left")

    def _evaluate(self, t: np.ndarray, side: str):
        """The right-continuous value (``side="right"``: a step at ``t`` taken) or the left limit."""
        if not self.sines and np.all(self.values == self.values[0]):  # constant: the common case of long runs
            out = np.full(t.shape, float(self.values[0]))
            return out if out.ndim else float(out)
        # the last breakpoint at or before t (right), or strictly before it (left)
        idx = np.clip(np.searchsorted(self.times_s, t, side=side) - 1, 0, len(self.times_s) - 1)
        nxt = np.clip(idx + 1, 0, len(self.times_s) - 1)
        t0, t1 = self.times_s[idx], self.times_s[nxt]
        v0, v1 = self.values[idx], self.values[nxt]
        span = np.where(t1 > t0, t1 - t0, 1.0)
        frac = np.where(t1 > t0, np.clip((t - t0) / span, 0.0, 1.0), 0.0)
        out = v0 + frac * (v1 - v0)
        if side == "left":
            out = np.where(t <= self.times_s[0], self.values[0], out)
        for (ta, tb, amp, f, ph) in self.sines:
            on = ((t >= ta) & (t < tb)) if side == "right" else ((t > ta) & (t <= tb))
            out = out + np.where(on, amp * np.sin(2 * np.pi * f * (t - ta) + ph), 0.0)
        return out if out.ndim else float(out)

    def jumps_s(self) -> np.ndarray:
        """Times at which the profile steps (breakpoints given twice with different values).

        Returns
        -------
        ndarray
        """
        same = np.diff(self.times_s) == 0
        step = same & (np.diff(self.values) != 0)
        return self.times_s[1:][step]

    def step_lines(self, t_edges_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares straight line of the profile over each interval between ``t_edges_s``.

        Returns its values at the start and at the end of each interval: the input of a
        first-order hold that carries the profile into a discretised model on time. Where
        the profile is linear over an interval (breakpoints and steps on the edges) these
        are the profile's own right-limit at the start and left-limit at the end, so steps
        and ramps enter exactly; an interval with a breakpoint or a sine inside gets the
        line with the profile's mean and first moment over it.

        Parameters
        ----------
        t_edges_s : ndarray
            Increasing interval edges (s), ``n + 1`` of them for ``n`` intervals.

        Returns
        -------
        tuple of ndarray
            ``(start, end)``, each of length ``n``.
        """
        te = np.asarray(t_edges_s, dtype=float)
        a, b = te[:-1], te[1:]
        if not self.sines and np.all(self.values == self.values[0]):  # constant: the common case of long runs
            return np.full(len(a), float(self.values[0])), np.full(len(a), float(self.values[0]))
        base = PiecewiseProfile(self.times_s, self.values, [])
        start, end = np.array(base(a), dtype=float), np.array(base.left_limit(b), dtype=float)
        # intervals with a breakpoint strictly inside: the moments of the piecewise-linear part, exactly
        tk = np.unique(self.times_s)
        k = np.searchsorted(b, tk, side="left")
        inside = k < len(a)
        tk, k = tk[inside], k[inside]
        inside = (a[k] < tk) & (tk < b[k])
        tk, k = tk[inside], k[inside]
        if tk.size:
            ks = np.unique(k)
            # the pieces [a, t1], [t1, t2], ..., [tn, b] of every such interval, as flat arrays
            p = np.concatenate([a[ks], tk])
            owner = np.concatenate([ks, k])
            order = np.lexsort((p, owner))
            p, owner = p[order], owner[order]
            last = np.r_[owner[1:] != owner[:-1], True]
            q = np.where(last, b[owner], np.r_[p[1:], 0.0])
            vp, vq, L = base(p), base.left_limit(q), q - p
            c = 0.5 * (a[owner] + b[owner])
            m0 = np.zeros(len(a))
            m1 = np.zeros(len(a))
            np.add.at(m0, owner, L * (vp + vq) / 2)
            np.add.at(m1, owner, (p - c) * L * (vp + vq) / 2 + L * L * (vp / 6 + vq / 3))
            start[ks], end[ks] = _line(m0[ks], m1[ks], b[ks] - a[ks])
        for (ta, tb, amp, f, ph) in self.sines:
            on = np.flatnonzero((b > ta) & (a < tb))
            if not on.size:
                continue
            lo, hi = np.maximum(a[on], ta), np.minimum(b[on], tb)
            c = 0.5 * (a[on] + b[on])
            w = 2 * np.pi * f
            # moments of amp sin(w (t - ta) + ph) over [lo, hi]: int sin, int (t - c) sin
            P = lambda t: w * (t - ta) + ph  # noqa: E731
            m0 = amp * (np.cos(P(lo)) - np.cos(P(hi))) / w
            m1 = amp * ((-(hi - c) * np.cos(P(hi)) + (lo - c) * np.cos(P(lo))) / w
                        + (np.sin(P(hi)) - np.sin(P(lo))) / w ** 2)
            s0, s1 = _line(m0, m1, b[on] - a[on])
            start[on] += s0
            end[on] += s1
        return start, end

    @property
    def end_s(self) -> float:
        """Time of the last breakpoint or sine end."""
        ends = [self.times_s[-1]] + [s[1] for s in self.sines]
        return float(max(ends))

    def derivative(self, t_s):
        """Slope of the piecewise-linear part (per second); sines excluded.

        Parameters
        ----------
        t_s : float or ndarray

        Returns
        -------
        float or ndarray
        """
        t = np.asarray(t_s, dtype=float)
        idx = np.clip(np.searchsorted(self.times_s, t, side="right") - 1, 0, len(self.times_s) - 1)
        nxt = np.clip(idx + 1, 0, len(self.times_s) - 1)
        dt = self.times_s[nxt] - self.times_s[idx]
        slope = np.where(dt > 0, (self.values[nxt] - self.values[idx]) / np.where(dt > 0, dt, 1.0), 0.0)
        slope = np.where(t >= self.times_s[-1], 0.0, slope)
        return slope if slope.ndim else float(slope)


def _line(m0, m1, h):
    """Start and end values of the line with integral ``m0`` and first moment ``m1`` (about the middle) over ``h``."""
    mean = m0 / h
    half_rise = 6.0 * m1 / h ** 2  # slope 12 m1 / h^3 times h / 2
    return mean - half_rise, mean + half_rise


def _num(seg: dict, key: str, where: str, positive: bool = False) -> float:
    v = seg[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"expected a number, got {v!r}", f"{where}.{key}")
    v = float(v)
    if not np.isfinite(v):
        raise InputError("expected a finite number", f"{where}.{key}")
    if positive and v <= 0:
        raise InputError(f"must be > 0, got {v!r}", f"{where}.{key}")
    return v


def build_profile(table: dict, where: str, start_key: str, value_key: str, unit_word: str,
                  allow_sines: bool) -> PiecewiseProfile:
    """Build a profile from a scenario table (``[temperature]`` or ``[rate]``).

    Parameters
    ----------
    table : dict
        The table: ``start_<unit>`` and ``segments``, or ``points``.
    where : str
        Key path for messages (``scenario.toml: temperature``).
    start_key : str
        Name of the starting value (``start_C`` / ``start_dps``).
    value_key : str
        Unit suffix used in segment keys (``C`` or ``dps``).
    unit_word : str
        Human unit for messages.
    allow_sines : bool
        Whether sine segments are allowed.

    Returns
    -------
    PiecewiseProfile

    Raises
    ------
    InputError
        Unknown segment keys, non-positive durations, or non-increasing points.
    """
    if "points" in table:
        pts = table["points"]
        if not isinstance(pts, list) or not pts or not all(isinstance(p, list) and len(p) == 2 for p in pts):
            raise InputError("expected [[t_s, value], ...]", f"{where}.points")
        arr = np.array(pts, dtype=float)
        if arr[0, 0] != 0:
            raise InputError("the first point must be at t = 0", f"{where}.points")
        bad = np.flatnonzero(np.diff(arr[:, 0]) <= 0)
        if bad.size:
            raise InputError(f"times must be strictly increasing (point {bad[0] + 2} at "
                             f"{arr[bad[0] + 1, 0]} s after {arr[bad[0], 0]} s)", f"{where}.points")
        return PiecewiseProfile(arr[:, 0], arr[:, 1], [])
    start = float(table.get(start_key, 0.0))
    times, values, sines = [0.0], [start], []
    t, v = 0.0, start
    for i, seg in enumerate(table.get("segments", [])):
        w = f"{where}.segments[{i}]"
        if not isinstance(seg, dict):
            raise InputError("each segment is a table like { hold_s = 60 }", w)
        keys = set(seg)
        if keys == {"hold_s"}:
            t += _num(seg, "hold_s", w, positive=True)
        elif keys == {f"ramp_to_{value_key}", f"rate_{value_key}_per_min"}:
            target = _num(seg, f"ramp_to_{value_key}", w)
            rate = abs(_num(seg, f"rate_{value_key}_per_min", w, positive=True))
            if target == v:
                raise InputError(f"ramp to the current value {v} {unit_word}", w)
            t += abs(target - v) / rate * 60.0
            v = target
        elif keys == {f"ramp_to_{value_key}", "duration_s"}:
            t += _num(seg, "duration_s", w, positive=True)
            v = _num(seg, f"ramp_to_{value_key}", w)
        elif keys == {f"step_to_{value_key}"}:
            v = _num(seg, f"step_to_{value_key}", w)
        elif allow_sines and {"sine_amplitude_dps", "sine_frequency_Hz", "duration_s"} <= keys <= {
                "sine_amplitude_dps", "sine_frequency_Hz", "duration_s", "phase_deg"}:
            dur = _num(seg, "duration_s", w, positive=True)
            f = _num(seg, "sine_frequency_Hz", w, positive=True)
            ph = np.deg2rad(float(seg.get("phase_deg", 0.0)))
            sines.append((t, t + dur, _num(seg, "sine_amplitude_dps", w), f, ph))
            t += dur
        else:
            forms = [f"{{ hold_s }}", f"{{ ramp_to_{value_key}, rate_{value_key}_per_min }}",
                     f"{{ ramp_to_{value_key}, duration_s }}", f"{{ step_to_{value_key} }}"]
            if allow_sines:
                forms.append("{ sine_amplitude_dps, sine_frequency_Hz, duration_s [, phase_deg] }")
            raise InputError(f"unknown segment keys {sorted(keys)}; expected one of: " + ", ".join(forms), w)
        times.append(t)
        values.append(v)
    return PiecewiseProfile(np.array(times), np.array(values), sines)
