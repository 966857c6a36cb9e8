"""Compile a step function: CasADi builds it symbolically, this module writes its C, gcc builds a library.

A :class:`StepModel` is a step function ``x+ = f(x, p, w)`` written against a math
backend, with the layouts of its state ``x``, its parameters ``p`` (which change
every parameter block) and its per-step inputs ``w``. CasADi turns it into one
straight-line expression graph; :func:`c_source` writes that graph as an inlined C
function of a *lane* (one simulated unit) and a short roll-out loop around it, so
that

* one unit runs as plain scalar code with nothing between two steps but the step
  itself (no calls, no argument checks, no copies), and
* ``L`` units of the same model (different parameters: tolerances, temperatures,
  seeds) run in one call, their states side by side (structure of arrays) so that gcc
  vectorises the step across units.

The arithmetic of each unit is the expression graph's, operation by operation, so a
unit gives the same numbers alone or among others.

A model may also give a :class:`Refinement`: the roll-out redoes the steps its step function
flags (a piecewise-linear model crossing from one piece into another) in sub-steps of a second
function, generated the same way and called only for those steps.

Libraries are cached under ``$FMVMG_CACHE_DIR`` (default ``~/.cache/fmvmg_sim``),
keyed by a hash of the C source, the compiler command and the CPU; the file name also
carries the SHA-256 of the library itself, written in one atomic rename. An entry is
loaded only after its content matches that hash; a bad entry (truncated, altered) is
removed and rebuilt with one warning line.
The first run pays the compile (a few seconds), later runs load the library. Without a
working C compiler the same roll-out runs in CasADi's virtual machine (several times
slower) and the engine says so once.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

from blocks.ops import numpy_ops

from .carrier.layout import Layout

_WARNED = False
#: -march=native is worth 25 % on the carrier step; the cache key includes the CPU so a library built for
#: one processor is never loaded on another. -ftree-vectorize with the dynamic cost model vectorises the
#: step across units (-fno-trapping-math lets it turn the step's selects into blends); -fno-math-errno lets
#: sqrt be one instruction. Neither changes a result: they drop errno and floating-point trap semantics only.
CFLAGS = ["-O2", "-march=native", "-ftree-vectorize", "-fvect-cost-model=dynamic", "-fno-math-errno",
          "-fno-trapping-math", "-fPIC", "-shared"]
FALLBACK_CFLAGS = ["-O2", "-fno-math-errno", "-fno-trapping-math", "-fPIC", "-shared"]
#: Units per vectorised pack: a constant, so every lane access has a fixed offset (one AVX2 vector of doubles;
#: measured: 4 lanes cost 0.44 of one unit each, 8 lanes 0.52).
LANE_WIDTH = 4


def _cpu_id() -> str:
    """The CPU model and feature flags (the target of -march=native), for the cache key."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        import platform
        return platform.processor() or platform.machine()
    keep = [ln for ln in text.splitlines() if ln.startswith(("model name", "flags"))][:2]
    return "\n".join(keep)


_HEADER = r"""
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#define EXPORT __attribute__((visibility("default")))
/* fmin/fmax as selects (C99 semantics for NaN arguments), so that the lane loop vectorises */
static inline double PREFIX_fmin(double a, double b) { return ((a < b) | (b != b)) ? a : b; }
static inline double PREFIX_fmax(double a, double b) { return ((a > b) | (b != b)) ? a : b; }
static inline double PREFIX_sign(double a) { return a < 0 ? -1.0 : (a > 0 ? 1.0 : a); }
"""

