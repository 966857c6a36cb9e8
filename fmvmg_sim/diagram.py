"""The wiring of paper 000's Figure 3 (blocks 1-14) from the block library.

``build_diagram(device, T, board_C=Tb)`` instantiates every block with its parameters at the
die temperature ``T`` (MEMS) and the board temperature ``Tb`` (electronics, default ``T``) and
knows how they connect. Both engines and the tuning tools use
it: the carrier engine discretises :meth:`Diagram.core_system` exactly and runs the
nonlinear blocks' carrier faces; the averaged model (:mod:`fmvmg_sim.averaged`) uses
the blocks' frequency responses and describing functions.

Signal flow::

    resonator.x -> drive_pickoff -> (+ drive noise) -> drive_amp (1) = v_x
    v_x -> phase_shifter (2) = v_ps -> rectifier (3) -> amplitude_lpf (4) = r
    e = Vref (6) - r (5) -> PI (7) = u
    carrier c = n * v_ps  (n = Vdac/|v| for the 'normalized' carrier, 1 for 'pickoff')
    v_ac = K_mod u c (8) ; F_x = comb_drive(VDC (9) +- v_ac) (10)
    resonator.y -> sense_pickoff (+ feedthrough of v_ac) -> (+ sense noise) -> sense_amp1 (11) -> sense_amp2 (12) = v_s
    rate_V = output_lpf(K_m v_s ref_I) (13, 14); quadrature_V likewise with ref_Q

The core (resonator, pickoffs, amplifiers, phase shifter, modulator gain, comb drive)
is linear for a given modulator gain ``g = K_mod u n`` and rate, both slowly varying.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import control
import numpy as np

from blocks import (AllPassPhaseShifter, CapacitivePickoff, DifferentialAmplifier, ElectrostaticDrive,
                    FullWaveRectifier, LowPass2, Multiplier, PIController, SummingJunction, TwoModeResonator)

from .amplitude_loop import NORMALISER_FLOOR_REL, AmplitudeLoop
from .device import Device, OperatingPoint
from .rebalance import build_sense_loop

#: External inputs of the linear core, in order.
CORE_INPUTS = ("F_x_ext", "F_y_ext", "n_drive", "n_sense")
#: Outputs of the linear core, in order.
CORE_OUTPUTS = ("v_x", "v_ps", "v_s", "x", "y", "v_ac")


@dataclass
class Diagram:
    """All blocks of the FMVMG drive loop and sense chain at one operating point.

    Parameters
    ----------
    op : OperatingPoint
        Parameter values at the temperature.
    phase_trim_rad : float
        Demodulation reference phase trim (designed at the reference temperature).
    """

    op: OperatingPoint
    phase_trim_rad: float = 0.0

    def __post_init__(self) -> None:
        m, c = self.op["mechanics"], self.op["circuit"]
        self.resonator = TwoModeResonator(**m)
        self.drive_pickoff = CapacitivePickoff(name="drive_pickoff", sign=1.0, c_feedthrough_F=0.0,
                                               **c["drive_pickoff"])
        self.drive_noise_sum = SummingJunction(name="drive_noise_sum", signs=(1.0, 1.0))
        self.drive_amp = DifferentialAmplifier(name="drive_amp", **c["drive_amp"])
        ps = c["phase_shifter"]
        self.phase_shifter = AllPassPhaseShifter.designed_for(ps["design_frequency_Hz"], ps["rc_tc_per_K"],
                                                              ps["delta_T_K"], ps["trim_rad"])
        self.rectifier = FullWaveRectifier(**c["rectifier"])
        self.amplitude_lpf = LowPass2(name="amplitude_lpf", f_c_Hz=c["amplitude_lpf"]["f_c_Hz"], gain=1.0)
        self.comparator = SummingJunction(name="comparator", signs=(1.0, -1.0))
        self.vref_V = float(c["reference"]["vref_V"])
        self.pi = PIController(**c["pi"])
        mod = c["modulator"]
        self.modulator = Multiplier(name="modulator", k_per_V=mod["k_per_V"])
        self.carrier_mode = mod["carrier"]
        self.vdac_V = float(mod["vdac_V"])
        self.comb_drive = ElectrostaticDrive(**c["comb_drive"])
        self.sense_pickoff = CapacitivePickoff(name="sense_pickoff", **c["sense_pickoff"])
        self.sense_noise_sum = SummingJunction(name="sense_noise_sum", signs=(1.0, 1.0))
        self.sense_amp1 = DifferentialAmplifier(name="sense_amp1", **c["sense_amp1"])
        self.sense_amp2 = DifferentialAmplifier(name="sense_amp2", **c["sense_amp2"])
        self.demodulator = Multiplier(name="demodulator", k_per_V=c["demodulator"]["k_per_V"])
        self.output_lpf = LowPass2(name="output_lpf", **c["output_lpf"])
        self.noise = self.op["noise"]
        #: Force-to-rebalance and quadrature control (:mod:`fmvmg_sim.rebalance`); None for the open loop.
        self.sense_loop = build_sense_loop(c)

    @property
    def temperature_C(self) -> float:
        """Die temperature of this operating point."""
        return self.op.temperature_C

    @property
    def board_temperature_C(self) -> float:
        """Board temperature of this operating point (the die's when not given apart)."""
        b = self.op.board_temperature_C
        return self.op.temperature_C if b is None else b

    @property
    def omega_drive_rad_s(self) -> float:
        """Drive-mode natural angular frequency."""
        return 2 * np.pi * self.resonator.f_drive_Hz

    def core_system(self, g: float, rate_rad_s: float = 0.0, k_drive_extra_N_per_m: float = 0.0,
                    dk_quad_N_per_m: float = 0.0, v_ac_input: bool = False) -> control.StateSpace:
        """The linear core for modulator gain ``g`` (v_ac = g v_ps) and rate ``rate_rad_s``.

        Parameters
        ----------
        g : float
            Modulator gain ``K_mod u n`` (V/V).
        rate_rad_s : float, optional
            Input rate.
        k_drive_extra_N_per_m : float, optional
            Extra drive stiffness (Duffing describing function).
        dk_quad_N_per_m : float, optional
            Extra quadrature stiffness.
        v_ac_input : bool, optional
            Add an input ``v_ac`` summed into the modulator's output (after the inputs
            :data:`CORE_INPUTS`): the drive voltage of a PLL drive, with ``g = 0``.

        Returns
        -------
        control.StateSpace
            Inputs :data:`CORE_INPUTS` (and ``v_ac``), outputs :data:`CORE_OUTPUTS`.
        """
        res = self.resonator.linear_model()
        A = self.resonator.state_matrix(rate_rad_s, k_drive_extra_N_per_m)
        if dk_quad_N_per_m:
            A = A.copy()
            A[1, 2] -= dk_quad_N_per_m / self.resonator.m_drive_kg
            A[3, 0] -= dk_quad_N_per_m / self.resonator.m_sense_kg
        res = control.ss(A, res.B, res.C, res.D, name="resonator", inputs=list(res.input_labels),
                         outputs=list(res.output_labels), states=list(res.state_labels))
        gain_blk = control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), [[g, 1.0]], name="mod",
                              inputs=["in", "ext"], outputs=["out"])
        fx = control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), [[1.0, 1.0]], name="fx_sum",
                        inputs=["comb", "ext"], outputs=["out"])
        systems = [res, self.drive_pickoff.linear_model(), self.drive_noise_sum.linear_model(),
                   self.drive_amp.linear_model(), self.phase_shifter.linear_model(), gain_blk,
                   self.comb_drive.linear_model(), fx, self.sense_pickoff.linear_model(),
                   self.sense_noise_sum.linear_model(), self.sense_amp1.linear_model(),
                   self.sense_amp2.linear_model()]
        conn = [
            ["drive_pickoff.x", "resonator.x"], ["drive_pickoff.v_ft", "mod.out"],
            ["drive_noise_sum.in0", "drive_pickoff.out"], ["drive_amp.in", "drive_noise_sum.out"],
            ["phase_shifter.in", "drive_amp.out"], ["mod.in", "phase_shifter.out"],
            ["comb_drive.v_ac", "mod.out"], ["fx_sum.comb", "comb_drive.F_x"], ["resonator.F_x", "fx_sum.out"],
            ["sense_pickoff.x", "resonator.y"], ["sense_pickoff.v_ft", "mod.out"],
            ["sense_noise_sum.in0", "sense_pickoff.out"], ["sense_amp1.in", "sense_noise_sum.out"],
            ["sense_amp2.in", "sense_amp1.out"],
        ]
        return control.interconnect(
            systems, connections=conn, name="core",
            inplist=["fx_sum.ext", "resonator.F_y", "drive_noise_sum.in1", "sense_noise_sum.in1"]
            + (["mod.ext"] if v_ac_input else []),
            inputs=list(CORE_INPUTS) + (["v_ac"] if v_ac_input else []),
            outlist=["drive_amp.out", "phase_shifter.out", "sense_amp2.out", "resonator.x", "resonator.y", "mod.out"],
            outputs=list(CORE_OUTPUTS), check_unused=False)

    def core_state_scale(self) -> np.ndarray:
        """Typical magnitudes of the core states (for balancing), in the core's state order.

        Returns
        -------
        ndarray
        """
        return np.concatenate([self.resonator.state_scale(), np.ones(4)])

    def core_output_offset(self) -> np.ndarray:
        """Constant offsets of the core outputs (amplifier offsets through the chain).

        Returns
        -------
        ndarray
        """
        off = np.zeros(len(CORE_OUTPUTS))
        off[0] = self.drive_amp.offset_V
        off[1] = self.drive_amp.offset_V * self.phase_shifter.frequency_response(0.0)[0, 0].real
        off[2] = self.sense_amp1.offset_V * self.sense_amp2.gain + self.sense_amp2.offset_V
        return off

    @cached_property
    def amplitude_loop(self) -> AmplitudeLoop:
        """The drive amplitude loop's closure (rectifier, low-pass, set-point, PI, normaliser, modulator gain).

        Every model that runs the loop reads it from here (:mod:`fmvmg_sim.amplitude_loop`).
        """
        return AmplitudeLoop(detector=self.rectifier, smoothing=self.amplitude_lpf, vref_V=self.vref_V,
                             controller=self.pi, k_mod_per_V=self.modulator.k_per_V, vdac_V=self.vdac_V,
                             normalized=self.carrier_mode == "normalized", floor_rel=NORMALISER_FLOOR_REL)

    def normaliser_floor_V(self) -> float:
        """Floor of the carrier normaliser ``n = Vdac / max(sqrt(v_x^2 + v_ps^2), floor)`` (V).

        :data:`~fmvmg_sim.amplitude_loop.NORMALISER_FLOOR_REL` of the phase-shifted pickoff's amplitude
        at the set-point (the amplitude the rectifier and low-pass read as Vref).

        Returns
        -------
        float
        """
        return self.amplitude_loop.floor_V

    # --- envelope faces of the chains -------------------------------------------------
    def drive_chain_response(self, omega_rad_s: float) -> complex:
        """v_x per metre of drive displacement at ``omega_rad_s`` (pickoff and amplifier 1).

        Parameters
        ----------
        omega_rad_s : float

        Returns
        -------
        complex
        """
        return complex(self.drive_pickoff.gain_V_per_m * self.drive_amp.frequency_response(omega_rad_s)[0, 0])

    def phase_shifter_response(self, omega_rad_s: float) -> complex:
        """v_ps / v_x at ``omega_rad_s``.

        Parameters
        ----------
        omega_rad_s : float

        Returns
        -------
        complex
        """
        return complex(self.phase_shifter.frequency_response(omega_rad_s)[0, 0])

    def sense_amps_response(self, omega_rad_s: float) -> complex:
        """v_s per volt at the sense charge-amplifier output (amplifiers 11 and 12).

        Parameters
        ----------
        omega_rad_s : float

        Returns
        -------
        complex
        """
        return complex(self.sense_amp1.frequency_response(omega_rad_s)[0, 0]
                       * self.sense_amp2.frequency_response(omega_rad_s)[0, 0])


