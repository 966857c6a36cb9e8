"""Compile a step function: CasADi builds it symbolically and generates C; gcc builds a library.

A :class:`StepModel` is a step function ``x+ = f(x, p, w)`` written against a math
backend, with the layouts of its state ``x``, its parameters ``p`` (which change
every parameter block) and its per-step inputs ``w``. CasADi generates the C of one
step; a short hand-written C loop in the same translation unit rolls it out, so gcc
can inline it. Libraries are cached under ``$FMVMG_CACHE_DIR`` (default
``~/.cache/fmvmg_sim``), keyed by a hash of the C source and the compiler command:
the first run pays the compile (a few seconds), later runs load the library. Without
a working C compiler the same roll-out runs in CasADi's virtual machine (several
times slower) and the engine says so once.
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

from .carrier.layout import Layout

_WARNED = False
#: -march=native is worth 25 % on the carrier step; the cache key includes the CPU so a library built for
#: one processor is never loaded on another.
CFLAGS = ["-O2", "-march=native", "-fPIC", "-shared"]
FALLBACK_CFLAGS = ["-O2", "-fPIC", "-shared"]


def _cpu_id() -> str:
    """The CPU model and feature flags (the target of -march=native), for the cache key."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        import platform
        return platform.processor() or platform.machine()
    keep = [ln for ln in text.splitlines() if ln.startswith(("model name", "flags"))][:2]
    return "\n".join(keep)