_DRIVER = r"""
/* ---- noise: xoshiro256+ uniforms and Doornik's ZIGNOR ziggurat (2005) for standard normals ---- */
typedef struct { uint64_t s[4]; } PREFIX_rng;
static inline uint64_t PREFIX_rotl(const uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
static inline uint64_t PREFIX_next(PREFIX_rng* r) {
  const uint64_t result = r->s[0] + r->s[3];
  const uint64_t t = r->s[1] << 17;
  r->s[2] ^= r->s[0]; r->s[3] ^= r->s[1]; r->s[1] ^= r->s[2]; r->s[0] ^= r->s[3];
  r->s[2] ^= t; r->s[3] = PREFIX_rotl(r->s[3], 45);
  return result;
}
static inline double PREFIX_u01(PREFIX_rng* r) { return ((double)(PREFIX_next(r) >> 11) + 0.5) * 0x1.0p-53; }
static void PREFIX_seed(PREFIX_rng* r, uint64_t seed) {
  for (int i = 0; i < 4; ++i) {  /* splitmix64 */
    uint64_t z = (seed += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL; z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    r->s[i] = z ^ (z >> 31);
  }
}
#define ZIG_C 128
#define ZIG_R 3.442619855899
#define ZIG_V 9.91256303526217e-3
static double PREFIX_zx[ZIG_C + 1], PREFIX_zr[ZIG_C];
static int PREFIX_zinit = 0;
static void PREFIX_zig_init(void) {
  double f = exp(-0.5 * ZIG_R * ZIG_R);
  PREFIX_zx[0] = ZIG_V / f; PREFIX_zx[1] = ZIG_R; PREFIX_zx[ZIG_C] = 0;
  for (int i = 2; i < ZIG_C; ++i) {
    PREFIX_zx[i] = sqrt(-2 * log(ZIG_V / PREFIX_zx[i - 1] + f));
    f = exp(-0.5 * PREFIX_zx[i] * PREFIX_zx[i]);
  }
  for (int i = 0; i < ZIG_C; ++i) PREFIX_zr[i] = PREFIX_zx[i + 1] / PREFIX_zx[i];
  PREFIX_zinit = 1;
}
static __attribute__((noinline)) double PREFIX_normal_slow(PREFIX_rng* r, double u, unsigned int i) {
  for (;;) {
    if (i == 0) {  /* the tail beyond R */
      double x, y;
      do { x = log(PREFIX_u01(r)) / ZIG_R; y = log(PREFIX_u01(r)); } while (-2 * y < x * x);
      return u < 0 ? x - ZIG_R : ZIG_R - x;
    }
    double x = u * PREFIX_zx[i];
    double f0 = exp(-0.5 * (PREFIX_zx[i] * PREFIX_zx[i] - x * x));
    double f1 = exp(-0.5 * (PREFIX_zx[i + 1] * PREFIX_zx[i + 1] - x * x));
    if (f1 + PREFIX_u01(r) * (f0 - f1) < 1.0) return x;
    u = 2 * PREFIX_u01(r) - 1;
    i = (unsigned int)(PREFIX_next(r) & 0x7F);
    if (fabs(u) < PREFIX_zr[i]) return u * PREFIX_zx[i];
  }
}
static inline double PREFIX_normal(PREFIX_rng* r) {
  double u = 2 * PREFIX_u01(r) - 1;
  unsigned int i = (unsigned int)(PREFIX_next(r) & 0x7F);
  if (__builtin_expect(fabs(u) < PREFIX_zr[i], 1)) return u * PREFIX_zx[i];
  return PREFIX_normal_slow(r, u, i);
}
EXPORT int PREFIX_normals_c(uint64_t seed, long n, double* out) {
  PREFIX_rng r; PREFIX_seed(&r, seed);
  if (!PREFIX_zinit) PREFIX_zig_init();
  for (long k = 0; k < n; ++k) out[k] = PREFIX_normal(&r);
  return 0;
}
/* Roll L units of the step function out together. K parameter blocks; each block holds NOB outputs of MO
   steps. Units come in packs of V lanes (L a multiple of V; V = 1 without lanes), each pack unit-minor:
   x0[L/V][NX][V]; P[K][L/V][NP][V]; W[K*NOB*MO][L/V][NW][V] per-step inputs, or NULL to draw NW standard
   normals per step and unit, each unit's generator seeded afresh every SB blocks from seeds[ceil(K/SB)][L];
   X[K*NOB][L/V][NX][V] receives the state after each output's last step. Returns 0, -1 if out of memory,
   -2 if L is not a multiple of V. */
#if LANES
#define V LANE_WIDTH
static void PREFIX_step_pack(const double* restrict x, const double* restrict p, const double* restrict w,
                             double* restrict y) {
#pragma GCC ivdep
  for (long l = 0; l < V; ++l) PREFIX_step(x, p, w, y, V, l);  /* V a constant: vectorised across the lanes */
}
#else
#define V 1
#endif
EXPORT int PREFIX_rollout_c(long L, const double* x0, const double* P, const double* W, double* X,
                            long MO, long K, long NOB, const uint64_t* seeds, long SB) {
  if (L < 1 || L % V != 0) return -2;  /* with lanes, every unit goes through a pack (the same numbers) */
  const long npk = L / V, vw = V;
  double* xa = (double*) malloc(sizeof(double) * NX * vw);
  double* xb = (double*) malloc(sizeof(double) * NX * vw);
  double* wb = (double*) malloc(sizeof(double) * (NW > 0 ? NW : 1) * vw);
  PREFIX_rng* r = (PREFIX_rng*) malloc(sizeof(PREFIX_rng) * vw);
  if (!xa || !xb || !wb || !r) { free(xa); free(xb); free(wb); free(r); return -1; }
  if (!W && !PREFIX_zinit) PREFIX_zig_init();
  if (SB < 1) SB = K > 0 ? K : 1;
  /* pack after pack, each through all its steps: a pack's parameters and state stay in the L1 cache */
  for (long q = 0; q < npk; ++q) {
    memcpy(xa, x0 + q * NX * vw, sizeof(double) * NX * vw);
    long s = 0;
    for (long k = 0; k < K; ++k) {
      const double* p = P + k * NP * L + q * NP * vw;
      if (!W && k % SB == 0)
        for (long l = 0; l < vw; ++l) PREFIX_seed(r + l, seeds[(k / SB) * L + q * vw + l]);
      for (long o = 0; o < NOB; ++o) {
        for (long m = 0; m < MO; ++m, ++s) {
          const double* w;
          if (W) w = W + s * NW * L + q * NW * vw;
          else {
            for (int j = 0; j < NW; ++j)  /* lanes interleaved: their generators' chains overlap */
              for (long l = 0; l < vw; ++l) wb[j * vw + l] = PREFIX_normal(r + l);
            w = wb;
          }
#if LANES
          PREFIX_step_pack(xa, p, w, xb);
#else
          PREFIX_step(xa, p, w, xb, 1, 0);
#endif
          double* t = xa; xa = xb; xb = t;
        }
        memcpy(X + (k * NOB + o) * NX * L + q * NX * vw, xa, sizeof(double) * NX * vw);
        for (int i = 0; i < NRESET; ++i)  /* integrate-and-dump accumulators */
          for (long l = 0; l < vw; ++l) xa[RESET_IDX[i] * vw + l] = 0.0;
      }
    }
  }
  free(xa); free(xb); free(wb); free(r);
  return 0;
}
"""