def _trim_for(device: Device) -> float:
    ref = Diagram(device.at(device.reference_temperature_C), 0.0)
    w = ref.omega_drive_rad_s
    return float(np.angle(ref.sense_amps_response(w)) - np.angle(ref.drive_chain_response(w))
                 - (np.angle(ref.phase_shifter_response(w)) - np.pi / 2))


def design_phase_trim(device: Device) -> float:
    """Reference phase trim that cancels the electronic phase mismatch at the reference temperature.

    The demodulation reference (the carrier) is rotated so that, at the reference
    temperature and drive frequency, it carries the same electronic phase lag as the
    sense chain; what remains is the mechanical sense phase and its drift.

    Parameters
    ----------
    device : Device

    Returns
    -------
    float
        Trim angle in rad (positive = reference leads).
    """
    setting = device.values["circuit"]["demodulator"]["phase_trim"]
    if setting != "auto":
        return float(setting)
    return _trim_for(device)


def build_diagram(device: Device, temperature_C: float, quad_delta_rel: float = 0.0,
                  board_C: float | None = None) -> Diagram:
    """All blocks of ``device`` at the die temperature ``temperature_C`` and the board temperature ``board_C``.

    Parameters
    ----------
    device : Device
    temperature_C : float
        Die temperature (the MEMS laws).
    quad_delta_rel : float, optional
        Relative change of the quadrature stiffness (hysteresis, stress relaxation).
    board_C : float, optional
        Board temperature (the electronics laws); default: the die temperature.

    Returns
    -------
    Diagram
    """
    op = device.at(temperature_C, board_C)
    if quad_delta_rel:
        op.values["mechanics"]["k_quad_N_per_m"] *= 1.0 + quad_delta_rel
    # the reference phase is trimmed once, at the reference temperature; its drift follows the board
    return Diagram(op, design_phase_trim(device) + op.values.get("demod_phase_drift_rad", 0.0))
