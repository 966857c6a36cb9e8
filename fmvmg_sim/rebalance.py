"""Closed-loop sense: force-to-rebalance and quadrature control, as the engines and the averaged model see them.

Selected in the device file (or a scenario's ``[device]`` table):

* ``circuit.sense.topology = "force-rebalance"``: the sense signal demodulated in phase (the Coriolis
  component) drives a :class:`blocks.RebalanceController`; its output ``u_I``, remodulated by the
  drive carrier (the normalised phase-shifted pickoff, in phase with the drive velocity like the
  Coriolis force), drives the force-rebalance combs: ``F_y = p_I K_fb k_m u_I c(t)``, ``K_fb`` the
  combs' linear gain (``2 C' V_DC`` push-pull). The loop holds the Coriolis motion at zero, so
  ``u_I = 2 m_c W w A / (K_fb k_m V_dac)``: the scale factor is set by the feedback electronics and
  the drive amplitude, not by the mode split. ``rate_V`` is ``u_I`` through the output low-pass (14).
* ``circuit.quadrature_control.enabled = true``: the quadrature-demodulated signal drives a second
  controller (no derivative) whose output ``V_t`` sets the quadrature-tuning electrodes' coupling
  stiffness ``dk_q = p_Q k_t V_t``: quadrature is cancelled at its source, the stiffness, so the sense
  mode carries no quadrature motion and no feedback phase error can turn it into bias.
  ``quadrature_V`` is ``V_t`` through the output low-pass.

The polarities ``p_I``, ``p_Q`` (+-1) make both loops negative feedback for the device's mode order (sense
above or below drive): :meth:`SenseLoop.polarities`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blocks import ElectrostaticDrive, Multiplier, QuadratureTuningElectrodes, RebalanceController

from .errors import InputError

#: Sense topologies a device or scenario may select.
TOPOLOGIES = ("open-loop", "force-rebalance")


@dataclass
class SenseLoop:
    """The closed-loop sense elements of one operating point.

    Parameters
    ----------
    force_rebalance : bool
        The rate loop is closed.
    quadrature_control : bool
        The quadrature loop is closed.
    controller : RebalanceController
        The rate loop's controller.
    comb : ElectrostaticDrive
        The force-rebalance combs.
    remodulator : Multiplier
        The multiplier putting the controller output on the carrier.
    quad_controller : RebalanceController
        The quadrature loop's controller.
    electrodes : QuadratureTuningElectrodes
        The quadrature-tuning electrodes.
    """

    force_rebalance: bool
    quadrature_control: bool
    controller: RebalanceController
    comb: ElectrostaticDrive
    remodulator: Multiplier
    quad_controller: RebalanceController
    electrodes: QuadratureTuningElectrodes

    def force_per_V(self, carrier: complex) -> complex:
        """Feedback force phasor per volt of rate-loop output, before the polarity (N/V).

        Parameters
        ----------
        carrier : complex
            The carrier's phasor (amplitude V_dac).

        Returns
        -------
        complex
        """
        return complex(self.comb.linear_coef_N_per_V * self.remodulator.k_per_V * carrier)

    @staticmethod
    def sense_transfer(dg, omega_rad_s: float) -> complex:
        """Sense-chain output phasor per newton of sense force at ``omega_rad_s`` (quasi-static, V/N).

        Parameters
        ----------
        dg : fmvmg_sim.diagram.Diagram
        omega_rad_s : float

        Returns
        -------
        complex
        """
        r = dg.resonator
        Hy = 1.0 / (r.k_sense_N_per_m - r.m_sense_kg * omega_rad_s ** 2 + 1j * omega_rad_s * r.c_sense_N_s_per_m)
        return complex(dg.sense_amps_response(omega_rad_s) * dg.sense_pickoff.gain_V_per_m * Hy)

    def polarities(self, dg, omega_rad_s: float, amplitude_m: float, carrier: complex, R_I: complex,
                   R_Q: complex) -> tuple[float, float]:
        """Feedback signs that make each loop negative feedback at this operating point.

        Parameters
        ----------
        dg : fmvmg_sim.diagram.Diagram
        omega_rad_s, amplitude_m : float
            Drive frequency and amplitude.
        carrier, R_I, R_Q : complex
            Carrier and demodulation-reference phasors.

        Returns
        -------
        tuple of float
            ``(p_I, p_Q)``.
        """
        T = self.sense_transfer(dg, omega_rad_s)
        p_i = -np.sign(np.real(T * self.force_per_V(carrier) * np.conj(R_I))) or 1.0
        p_q = -np.sign(np.real(T * (-self.electrodes.dk_dV_N_per_m_per_V * amplitude_m) * np.conj(R_Q))) or 1.0
        return float(p_i), float(p_q)

    def steady_outputs(self, dg, omega_rad_s: float, amplitude_m: float, V_s: complex, Y: complex,
                       carrier: complex, R_I: complex, R_Q: complex) -> dict:
        """The loops' steady state: the efforts that null their demodulated channels, and the outputs.

        The drive loop's steady state (frequency, amplitude) is taken as the open sense chain's: the
        feedback force's back-action on the drive is of second order.

        Parameters
        ----------
        dg : fmvmg_sim.diagram.Diagram
        omega_rad_s, amplitude_m : float
        V_s, Y : complex
            Sense-chain output and sense displacement without the loops.
        carrier, R_I, R_Q : complex

        Returns
        -------
        dict
            ``u_I``, ``v_t`` (V), ``V_s``, ``Y``, ``rate_V``, ``quadrature_V``.
        """
        T = self.sense_transfer(dg, omega_rad_s)
        p_i, p_q = self.polarities(dg, omega_rad_s, amplitude_m, carrier, R_I, R_Q)
        f_u = p_i * self.force_per_V(carrier) if self.force_rebalance else 0.0
        f_v = -p_q * self.electrodes.dk_dV_N_per_m_per_V * amplitude_m if self.quadrature_control else 0.0
        # Re(conj(R) (V_s + T (f_u u + f_v v))) = 0 for each closed loop
        rows, rhs, cols = [], [], []
        for on, R in ((self.force_rebalance, R_I), (self.quadrature_control, R_Q)):
            if on:
                rows.append([np.real(np.conj(R) * T * f_u), np.real(np.conj(R) * T * f_v)])
                rhs.append(-np.real(np.conj(R) * V_s))
        cols = [k for k, on in enumerate((self.force_rebalance, self.quadrature_control)) if on]
        M = np.array(rows)[:, cols]
        sol = np.zeros(2)
        sol[cols] = np.linalg.solve(M, np.array(rhs))
        u_i, v_t = sol
        dF = f_u * u_i + f_v * v_t
        r = dg.resonator
        Y1 = Y + dF / (r.k_sense_N_per_m - r.m_sense_kg * omega_rad_s ** 2 + 1j * omega_rad_s * r.c_sense_N_s_per_m)
        V1 = V_s + T * dF
        k_out = dg.output_lpf.gain
        rate_V = k_out * u_i if self.force_rebalance else k_out * dg.demodulator.baseband(V1, R_I)
        quad_V = k_out * v_t if self.quadrature_control else k_out * dg.demodulator.baseband(V1, R_Q)
        return dict(u_I=float(u_i), v_t=float(v_t), V_s=complex(V1), Y=complex(Y1), rate_V=float(rate_V),
                    quadrature_V=float(quad_V))


def build_sense_loop(circuit: dict) -> SenseLoop | None:
    """The closed-loop sense elements from an operating point's circuit values, or None (open loop).

    Parameters
    ----------
    circuit : dict
        ``OperatingPoint["circuit"]``.

    Returns
    -------
    SenseLoop or None

    Raises
    ------
    InputError
        A loop is selected but the device has no parameters for it.
    """
    ftr = circuit.get("sense", {}).get("topology", "open-loop") == "force-rebalance"
    qc = bool(circuit.get("quadrature_control", {}).get("enabled", False))
    if not (ftr or qc):
        return None
    fb = circuit.get("rebalance")
    if fb is None:
        raise InputError("a closed-loop sense needs the force-rebalance parameters [circuit.rebalance] in the "
                         "device file (see scenarios/devices/fmvmg_a.toml)", "circuit.rebalance")
    q = circuit.get("quadrature_control", {})
    if qc and "dk_dV_N_per_m_per_V" not in q:
        raise InputError("quadrature control needs [circuit.quadrature_control] parameters in the device file "
                         "(see scenarios/devices/fmvmg_a.toml)", "circuit.quadrature_control")
    return SenseLoop(
        force_rebalance=ftr, quadrature_control=qc,
        controller=RebalanceController(name="rebalance_controller", f_c_Hz=fb["filter_f_c_Hz"], kp=fb["kp"],
                                       ki_per_s=fb["ki_per_s"], kd_s=fb["kd_s"]),
        comb=ElectrostaticDrive(name="rebalance_comb", dC_dx_F_per_m=fb["dC_dx_F_per_m"], vdc_V=fb["vdc_V"],
                                topology="push-pull", asymmetry=0.0),
        remodulator=Multiplier(name="remodulator", k_per_V=fb["k_mod_per_V"]),
        quad_controller=RebalanceController(name="quadrature_controller", f_c_Hz=q.get("filter_f_c_Hz", 1.0),
                                            kp=q.get("kp", 0.0), ki_per_s=q.get("ki_per_s", 0.0), kd_s=0.0),
        electrodes=QuadratureTuningElectrodes(dk_dV_N_per_m_per_V=q.get("dk_dV_N_per_m_per_V", 1.0)),
    )


def design_gains(dg, bandwidth_Hz: float = 50.0, zeta: float = 0.7) -> dict:
    """Rate-loop gains by pole placement on the demodulated sense mode (the demodulation low-pass left out).

    In phase, the sense mode seen through the demodulator is ``P0 (s_0^2) / ((s + sigma)^2 + dw^2)``,
    ``dw`` the mode split, ``sigma`` its decay rate and ``P0`` the loop's static gain (demodulated volts
    per volt of effort). With ``C = Kp + Ki/s + Kd s`` the closed loop's characteristic polynomial is
    placed at ``(s + p)(s^2 + 2 zeta dw s + dw^2)``: the integral pole ``p = 2 pi bandwidth_Hz`` and the
    split's resonance damped to ``zeta``.

    Parameters
    ----------
    dg : fmvmg_sim.diagram.Diagram
        A diagram with a closed rate loop.
    bandwidth_Hz : float, optional
        The integral pole (Hz).
    zeta : float, optional
        Damping of the split's resonance.

    Returns
    -------
    dict
        ``kp``, ``ki_per_s``, ``kd_s``.
    """
    from .averaged import carrier_phasors, steady_state  # the averaged model imports this module's users
    ss = steady_state(dg)
    w, A = ss.omega_rad_s, ss.amplitude_m
    Hx, Hps = dg.drive_chain_response(w), dg.phase_shifter_response(w)
    C0, _, _ = carrier_phasors(dg, Hx * A, Hx * Hps * A)
    loop = dg.sense_loop
    P0 = abs(dg.demodulator.baseband(loop.sense_transfer(dg, w) * loop.force_per_V(C0), ss.R_I))
    r = dg.resonator
    sigma = r.c_sense_N_s_per_m / (2 * r.m_sense_kg)
    dw = abs(np.sqrt(r.k_sense_N_per_m / r.m_sense_kg) - w)
    s0 = sigma ** 2 + dw ** 2
    p = 2 * np.pi * bandwidth_Hz
    return dict(kp=float(2 * zeta * dw * p / (P0 * s0)), ki_per_s=float(p * dw ** 2 / (P0 * s0)),
                kd_s=float(max(0.0, p + 2 * zeta * dw - 2 * sigma) / (P0 * s0)))


__all__ = ["TOPOLOGIES", "SenseLoop", "build_sense_loop", "design_gains"]