#: Where a refined model's roll-out checks each step's flag (after the step, before the state swap).
_REFINE_ANCHOR = "          double* t = xa; xa = xb; xb = t;\n"
_REFINE_CALL = """          for (long l = 0; l < vw; ++l)  /* flagged steps are redone in sub-steps, lane by lane */
            if (xb[FLAG_IDX * vw + l] != 0.0) PREFIX_refine(xa, p, w, xb, vw, l);
"""
#: The refinement of one lane's step: ``NSUB`` sub-steps from the step's start state (contiguous copies).
_REFINE_FN = r"""
static __attribute__((noinline)) void PREFIX_refine(const double* x, const double* p, const double* w, double* y,
                                                    const long V_, const long l) {
  double xl[NX], yl[NX], wl[NW + 1], pl[NP];
  for (int i = 0; i < NX; ++i) xl[i] = x[i * V_ + l];
  for (int i = 0; i < NP; ++i) pl[i] = p[i * V_ + l];
  for (int i = 0; i < NW; ++i) wl[i] = w[i * V_ + l];
  for (int j = 0; j < NSUB; ++j) {
    wl[NW] = (double) j;
    PREFIX_sub(xl, pl, wl, yl, 1, 0);
    memcpy(xl, yl, sizeof(double) * NX);
  }
  for (int i = 0; i < NX; ++i) y[i * V_ + l] = xl[i];
}
"""

# C of each CasADi operation (CasADi's own codegen semantics, operation by operation)
_UNARY = {
    "OP_ASSIGN": "{0}", "OP_NEG": "(-{0})", "OP_SQ": "({0}*{0})", "OP_TWICE": "(2.*{0})", "OP_INV": "(1./{0})",
    "OP_SQRT": "sqrt({0})", "OP_FABS": "fabs({0})", "OP_NOT": "(!{0})", "OP_SIN": "sin({0})", "OP_COS": "cos({0})",
    "OP_TAN": "tan({0})", "OP_EXP": "exp({0})", "OP_LOG": "log({0})", "OP_FLOOR": "floor({0})",
    "OP_CEIL": "ceil({0})", "OP_TANH": "tanh({0})", "OP_SIGN": "PREFIX_sign({0})", "OP_ATAN": "atan({0})",
}
_BINARY = {
    "OP_ADD": "({0}+{1})", "OP_SUB": "({0}-{1})", "OP_MUL": "({0}*{1})", "OP_DIV": "({0}/{1})",
    "OP_LT": "({0}<{1})", "OP_LE": "({0}<={1})", "OP_EQ": "({0}=={1})", "OP_NE": "({0}!={1})",
    "OP_AND": "({0}&&{1})", "OP_OR": "({0}||{1})", "OP_IF_ELSE_ZERO": "({0}?{1}:0)",
    "OP_FMIN": "PREFIX_fmin({0},{1})", "OP_FMAX": "PREFIX_fmax({0},{1})", "OP_POW": "pow({0},{1})",
    "OP_CONSTPOW": "pow({0},{1})", "OP_ATAN2": "atan2({0},{1})", "OP_HYPOT": "hypot({0},{1})",
    "OP_COPYSIGN": "copysign({0},{1})",
}
_OPS = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}