_DRIVER = r"""
#include <stdlib.h>
#include <string.h>
#include <stdint.h>
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
static double PREFIX_normal(PREFIX_rng* r) {
  for (;;) {
    double u = 2 * PREFIX_u01(r) - 1;
    unsigned int i = (unsigned int)(PREFIX_next(r) & 0x7F);
    if (fabs(u) < PREFIX_zr[i]) return u * PREFIX_zx[i];
    if (i == 0) {  /* the tail beyond R */
      double x, y;
      do { x = log(PREFIX_u01(r)) / ZIG_R; y = log(PREFIX_u01(r)); } while (-2 * y < x * x);
      return u < 0 ? x - ZIG_R : ZIG_R - x;
    }
    double x = u * PREFIX_zx[i];
    double f0 = exp(-0.5 * (PREFIX_zx[i] * PREFIX_zx[i] - x * x));
    double f1 = exp(-0.5 * (PREFIX_zx[i + 1] * PREFIX_zx[i + 1] - x * x));
    if (f1 + PREFIX_u01(r) * (f0 - f1) < 1.0) return x;
  }
}
CASADI_SYMBOL_EXPORT int PREFIX_normals_c(uint64_t seed, long n, double* out) {
  PREFIX_rng r; PREFIX_seed(&r, seed);
  if (!PREFIX_zinit) PREFIX_zig_init();
  for (long k = 0; k < n; ++k) out[k] = PREFIX_normal(&r);
  return 0;
}
/* Roll the step function out. K parameter blocks; each block holds NOB outputs of MO steps.
   x0[NX]; P[K][NP]; W[K*NOB*MO][NW] per-step inputs, or NULL to draw NW standard normals per step from
   `seed` (the first NW_NOISE inputs; models whose inputs are all noise); X[K*NOB][NX]. */
CASADI_SYMBOL_EXPORT int PREFIX_rollout_c(const double* x0, const double* P, const double* W, double* X,
                                         long MO, long K, long NOB, uint64_t seed) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  PREFIX_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = (const casadi_real**) malloc(sizeof(casadi_real*) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real** res = (casadi_real**) malloc(sizeof(casadi_real*) * (sz_res > 1 ? sz_res : 1));
  casadi_int* iw = (casadi_int*) malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = (casadi_real*) malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double xa[NX], xb[NX], wbuf[NW];
  PREFIX_rng r; PREFIX_seed(&r, seed);
  if (!PREFIX_zinit) PREFIX_zig_init();
  memcpy(xa, x0, sizeof(double) * NX);
  long s = 0;
  for (long k = 0; k < K; ++k) {
    const double* p = P + k * NP;
    for (long o = 0; o < NOB; ++o) {
      for (long m = 0; m < MO; ++m, ++s) {
        if (W) { arg[2] = W + s * NW; }
        else { for (int j = 0; j < NW; ++j) wbuf[j] = PREFIX_normal(&r); arg[2] = wbuf; }
        arg[0] = xa; arg[1] = p;
        res[0] = xb;
        PREFIX_step(arg, res, iw, w, 0);
        memcpy(xa, xb, sizeof(double) * NX);
      }
      memcpy(X + (k * NOB + o) * NX, xa, sizeof(double) * NX);
      for (int q = 0; q < NRESET; ++q) xa[RESET_IDX[q]] = 0.0;  /* integrate-and-dump accumulators */
    }
  }
  free(arg); free(res); free(iw); free(w);
  return 0;
}
"""


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
    """

    name: str
    state: Layout
    params: Layout
    n_inputs: int
    step: Callable
    reset: tuple = ()

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
        x = ca.SX.sym("x", self.state.size)
        p = ca.SX.sym("p", self.params.size)
        w = ca.SX.sym("w", self.n_inputs)
        out = self.step([x[i] for i in range(self.state.size)], [p[i] for i in range(self.params.size)],
                        [w[i] for i in range(self.n_inputs)], CasadiOps())
        return ca.Function(f"{self.name}_step", [x, p, w], [ca.vertcat(*out)])


class Rollout:
    """``X = rollout(x0, P, W, steps_per_output, outputs_per_block)``.

    Attributes
    ----------
    compiled : bool
        Whether a compiled library is used (else CasADi's virtual machine).
    compile_s : float
        Compile time of this call (0 when loaded from the cache).
    """

    def __init__(self, model: StepModel, fn, compiled: bool, compile_s: float = 0.0, library: str | None = None,
                 normals=None):
        self.model = model
        self._fn = fn
        self._normals = normals
        self.compiled = compiled
        self.compile_s = compile_s
        self.library = library
        self._vm: dict = {}

    def continue_from(self, x_last: np.ndarray) -> np.ndarray:
        """The state to start the next call from: the last output row with its accumulators zeroed.

        Parameters
        ----------
        x_last : ndarray
            Last row returned by a call.

        Returns
        -------
        ndarray
        """
        x = np.array(x_last, dtype=float, copy=True)
        x[self.model.reset_indices()] = 0.0
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
        """Run ``K = len(P)`` parameter blocks.

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
        K = P.shape[0]
        nx = self.model.state.size
        Mo, nob = int(steps_per_output), int(outputs_per_block)
        if W is None and not self.compiled:
            raise ValueError("the virtual-machine roll-out needs its inputs W")
        if W is not None and W.shape != (K * nob * Mo, self.model.n_inputs):
            raise ValueError(f"W has shape {W.shape}, expected {(K * nob * Mo, self.model.n_inputs)}")
        if self.compiled:
            x0 = np.ascontiguousarray(x0, dtype=float)
            P = np.ascontiguousarray(P, dtype=float)
            X = np.empty((K * nob, nx))
            dp = ctypes.POINTER(ctypes.c_double)
            if W is None:
                wp = ctypes.cast(None, dp)
            else:
                W = np.ascontiguousarray(W, dtype=float)
                wp = W.ctypes.data_as(dp)
            self._fn(x0.ctypes.data_as(dp), P.ctypes.data_as(dp), wp, X.ctypes.data_as(dp),
                     ctypes.c_long(Mo), ctypes.c_long(K), ctypes.c_long(nob), ctypes.c_uint64(int(seed) % 2 ** 64))
            return X
        key = (Mo, nob)
        if key not in self._vm:
            f = self.model.casadi_function()
            inner = f.mapaccum("steps", Mo)
            x0s = ca.MX.sym("x0", nx)
            ps = ca.MX.sym("p", self.model.params.size)
            Ws = ca.MX.sym("W", self.model.n_inputs, Mo)
            self._vm[key] = ca.Function("one", [x0s, ps, Ws], [inner(x0s, ca.repmat(ps, 1, Mo), Ws)[:, Mo - 1]])
        F = self._vm[key]
        reset = self.model.reset_indices()
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


_SOURCES: dict[str, bytes] = {}


def c_source(model: StepModel) -> bytes:
    """The C source: CasADi's generated step plus the roll-out driver (memoised per process).

    Parameters
    ----------
    model : StepModel

    Returns
    -------
    bytes
    """
    if model.name in _SOURCES:
        return _SOURCES[model.name]
    f = model.casadi_function()
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            f.generate(f"{model.name}_step.c")
        finally:
            os.chdir(cwd)
        src = (Path(tmp) / f"{model.name}_step.c").read_text()
    idx = model.reset_indices()
    defs = (f"#define NX {model.state.size}\n#define NP {model.params.size}\n#define NW {model.n_inputs}\n"
            f"#define NRESET {len(idx)}\n"
            f"static const int RESET_IDX[{max(1, len(idx))}] = {{{', '.join(map(str, idx)) or '0'}}};\n")
    driver = _DRIVER.replace("PREFIX", model.name)
    marker = "#ifdef __cplusplus\n} /* extern \"C\" */\n#endif"
    src = src.replace(marker, defs + driver + "\n" + marker) if marker in src else src + defs + driver
    _SOURCES[model.name] = src.encode()
    return _SOURCES[model.name]


def load_rollout(model: StepModel, log=None) -> Rollout:
    """The roll-out of ``model``, compiled and cached when a C compiler is available.

    Parameters
    ----------
    model : StepModel
    log : callable, optional
        Receives one-line messages (compile time, fallback notice); default stderr.

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
    src = c_source(model)
    key = hashlib.sha256(src + " ".join([cc] + CFLAGS).encode() + _cpu_id().encode()).hexdigest()[:20]
    lib = cache_dir() / f"{model.name}_{key}.so"
    compile_s = 0.0
    if not lib.exists():
        t0 = time.perf_counter()
        lib.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            cpath = Path(tmp) / f"{model.name}.c"
            cpath.write_bytes(src)
            tmp_lib = lib.parent / f".{lib.name}.{os.getpid()}.tmp"
            res = subprocess.run([cc_path, *CFLAGS, str(cpath), "-o", str(tmp_lib), "-lm"],
                                 capture_output=True, text=True)
            if res.returncode != 0:  # a compiler without -march=native: portable flags
                res = subprocess.run([cc_path, *FALLBACK_CFLAGS, str(cpath), "-o", str(tmp_lib), "-lm"],
                                     capture_output=True, text=True)
            if res.returncode != 0:
                if not _WARNED:
                    log(f"fmvmg: C compile failed ({res.stderr.strip()[:200]}); "
                        "the engines run in CasADi's virtual machine (slower)")
                    _WARNED = True
                return Rollout(model, None, compiled=False)
            os.replace(tmp_lib, lib)
        compile_s = time.perf_counter() - t0
        log(f"fmvmg: compiled the {model.name} step function in {compile_s:.1f} s (cached in {lib.parent})")
    cdll = ctypes.CDLL(str(lib))
    fn = getattr(cdll, f"{model.name}_rollout_c")
    dp = ctypes.POINTER(ctypes.c_double)
    fn.argtypes = [dp, dp, dp, dp, ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_uint64]
    fn.restype = ctypes.c_int
    normals = getattr(cdll, f"{model.name}_normals_c")
    normals.argtypes = [ctypes.c_uint64, ctypes.c_long, dp]
    normals.restype = ctypes.c_int
    return Rollout(model, fn, compiled=True, compile_s=compile_s, library=str(lib), normals=normals)
