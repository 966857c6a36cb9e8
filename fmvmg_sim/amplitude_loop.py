"""The drive amplitude loop's closure, described once for every model that runs it.

The closure: the phase-shifted pickoff ``v_ps`` -> full-wave rectifier (3) -> amplitude low-pass (4)
-> comparison with the set-point Vref (5, 6) -> PI controller with output clamp and anti-windup (7)
-> carrier normaliser ``n = Vdac / max(|v|, floor)`` -> modulator gain ``K_mod`` (8) -> comb drive.
Each element's behaviour belongs to its block (:mod:`blocks`); this module holds how they are chained,
with one face per model that runs the loop:

* the set-point relation: the ``v_ps`` amplitude (and drive amplitude) the loop holds for a Vref, and
  the detector level a ``v_ps`` amplitude gives (the averaged steady state, the envelope's steady state,
  the normaliser's floor, the tuning tools);
* the phasor face: the carrier normaliser's gain over a cycle and the PI output's 2-omega ripple
  (:mod:`fmvmg_sim.averaged`);
* the envelope face: the loop's linear rows in the averaged model (sensor gain, filter, PI) and the
  integrator state that holds an effort (:mod:`fmvmg_sim.envelope.model`);
* the step face (:class:`AmplitudeLoopStep`): the loop inside a compiled step function, its numbers read
  from the step's packed parameters (numbers or CasADi symbols). The carrier steps advance
  detector -> filter -> comparator -> PI over a step; the envelope steps take the PI's clamp state
  and the mean of its output from it. The parameter fields it reads are declared here
  (:data:`DETECTOR_FIELDS` etc.) and spliced into each step's layout.

A change to the closure (a detector offset, another filter) is made here and reaches every model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from blocks import FullWaveRectifier, LowPass2, PIController
from blocks.ops import numpy_ops

from .numerics.discretize import zoh
from .numerics.layout import Layout, lpf_step

#: Floor of the carrier normaliser's amplitude detector, as a fraction of the phase-shifted pickoff's
#: amplitude at the set-point: below it the 'normalized' carrier shrinks with the pickoff instead of
#: amplifying noise (every model applies it).
NORMALISER_FLOOR_REL = 0.1

#: The rectifier's fields in a carrier step's parameters: its carrier-face constants, gain and offset.
DETECTOR_FIELDS = [("rect_k", (4,)), ("rect_gain", ()), ("rect_offset", ())]
#: The amplitude low-pass, discretised for the step.
SMOOTHING_FIELDS = [("Phi_amp", (2, 2)), ("Gam_amp", (2,))]
#: The set-point and the PI controller (gains and output limits).
CONTROLLER_FIELDS = [("vref", ()), ("kp", ()), ("ki", ()), ("u_min", ()), ("u_max", ())]
#: The modulator gain and the carrier's amplitude.
MODULATOR_FIELDS = [("k_mod", ()), ("vdac", ())]
#: The carrier normaliser: on (1) or off (0, the pickoff as carrier), and its floor.
NORMALISER_FIELDS = [("normalized", ()), ("n_floor_V", ())]
#: Everything a carrier step with the rectifier loop reads, in layout order.
CARRIER_FIELDS = DETECTOR_FIELDS + SMOOTHING_FIELDS + CONTROLLER_FIELDS + MODULATOR_FIELDS + NORMALISER_FIELDS
#: The low-pass and the PI alone (:meth:`AmplitudeLoop.regulator`).
REGULATOR_LAYOUT = Layout(SMOOTHING_FIELDS + CONTROLLER_FIELDS)


class EnvelopeRows(NamedTuple):
    """The loop's linear rows in the averaged model (see :meth:`AmplitudeLoop.envelope_rows`).

    Attributes
    ----------
    sensor_gain : float
        Mean detector output per metre of drive amplitude.
    A, B : ndarray
        The amplitude low-pass's state matrix (2, 2) and input column (2,).
    offset_V : float
        The detector's output offset (a constant input of the low-pass).
    kp, ki : float
        The PI's gains: ``u = kp (Vref - r) + ki I`` while it is free.
    """

    sensor_gain: float
    A: np.ndarray
    B: np.ndarray
    offset_V: float
    kp: float
    ki: float


@dataclass(frozen=True)
class AmplitudeLoop:
    """The drive amplitude loop's closure at one operating point.

    Parameters
    ----------
    detector : FullWaveRectifier
        Amplitude detector (3) on ``v_ps``.
    smoothing : LowPass2
        Amplitude low-pass (4) on the detector's output.
    vref_V : float
        Set-point (6).
    controller : PIController
        PI (7) on ``Vref - r``, clamped with anti-windup.
    k_mod_per_V : float
        Modulator gain (8).
    vdac_V : float
        Carrier amplitude of the normaliser.
    normalized : bool
        The carrier is ``Vdac v_ps / max(|v|, floor)`` (True) or ``v_ps`` itself (False).
    floor_rel : float, optional
        The normaliser's floor as a fraction of the ``v_ps`` amplitude at the set-point.
    """

    detector: FullWaveRectifier
    smoothing: LowPass2
    vref_V: float
    controller: PIController
    k_mod_per_V: float
    vdac_V: float
    normalized: bool
    floor_rel: float = NORMALISER_FLOOR_REL

    # --- the set-point relation -------------------------------------------------------------
    def held_amplitude_V(self, vref_V: float | None = None) -> float:
        """Amplitude of ``v_ps`` the loop holds for a set-point: ``(Vref - offset) / describing gain``.

        Parameters
        ----------
        vref_V : float, optional
            Set-point (default: the loop's).

        Returns
        -------
        float
        """
        vref = self.vref_V if vref_V is None else vref_V
        return (vref - self.detector.offset_V) / self.detector.describing_gain()

    def held_drive_amplitude_m(self, response: complex, vref_V: float | None = None) -> float:
        """Drive amplitude the loop holds, given ``v_ps`` per metre of drive displacement.

        Parameters
        ----------
        response : complex
            ``v_ps`` per metre at the oscillation frequency (drive chain times phase shifter).
        vref_V : float, optional
            Set-point (default: the loop's).

        Returns
        -------
        float
        """
        return self.held_amplitude_V(vref_V) / abs(response)

    def detector_level_V(self, amplitude_V: float) -> float:
        """Mean detector (and low-pass) output for a ``v_ps`` amplitude: the inverse of :meth:`held_amplitude_V`.

        Parameters
        ----------
        amplitude_V : float

        Returns
        -------
        float
        """
        return self.detector.describing_gain() * amplitude_V + self.detector.offset_V

    def sensor_gain(self, response: complex) -> float:
        """Mean detector output per metre of drive amplitude (the loop's sensor, linearised).

        Parameters
        ----------
        response : complex
            ``v_ps`` per metre of drive displacement.

        Returns
        -------
        float
        """
        return self.detector.describing_gain() * abs(response)

    @property
    def floor_V(self) -> float:
        """Floor of the carrier normaliser ``n = Vdac / max(sqrt(v_x^2 + v_ps^2), floor)`` (V):
        :attr:`floor_rel` of the ``v_ps`` amplitude the loop holds."""
        return self.floor_rel * (self.vref_V - self.detector.offset_V) / self.detector.describing_gain()

    def floor_drive_amplitude_m(self, carrier: complex, response: complex) -> float:
        """The normaliser's floor as a drive amplitude: below it the carrier is ``(Vdac / floor) v_ps``.

        Parameters
        ----------
        carrier : complex
            The carrier's fundamental at the set-point.
        response : complex
            ``v_ps`` per metre of drive displacement.

        Returns
        -------
        float
        """
        return self.floor_V * abs(carrier) / (self.vdac_V * abs(response))

    def integrator_state(self, effort_V: float) -> float:
        """The PI integrator's state that holds an output ``effort_V`` at zero error.

        Parameters
        ----------
        effort_V : float

        Returns
        -------
        float
            ``effort / Ki`` (V s), zero for a proportional-only controller.
        """
        ki = self.controller.ki_per_s
        return effort_V / ki if ki > 0 else 0.0

    # --- the phasor face ----------------------------------------------------------------------
    def carrier_gain(self, v_x, v_ps):
        """The carrier normaliser's gain ``n`` for samples of ``v_x`` and ``v_ps`` over a cycle (no floor).

        Parameters
        ----------
        v_x, v_ps : ndarray

        Returns
        -------
        ndarray
            ``Vdac / sqrt(v_x^2 + v_ps^2)`` for the 'normalized' carrier, ones otherwise.
        """
        return self.vdac_V / np.sqrt(v_x ** 2 + v_ps ** 2) if self.normalized else np.ones_like(v_x)

    def effort_ripple(self, omega_rad_s: float, V_ps: complex) -> complex:
        """2-omega phasor of the PI output caused by the detector's ripple leaking through the low-pass.

        ``|cos| = 2/pi + (4/(3 pi)) cos(2 theta) - ...``: the ripple passes the amplitude low-pass and
        the PI.

        Parameters
        ----------
        omega_rad_s : float
            Oscillation frequency.
        V_ps : complex
            Phasor of the phase-shifted pickoff (the detector's input).

        Returns
        -------
        complex
        """
        R2 = self.detector.second_harmonic_gain() * abs(V_ps) * np.exp(2j * np.angle(V_ps))
        H2 = self.smoothing.frequency_response(2 * omega_rad_s)[0, 0]
        pi2 = self.controller.kp + self.controller.ki_per_s / (2j * omega_rad_s)
        return complex(-pi2 * H2 * R2)

    def drive_phasor(self, effort_V, carrier: complex, ripple: complex = 0.0) -> complex:
        """Fundamental of the modulator's output ``K_mod u c`` for a PI output ``effort_V`` (plus its 2-omega
        ``ripple``, which beats with the carrier down to the fundamental) and a carrier fundamental ``carrier``.

        Parameters
        ----------
        effort_V : float or complex
            The PI output's mean.
        carrier : complex
            The carrier's fundamental (:meth:`carrier_gain` times ``v_ps``, over a cycle).
        ripple : complex, optional
            The PI output's 2-omega phasor (:meth:`effort_ripple`).

        Returns
        -------
        complex
        """
        return self.k_mod_per_V * (effort_V * carrier + 0.5 * ripple * np.conj(carrier))

    def effort_for(self, V_ac: complex, carrier: complex, ripple: complex = 0.0) -> complex:
        """The PI output whose modulator output has the fundamental ``V_ac``: the inverse of :meth:`drive_phasor`.

        Parameters
        ----------
        V_ac : complex
        carrier : complex
        ripple : complex, optional

        Returns
        -------
        complex
            Real where the loop's phase balances.
        """
        return (V_ac / self.k_mod_per_V - 0.5 * ripple * np.conj(carrier)) / carrier

    # --- the envelope face --------------------------------------------------------------------
    def envelope_rows(self, response: complex) -> EnvelopeRows:
        """The loop's linear rows in the averaged model.

        The detector by its describing function (``sensor_gain A + offset`` into the low-pass), the
        low-pass as it is, the PI free as ``u = kp (Vref - r) + ki I``.

        Parameters
        ----------
        response : complex
            ``v_ps`` per metre of drive displacement at the oscillation frequency.

        Returns
        -------
        EnvelopeRows
        """
        lp = self.smoothing.linear_model()
        return EnvelopeRows(sensor_gain=self.sensor_gain(response), A=np.asarray(lp.A), B=np.asarray(lp.B)[:, 0],
                            offset_V=self.detector.offset_V, kp=self.controller.kp, ki=self.controller.ki_per_s)

    # --- the step face: packed parameters -----------------------------------------------------
    def smoothing_step(self, h_s: float) -> dict:
        """The amplitude low-pass discretised exactly for a step (fields :data:`SMOOTHING_FIELDS`).

        Parameters
        ----------
        h_s : float

        Returns
        -------
        dict
        """
        lp = self.smoothing.linear_model()
        Phi, Gam = zoh(np.asarray(lp.A), np.asarray(lp.B), h_s)
        return dict(Phi_amp=Phi, Gam_amp=Gam[:, 0])

    def controller_params(self) -> dict:
        """The set-point and the PI's numbers (fields :data:`CONTROLLER_FIELDS`).

        Returns
        -------
        dict
        """
        pi = self.controller
        return dict(vref=self.vref_V, kp=pi.kp, ki=pi.ki_per_s, u_min=pi.u_min_V, u_max=pi.u_max_V)

    def modulator_params(self) -> dict:
        """The modulator gain and the carrier amplitude (fields :data:`MODULATOR_FIELDS`).

        Returns
        -------
        dict
        """
        return dict(k_mod=self.k_mod_per_V, vdac=self.vdac_V)

    def carrier_params(self, omega_rad_s: float, h_s: float) -> dict:
        """Every field of :data:`CARRIER_FIELDS` for a carrier step of ``h_s`` at ``omega_rad_s``.

        Parameters
        ----------
        omega_rad_s : float
            The oscillation frequency (the rectifier's carrier face assumes it over a step).
        h_s : float
            Step length.

        Returns
        -------
        dict
        """
        return dict(rect_k=FullWaveRectifier.carrier_constants(omega_rad_s, h_s), rect_gain=self.detector.gain,
                    rect_offset=self.detector.offset_V, **self.smoothing_step(h_s), **self.controller_params(),
                    **self.modulator_params(), normalized=1.0 if self.normalized else 0.0, n_floor_V=self.floor_V)

    def regulator(self, h_s: float, controller: PIController | None = None) -> "AmplitudeLoopStep":
        """The low-pass, comparator and PI as a numeric step face for steps of ``h_s`` (no detector).

        For a model that detects the amplitude its own way (an averaged start-up, a PLL's amplitude channel).

        Parameters
        ----------
        h_s : float
            Step length.
        controller : PIController, optional
            Another PI in place of the loop's (other gains under study).

        Returns
        -------
        AmplitudeLoopStep
        """
        loop = self if controller is None else replace(self, controller=controller)
        fields = {**loop.smoothing_step(h_s), **loop.controller_params()}
        return AmplitudeLoopStep(REGULATOR_LAYOUT, REGULATOR_LAYOUT.pack(fields))


class AmplitudeLoopStep:
    """The loop inside a step function: its numbers read from the step's packed parameters.

    Works on numbers (numpy backend) and on CasADi symbols alike; it reads only the fields it is
    asked for, so a step declares in its layout just the groups it uses (:data:`CARRIER_FIELDS`, or
    :data:`SMOOTHING_FIELDS` and :data:`CONTROLLER_FIELDS` for a loop with its own detector).

    Parameters
    ----------
    layout : Layout
        The step's parameter layout.
    p : sequence
        The packed parameters.
    """

    def __init__(self, layout, p):
        self._P = layout.unpack
        self._p = p
        P = self._param
        self.vref = P("vref")
        self.controller = PIController(kp=P("kp"), ki_per_s=P("ki"), u_min_V=P("u_min"), u_max_V=P("u_max"))

    def _param(self, name):
        return self._P(self._p, name)

    # --- the carrier face ---------------------------------------------------------------------
    def detect(self, v0, v1, ops=numpy_ops):
        """The rectifier's mean output over a step with ``v_ps`` going from ``v0`` to ``v1``.

        Parameters
        ----------
        v0, v1 : float or symbolic
        ops : object, optional
            Math backend.

        Returns
        -------
        float or symbolic
        """
        P = self._param
        rect = FullWaveRectifier(gain=P("rect_gain"), offset_V=P("rect_offset"))
        return rect.carrier_mean(v0, v1, P("rect_k"), ops)

    def regulate(self, s_amp, integ, detected, h_s, ops=numpy_ops):
        """Low-pass, comparator and PI over a step driven by the detector's mean output ``detected``.

        Parameters
        ----------
        s_amp : sequence
            The low-pass's two states at the step's start.
        integ, detected : float or symbolic
            The PI's integrator at the start; the detector's mean output over the step.
        h_s : float or symbolic
            Step length.
        ops : object, optional
            Math backend (numpy or CasADi).

        Returns
        -------
        tuple
            ``(s_amp, integ, u)`` at the step's end (``s_amp[0]`` the amplitude estimate ``r``).
        """
        Phi, Gam = self._param("Phi_amp"), self._param("Gam_amp")
        s1 = lpf_step(Phi, Gam, s_amp, detected)
        integ1, u1 = self.controller.carrier_step(integ, self.vref - s1[0], h_s, ops)
        return s1, integ1, u1

    def advance(self, s_amp, integ, v0, v1, h_s, ops=numpy_ops):
        """Detector, low-pass, comparator and PI over a step with ``v_ps`` going from ``v0`` to ``v1``.

        Parameters
        ----------
        s_amp : sequence
        integ : float or symbolic
        v0, v1 : float or symbolic
            ``v_ps`` at the step's start and end.
        h_s : float or symbolic
        ops : object, optional

        Returns
        -------
        tuple
            ``(s_amp, integ, u)`` at the step's end.
        """
        return self.regulate(s_amp, integ, self.detect(v0, v1, ops), h_s, ops)

    def normaliser(self, v_x, v_ps, ops=numpy_ops):
        """The carrier normaliser's gain ``n``: ``Vdac / max(|v|, floor)``, or 1 for the pickoff carrier.

        Parameters
        ----------
        v_x, v_ps : float or symbolic
        ops : object, optional

        Returns
        -------
        float or symbolic
        """
        P = self._param
        amp = ops.fmax(ops.sqrt(v_x * v_x + v_ps * v_ps), P("n_floor_V"))
        norm = P("normalized")
        return norm * P("vdac") / amp + (1 - norm)

    def modulator_gain(self, u, n):
        """The modulator's gain on ``v_ps``: ``K_mod u n``.

        Parameters
        ----------
        u, n : float or symbolic
            PI output and normaliser gain.

        Returns
        -------
        float or symbolic
        """
        return self._param("k_mod") * u * n

    # --- the envelope face --------------------------------------------------------------------
    def clamp_state(self, r, integ, vref):
        """The PI's unclamped output and clamp state at amplitude estimate ``r``, integrator ``integ``.

        Parameters
        ----------
        r, integ, vref : float or symbolic
            Amplitude estimate, integrator state, set-point.

        Returns
        -------
        tuple
            ``(u_free, high, low, hold)``, the flags as 0/1 numbers.
        """
        e = vref - r
        pi = self.controller
        u_free = pi.kp * e + pi.ki_per_s * integ
        high, low, hold = pi.clamp_state(u_free, e)
        return u_free, 1.0 * high, 1.0 * low, 1.0 * hold

    def clamp(self, u, ops=numpy_ops):
        """The PI's output clamped to its limits.

        Parameters
        ----------
        u : float or symbolic
        ops : object, optional

        Returns
        -------
        float or symbolic
        """
        return ops.fmin(ops.fmax(u, self.controller.u_min_V), self.controller.u_max_V)

    def limit(self, high, ops=numpy_ops):
        """The limit the PI is clamped at: the upper where ``high``, else the lower.

        Parameters
        ----------
        high : float or symbolic
        ops : object, optional

        Returns
        -------
        float or symbolic
        """
        return ops.if_else(high, self.controller.u_max_V, self.controller.u_min_V)

    def effort_integral(self, v0, v1, dt, dJ, dK, clamped, U, ops=numpy_ops):
        """The PI output's integral over a step of ``dt``: the held limit ``U``, or
        ``Kp (Vref - r) + Ki I`` integrated exactly (Vref linear from ``v0`` to ``v1``, ``dJ`` and ``dK``
        the step's integrals of ``r`` and of ``I``).

        Parameters
        ----------
        v0, v1, dt, dJ, dK : float or symbolic
        clamped : float or symbolic
            Nonzero where the PI is clamped over the step.
        U : float or symbolic
            The limit it is clamped at.
        ops : object, optional

        Returns
        -------
        float or symbolic
        """
        free = self.controller.kp * (0.5 * (v0 + v1) * dt - dJ) + self.controller.ki_per_s * dK
        return ops.if_else(clamped > 0, U * dt, free)


__all__ = ["AmplitudeLoop", "AmplitudeLoopStep", "EnvelopeRows", "NORMALISER_FLOOR_REL", "CARRIER_FIELDS",
           "DETECTOR_FIELDS", "SMOOTHING_FIELDS", "CONTROLLER_FIELDS", "MODULATOR_FIELDS", "NORMALISER_FIELDS"]