def _c_literal(v: float) -> str:
    """An exact C literal of ``v`` (hexadecimal floating point; the math.h macros for inf and nan)."""
    if np.isnan(v):
        return "NAN"
    if np.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    return v.hex()


def _step_c(model: "StepModel") -> str:
    """The model's step as an inline C function of one lane (unit ``l`` of ``L``, unit-minor arrays)."""
    return _function_c(model, model.casadi_function(), "PREFIX_step")


def _function_c(model: "StepModel", f: ca.Function, c_name: str) -> str:
    """A CasADi function of ``(x, p, w)`` as an inline C function of one lane."""
    arrays = ("x", "p", "w")
    body = []
    for k in range(f.n_instructions()):
        op = _OPS[f.instruction_id(k)]
        o, i = f.instruction_output(k), f.instruction_input(k)
        if op == "OP_INPUT":
            body.append(f"  w{o[0]}={arrays[i[0]]}[{i[1]}*L+l];")
        elif op == "OP_OUTPUT":
            body.append(f"  y[{o[1]}*L+l]=w{i[0]};")
        elif op == "OP_CONST":
            body.append(f"  w{o[0]}={_c_literal(float(f.instruction_constant(k)))};")
        elif op in _UNARY:
            body.append(f"  w{o[0]}={_UNARY[op].format(f'w{i[0]}')};")
        elif op in _BINARY:
            body.append(f"  w{o[0]}={_BINARY[op].format(f'w{i[0]}', f'w{i[1]}')};")
        else:
            raise NotImplementedError(f"{model.name}: CasADi operation {op} has no C form here")
    n_work = max(1, f.sz_w())
    decl = "  double " + ", ".join(f"w{j}" for j in range(n_work)) + ";"
    return (f"static inline __attribute__((always_inline)) void {c_name}(const double* restrict x, "
            "const double* restrict p, const double* restrict w, double* restrict y, const long L, const long l) {\n"
            + decl + "\n" + "\n".join(body) + "\n}\n")


class CasadiOps:
    """CasADi backend of the carrier-face operations (see :mod:`blocks.ops`)."""

    sqrt = staticmethod(ca.sqrt)
    fabs = staticmethod(ca.fabs)
    fmin = staticmethod(ca.fmin)
    fmax = staticmethod(ca.fmax)
    sin = staticmethod(ca.sin)
    cos = staticmethod(ca.cos)
    tan = staticmethod(ca.tan)
    exp = staticmethod(ca.exp)

    @staticmethod
    def if_else(cond, a, b):
        """``a if cond else b`` (both branches evaluated)."""
        return ca.if_else(cond, a, b)


@dataclass(frozen=True)
class Refinement:
    """A finer update of the steps the step function flags: ``n_sub`` sub-steps in a row.

    A piecewise-linear model (a clamped controller, a gain that changes with the state)
    advances with one exact discretisation per step while it stays in one piece; a step that
    crosses into another piece sets the flag, and the roll-out redoes that step from its start
    state with ``n_sub`` calls of ``substep``, each deciding its piece afresh. The flagged steps
    are few (the crossings), so the fine path costs little however long it is.

    Parameters
    ----------
    substep : callable
        ``substep(x, p, w_j, ops) -> list``: the state after sub-step ``j``, where ``w_j`` is the
        step's input vector with ``j`` (0 .. n_sub - 1) appended.
    n_sub : int
        Sub-steps per refined step.
    flag : str
        Scalar state field the step function sets non-zero to have its step refined.
    """

    substep: Callable
    n_sub: int
    flag: str


@dataclass(frozen=True)
class StepModel:
    """A step function with its layouts.

    Parameters
    ----------
    name : str
        C identifier prefix.
    state : Layout
    params : Layout
    n_inputs : int
        Length of the per-step input vector ``w``.
    step : callable
        ``step(x, p, w, ops) -> list`` (the next state).
    reset : tuple of str
        State fields zeroed after each output sample (accumulators of integrate-and-dump outputs).
    refine : Refinement, optional
        The finer update of flagged steps.
    """

    name: str
    state: Layout
    params: Layout
    n_inputs: int
    step: Callable
    reset: tuple = ()
    refine: Refinement | None = None

    def advance(self, x, p, w) -> np.ndarray:
        """One step in numpy, refined where the step function flags it (what the roll-out does).

        Parameters
        ----------
        x, p, w : array_like
            State, parameters and the step's inputs.

        Returns
        -------
        ndarray
            The next state.
        """
        y = np.asarray(self.step(list(x), list(p), list(w), numpy_ops), dtype=float)
        r = self.refine
        if r is None or y[self.state.slices[r.flag].start] == 0:
            return y
        xs = list(x)
        for j in range(r.n_sub):
            xs = r.substep(xs, list(p), list(w) + [float(j)], numpy_ops)
        return np.asarray(xs, dtype=float)

    def reset_indices(self) -> list[int]:
        """Flat state indices of the :attr:`reset` fields.

        Returns
        -------
        list of int
        """
        idx = []
        for name in self.reset:
            sl = self.state.slices[name]
            idx += list(range(sl.start, sl.stop))
        return idx

    def casadi_function(self) -> ca.Function:
        """The symbolic one-step function.

        Returns
        -------
        casadi.Function
        """
        return self._symbolic(self.step, self.n_inputs, "step")

    def casadi_substep(self) -> ca.Function:
        """The symbolic sub-step of :attr:`refine` (inputs extended by the sub-step index).

        Returns
        -------
        casadi.Function
        """
        return self._symbolic(self.refine.substep, self.n_inputs + 1, "sub")

    def _symbolic(self, fn: Callable, n_inputs: int, suffix: str) -> ca.Function:
        """``fn(x, p, w, ops)`` built with CasADi symbols as ``<name>_<suffix>(x, p, w)``."""
        x = ca.SX.sym("x", self.state.size)
        p = ca.SX.sym("p", self.params.size)
        w = ca.SX.sym("w", n_inputs)
        out = fn([x[i] for i in range(self.state.size)], [p[i] for i in range(self.params.size)],
                 [w[i] for i in range(n_inputs)], CasadiOps())
        return ca.Function(f"{self.name}_{suffix}", [x, p, w], [ca.vertcat(*out)])

    def refined_function(self) -> ca.Function:
        """The step with its refinement as one function (for the virtual machine): the flagged
        branch is evaluated only when taken.

        Returns
        -------
        casadi.Function
        """
        f = self.casadi_function()
        if self.refine is None:
            return f
        sub = self.casadi_substep()
        x = ca.MX.sym("x", self.state.size)
        p = ca.MX.sym("p", self.params.size)
        w = ca.MX.sym("w", self.n_inputs)
        y = f(x, p, w)
        xs = x
        for j in range(self.refine.n_sub):
            xs = sub(xs, p, ca.vertcat(w, float(j)))
        flag = y[self.state.slices[self.refine.flag].start]
        return ca.Function(f"{self.name}_refined", [x, p, w], [ca.if_else(flag != 0, xs, y, True)])


class Rollout:
    """``X = rollout(x0, P, W, steps_per_output, outputs_per_block)`` for one unit; :meth:`units` for many.

    Attributes
    ----------
    compiled : bool
        Whether a compiled library is used (else CasADi's virtual machine).
    compile_s : float
        Compile time of this call (0 when loaded from the cache).
    library : str or None
        Path of the loaded library.
    """

    def __init__(self, model: StepModel, fn, compiled: bool, compile_s: float = 0.0, library: str | None = None,
                 normals=None, lanes: bool = False):
        self.model = model
        self.lanes = lanes
        self._fn = fn
        self._normals = normals
        self.compiled = compiled
        self.compile_s = compile_s
        self.library = library
        self._vm: dict = {}

    def continue_from(self, x_last: np.ndarray) -> np.ndarray:
        """The state to start the next call from: the last output row(s) with the accumulators zeroed.

        Parameters
        ----------
        x_last : ndarray, shape (n_x,) or (L, n_x)
            Last row returned by a call (one per unit).

        Returns
        -------
        ndarray
        """
        x = np.array(x_last, dtype=float, copy=True)
        x[..., self.model.reset_indices()] = 0.0
        return x

    @property
    def draws_noise(self) -> bool:
        """Whether the roll-out can draw its per-step inputs as standard normals itself (compiled only)."""
        return self.compiled

    def normals(self, seed: int, n: int) -> np.ndarray:
        """Standard normals from the compiled generator (xoshiro256+ and a ziggurat), for tests.

        Parameters
        ----------
        seed : int
        n : int

        Returns
        -------
        ndarray
        """
        out = np.empty(n)
        self._normals(ctypes.c_uint64(seed), ctypes.c_long(n), out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        return out

    def __call__(self, x0: np.ndarray, P: np.ndarray, W: np.ndarray | None, steps_per_output: int,
                 outputs_per_block: int = 1, seed: int = 0) -> np.ndarray:
        """Run one unit through ``K = len(P)`` parameter blocks.

        Parameters
        ----------
        x0 : ndarray, shape (n_x,)
        P : ndarray, shape (K, n_p)
        W : ndarray, shape (K * outputs_per_block * steps_per_output, n_w), or None
            Per-step inputs; ``None`` lets the compiled code draw them as standard normals from ``seed``.
        steps_per_output : int
        outputs_per_block : int, optional
        seed : int, optional
            Seed of the compiled generator when ``W`` is None.

        Returns
        -------
        ndarray, shape (K * outputs_per_block, n_x)
            The state after each output's last step, before its accumulators are zeroed
            (continue with :meth:`continue_from`).
        """
        Wu = None if W is None else np.asarray(W)[None]
        return self.units(np.asarray(x0)[None], np.asarray(P)[None], Wu, steps_per_output, outputs_per_block,
                          seeds=[seed])[0]

    def units(self, x0: np.ndarray, P: np.ndarray, W: np.ndarray | None, steps_per_output: int,
              outputs_per_block: int = 1, seeds=None, blocks_per_seed: int | None = None) -> np.ndarray:
        """Run ``L`` units of the model together, each with its own parameters, inputs and seeds.

        Unit ``u``'s result equals what a call with ``x0[u]``, ``P[u]``, ``W[u]`` and ``seeds[u]`` alone
        gives, bit for bit; and a call over several seed blocks equals one call per block, each
        continued from the last (:meth:`continue_from`).

        Parameters
        ----------
        x0 : ndarray, shape (L, n_x)
        P : ndarray, shape (L, K, n_p)
        W : ndarray, shape (L, K * outputs_per_block * steps_per_output, n_w), or None
            Per-step inputs; ``None`` lets the compiled code draw each unit's as standard normals from its seeds.
        steps_per_output : int
        outputs_per_block : int, optional
        seeds : array-like of int, shape (L,) or (L, ceil(K / blocks_per_seed)), optional
            Generator seeds per unit (used when ``W`` is None): the generator starts afresh from the next
            seed every ``blocks_per_seed`` parameter blocks.
        blocks_per_seed : int, optional
            Default: all ``K`` blocks from one seed.

        Returns
        -------
        ndarray, shape (L, K * outputs_per_block, n_x)
        """
        x0 = np.asarray(x0, dtype=float)
        P = np.asarray(P, dtype=float)
        L, K = P.shape[0], P.shape[1]
        nx, npar, nw = self.model.state.size, self.model.params.size, self.model.n_inputs
        Mo, nob = int(steps_per_output), int(outputs_per_block)
        if x0.shape != (L, nx) or P.shape != (L, K, npar):
            raise ValueError(f"x0 {x0.shape} and P {P.shape} do not match L={L}, n_x={nx}, n_p={npar}")
        if W is None and not self.compiled:
            raise ValueError("the virtual-machine roll-out needs its inputs W")
        if W is not None and np.shape(W) != (L, K * nob * Mo, nw):
            raise ValueError(f"W has shape {np.shape(W)}, expected {(L, K * nob * Mo, nw)}")
        if not self.compiled:
            return np.stack([self._vm_one(x0[u], P[u], np.asarray(W[u], dtype=float), Mo, nob) for u in range(L)])
        sb = K if blocks_per_seed is None else max(1, int(blocks_per_seed))
        n_seed = max(1, -(-K // sb))
        seeds = np.zeros((L, n_seed), dtype=np.uint64) if seeds is None else np.array(
            [[int(v) % 2 ** 64 for v in np.atleast_1d(row)] for row in seeds], dtype=np.uint64).reshape(L, -1)
        if seeds.shape != (L, n_seed):
            raise ValueError(f"seeds have shape {seeds.shape}, expected {(L, n_seed)}")
        if L > 1 and not self.lanes:  # built without the vectorised path: one unit after the other
            return np.stack([self.units(x0[u:u + 1], P[u:u + 1], None if W is None else W[u:u + 1], Mo, nob,
                                        seeds=seeds[u:u + 1], blocks_per_seed=sb)[0] for u in range(L)])
        # packs of LANE_WIDTH units, unit-minor within a pack (padded with copies of the last unit)
        V = LANE_WIDTH if self.lanes else 1
        npk = -(-L // V)
        pad = npk * V - L

        def packed(a, lead):  # (L, *lead, n) -> (*lead, npk, n, V)
            a = np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a
            a = a.reshape((npk, V) + a.shape[1:])
            nd = a.ndim
            return np.ascontiguousarray(a.transpose(tuple(range(2, 2 + lead)) + (0, nd - 1, 1)))

        xs = packed(x0, 0)
        Ps = packed(P, 1)
        X = np.empty((K * nob, npk, nx, V))
        dp = ctypes.POINTER(ctypes.c_double)
        if W is None:
            wp = ctypes.cast(None, dp)
        else:
            Ws = packed(np.asarray(W, dtype=float), 1)
            wp = Ws.ctypes.data_as(dp)
        if pad:
            seeds = np.concatenate([seeds, np.repeat(seeds[-1:], pad, axis=0)])
        seeds_t = np.ascontiguousarray(seeds.T)  # [seed block][unit]
        rc = self._fn(ctypes.c_long(npk * V), xs.ctypes.data_as(dp), Ps.ctypes.data_as(dp), wp,
                      X.ctypes.data_as(dp), ctypes.c_long(Mo), ctypes.c_long(K), ctypes.c_long(nob),
                      seeds_t.ctypes.data_as(ctypes.POINTER(ctypes.c_uint64)), ctypes.c_long(sb))
        if rc != 0:
            raise MemoryError(f"the compiled roll-out could not allocate its work arrays for {L} units")
        return X.transpose(1, 3, 0, 2).reshape(npk * V, K * nob, nx)[:L]

    def _vm_one(self, x0, P, W, Mo, nob):
        nx = self.model.state.size
        key = (Mo, nob)
        if key not in self._vm:
            f = self.model.refined_function()
            inner = f.mapaccum("steps", Mo)
            x0s = ca.MX.sym("x0", nx)
            ps = ca.MX.sym("p", self.model.params.size)
            Ws = ca.MX.sym("W", self.model.n_inputs, Mo)
            self._vm[key] = ca.Function("one", [x0s, ps, Ws], [inner(x0s, ca.repmat(ps, 1, Mo), Ws)[:, Mo - 1]])
        F = self._vm[key]
        reset = self.model.reset_indices()
        K = P.shape[0]
        out = np.empty((K * nob, nx))
        x = np.asarray(x0, dtype=float).copy()
        Wt = W.T
        i = 0
        for k in range(K):
            for o in range(nob):
                x = np.asarray(F(x, P[k], Wt[:, i * Mo:(i + 1) * Mo])).ravel()
                out[i] = x
                x = x.copy()
                x[reset] = 0.0
                i += 1
        return out


def cache_dir() -> Path:
    """Where compiled libraries are kept (``$FMVMG_CACHE_DIR`` or ``~/.cache/fmvmg_sim``).

    Returns
    -------
    Path
    """
    root = os.environ.get("FMVMG_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "fmvmg_sim")
    return Path(root)


_SOURCES: dict[tuple, bytes] = {}
#: Hex digits of the library's SHA-256 carried in its file name.
_DIGEST_CHARS = 16


def c_source(model: StepModel, lanes: bool = False) -> bytes:
    """The C source: the model's step as an inline lane function plus the roll-out driver (memoised).

    Parameters
    ----------
    model : StepModel
    lanes : bool, optional
        Include the vectorised path that advances many units per call.

    Returns
    -------
    bytes
    """
    if (model.name, lanes) in _SOURCES:
        return _SOURCES[model.name, lanes]
    idx = model.reset_indices()
    defs = (f"#define NX {model.state.size}\n#define NP {model.params.size}\n#define NW {model.n_inputs}\n"
            f"#define NRESET {len(idx)}\n#define LANES {int(lanes)}\n#define LANE_WIDTH {LANE_WIDTH}\n"
            f"static const int RESET_IDX[{max(1, len(idx))}] = {{{', '.join(map(str, idx)) or '0'}}};\n")
    driver = _DRIVER
    if model.refine is not None:
        r = model.refine
        defs += (f"#define NSUB {int(r.n_sub)}\n#define FLAG_IDX {model.state.slices[r.flag].start}\n"
                 + _function_c(model, model.casadi_substep(), "PREFIX_sub") + _REFINE_FN)
        for anchor, text in ((_REFINE_ANCHOR, _REFINE_CALL + _REFINE_ANCHOR),):
            if anchor not in driver:  # pragma: no cover - the driver text and the anchor are written together
                raise RuntimeError("the roll-out driver has no place for the refinement call")
            driver = driver.replace(anchor, text)
    src = (f"/* {model.name}: generated by fmvmg_sim.compiled from the model's CasADi expression graph */\n"
           + _HEADER + defs + _step_c(model) + driver).replace("PREFIX", model.name)
    _SOURCES[model.name, lanes] = src.encode()
    return _SOURCES[model.name, lanes]


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _cached(prefix: str, log) -> Path | None:
    """A cached library ``<prefix>_<digest>.so`` whose content matches the digest in its name.

    Entries that do not match (truncated, altered) are reported in one line and removed.
    """
    root = cache_dir()
    for lib in sorted(root.glob(f"{prefix}_*.so")):
        want = lib.stem.rsplit("_", 1)[-1]
        try:
            ok = _digest(lib)[:len(want)] == want and len(want) == _DIGEST_CHARS
        except OSError:
            ok = False
        if ok:
            return lib
        log(f"fmvmg: cached library {lib} failed its content check (truncated or altered); rebuilding it")
        try:
            lib.unlink()
        except OSError:
            pass
    return None


def _build(cc_path: str, src: bytes, prefix: str, name: str) -> tuple[Path | None, str | None]:
    """Compile ``src`` into the cache as ``<prefix>_<digest of the library>.so`` (one atomic rename).

    Returns (path, None) on success, else (None, the compiler's message).
    """
    root = cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        cpath = Path(tmp) / f"{name}.c"
        cpath.write_bytes(src)
        tmp_lib = root / f".{prefix}.{os.getpid()}.tmp"
        res = subprocess.run([cc_path, *CFLAGS, str(cpath), "-o", str(tmp_lib), "-lm"], capture_output=True, text=True)
        if res.returncode != 0:  # a compiler without -march=native: portable flags
            res = subprocess.run([cc_path, *FALLBACK_CFLAGS, str(cpath), "-o", str(tmp_lib), "-lm"],
                                 capture_output=True, text=True)
        if res.returncode != 0:
            tmp_lib.unlink(missing_ok=True)
            return None, res.stderr.strip()[:200]
        lib = root / f"{prefix}_{_digest(tmp_lib)[:_DIGEST_CHARS]}.so"
        os.replace(tmp_lib, lib)
    return lib, None


def load_rollout(model: StepModel, log=None, lanes: bool = False) -> Rollout:
    """The roll-out of ``model``, compiled and cached when a C compiler is available.

    A cached library is loaded only after its content matches the hash recorded when it was
    built; a bad entry is rebuilt (one warning line).

    Parameters
    ----------
    model : StepModel
    log : callable, optional
        Receives one-line messages (compile time, rebuilt entries, fallback notice); default stderr.
    lanes : bool, optional
        Build the vectorised path that advances many units per call (:meth:`Rollout.units`); its
        compile takes several times longer, so a one-unit library leaves it out.

    Returns
    -------
    Rollout
    """
    global _WARNED
    log = log or (lambda msg: sys.stderr.write(msg + "\n"))
    cc = os.environ.get("CC") or "gcc"
    cc_path = shutil.which(cc)
    if cc_path is None or os.environ.get("FMVMG_NO_COMPILE"):
        if not _WARNED:
            log("fmvmg: no C compiler found (set CC): the engines run in CasADi's virtual machine, "
                "10-20x slower than compiled code")
            _WARNED = True
        return Rollout(model, None, compiled=False)
    src = c_source(model, lanes)
    key = hashlib.sha256(src + " ".join([cc] + CFLAGS).encode() + _cpu_id().encode()).hexdigest()[:20]
    prefix = f"{model.name}{'_lanes' if lanes else ''}_{key}"
    compile_s = 0.0
    lib = _cached(prefix, log)
    if lib is None:
        t0 = time.perf_counter()
        lib, err = _build(cc_path, src, prefix, model.name)
        if lib is None:
            if not _WARNED:
                log(f"fmvmg: C compile failed ({err}); the engines run in CasADi's virtual machine (slower)")
                _WARNED = True
            return Rollout(model, None, compiled=False)
        compile_s = time.perf_counter() - t0
        what = f"the {model.name} step function" + (" in packs of lanes" if lanes else "")
        log(f"fmvmg: compiled {what} in {compile_s:.1f} s (cached in {lib.parent})")
    cdll = ctypes.CDLL(str(lib))
    fn = getattr(cdll, f"{model.name}_rollout_c")
    dp = ctypes.POINTER(ctypes.c_double)
    fn.argtypes = [ctypes.c_long, dp, dp, dp, dp, ctypes.c_long, ctypes.c_long, ctypes.c_long,
                   ctypes.POINTER(ctypes.c_uint64), ctypes.c_long]
    fn.restype = ctypes.c_int
    normals = getattr(cdll, f"{model.name}_normals_c")
    normals.argtypes = [ctypes.c_uint64, ctypes.c_long, dp]
    normals.restype = ctypes.c_int
    return Rollout(model, fn, compiled=True, compile_s=compile_s, library=str(lib), normals=normals, lanes=lanes)
