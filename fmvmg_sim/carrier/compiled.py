"""Compile the step function: CasADi builds it symbolically and generates C; gcc builds a library.

The step function (the whole diagram, see :mod:`fmvmg_sim.carrier.step`) is generated
by CasADi; a short hand-written C loop in the same translation unit rolls it out over
``M`` steps per output sample and ``K`` samples per call, so gcc can inline it.
Libraries are cached under ``$FMVMG_CACHE_DIR`` (default ``~/.cache/fmvmg_sim``),
keyed by a hash of the C source and the compiler command: the first run pays the
compile (a few seconds), later runs load the library. Without a working C compiler
the same roll-out runs in CasADi's virtual machine (CasADi ``mapaccum``, several
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
from pathlib import Path

import casadi as ca
import numpy as np

from .step import N_NOISE, PARAMS, STATE, step

_WARNED = False
CFLAGS = ["-O2", "-fPIC", "-shared"]

_DRIVER = r"""
#include <stdlib.h>
#include <string.h>
/* Roll the step function out: K output samples of M steps each.
   x0[NX]; P[K][NP] (one parameter vector per sample); W[K*M][NW]; X[K][NX] (state at each sample). */
CASADI_SYMBOL_EXPORT int fmvmg_rollout_c(const double* x0, const double* P, const double* W, double* X,
                                        long M, long K) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  fmvmg_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = (const casadi_real**) malloc(sizeof(casadi_real*) * (sz_arg > 3 ? sz_arg : 3));
  casadi_real** res = (casadi_real**) malloc(sizeof(casadi_real*) * (sz_res > 1 ? sz_res : 1));
  casadi_int* iw = (casadi_int*) malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = (casadi_real*) malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double xa[NX], xb[NX];
  memcpy(xa, x0, sizeof(double) * NX);
  for (long k = 0; k < K; ++k) {
    const double* p = P + k * NP;
    for (long m = 0; m < M; ++m) {
      arg[0] = xa; arg[1] = p; arg[2] = W + (k * M + m) * NW;
      res[0] = xb;
      fmvmg_step(arg, res, iw, w, 0);
      memcpy(xa, xb, sizeof(double) * NX);
    }
    memcpy(X + k * NX, xa, sizeof(double) * NX);
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

    @staticmethod
    def if_else(cond, a, b):
        """``a if cond else b`` (both branches evaluated)."""
        return ca.if_else(cond, a, b)


def step_function() -> ca.Function:
    """The symbolic one-step function ``x+ = f(x, p, w)``.

    Returns
    -------
    casadi.Function
    """
    x = ca.SX.sym("x", STATE.size)
    p = ca.SX.sym("p", PARAMS.size)
    w = ca.SX.sym("w", N_NOISE)
    out = step([x[i] for i in range(STATE.size)], [p[i] for i in range(PARAMS.size)],
               [w[i] for i in range(N_NOISE)], CasadiOps())
    return ca.Function("fmvmg_step", [x, p, w], [ca.vertcat(*out)])


class Rollout:
    """``X = rollout(x0, P, W)``: the diagram run for ``K`` output samples of ``M`` steps.

    Parameters
    ----------
    M : int
        Steps per output sample.
    compiled : bool
        Whether a compiled library is used (else CasADi's virtual machine).
    """

    def __init__(self, M: int, fn, compiled: bool, compile_s: float = 0.0, library: str | None = None):
        self.M = int(M)
        self._fn = fn
        self.compiled = compiled
        self.compile_s = compile_s
        self.library = library
        self._vm_cache: dict[int, ca.Function] = {}

    def __call__(self, x0: np.ndarray, P: np.ndarray, W: np.ndarray) -> np.ndarray:
        """Run ``K = len(P)`` samples.

        Parameters
        ----------
        x0 : ndarray, shape (n_x,)
        P : ndarray, shape (K, n_p)
        W : ndarray, shape (K * M, n_w)

        Returns
        -------
        ndarray, shape (K, n_x)
            The state at the end of each sample.
        """
        K = P.shape[0]
        if self.compiled:
            x0 = np.ascontiguousarray(x0, dtype=float)
            P = np.ascontiguousarray(P, dtype=float)
            W = np.ascontiguousarray(W, dtype=float)
            X = np.empty((K, STATE.size))
            dp = ctypes.POINTER(ctypes.c_double)
            self._fn(x0.ctypes.data_as(dp), P.ctypes.data_as(dp), W.ctypes.data_as(dp), X.ctypes.data_as(dp),
                     ctypes.c_long(self.M), ctypes.c_long(K))
            return X
        F = self._vm_cache.get(K)
        if F is None:
            F = self._vm(K)
            self._vm_cache[K] = F
        return np.asarray(F(x0, P.T, W.T)).T

    def _vm(self, K: int) -> ca.Function:
        f = step_function()
        inner = f.mapaccum("fmvmg_steps", self.M)
        x0 = ca.MX.sym("x0", STATE.size)
        p = ca.MX.sym("p", PARAMS.size)
        W = ca.MX.sym("W", N_NOISE, self.M)
        Xall = inner(x0, ca.repmat(p, 1, self.M), W)
        return ca.Function("fmvmg_sample", [x0, p, W], [Xall[:, self.M - 1]]).mapaccum("fmvmg_rollout", K)


def cache_dir() -> Path:
    """Where compiled libraries are kept (``$FMVMG_CACHE_DIR`` or ``~/.cache/fmvmg_sim``).

    Returns
    -------
    Path
    """
    root = os.environ.get("FMVMG_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "fmvmg_sim")
    return Path(root)


_SOURCE: bytes | None = None


def _c_source() -> bytes:
    global _SOURCE
    if _SOURCE is not None:
        return _SOURCE
    f = step_function()
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            f.generate("fmvmg_step.c")
        finally:
            os.chdir(cwd)
        src = (Path(tmp) / "fmvmg_step.c").read_text()
    defs = f"#define NX {STATE.size}\n#define NP {PARAMS.size}\n#define NW {N_NOISE}\n"
    # the driver goes before the closing 'extern "C"' guard of the generated file
    marker = "#ifdef __cplusplus\n} /* extern \"C\" */\n#endif"
    if marker in src:
        src = src.replace(marker, defs + _DRIVER + "\n" + marker)
    else:
        src = src + defs + _DRIVER
    _SOURCE = src.encode()
    return _SOURCE


def load_rollout(M: int, log=None) -> Rollout:
    """The roll-out for ``M`` steps per output sample, compiled and cached when possible.

    Parameters
    ----------
    M : int
        Steps per output sample.
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
            log("fmvmg: no C compiler found (set CC): the carrier engine runs in CasADi's virtual machine, "
                "several times slower than compiled code")
            _WARNED = True
        return Rollout(M, None, compiled=False)
    src = _c_source()
    key = hashlib.sha256(src + " ".join([cc] + CFLAGS).encode()).hexdigest()[:20]
    lib = cache_dir() / f"fmvmg_rollout_{key}.so"
    compile_s = 0.0
    if not lib.exists():
        t0 = time.perf_counter()
        lib.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            cpath = Path(tmp) / "fmvmg_rollout.c"
            cpath.write_bytes(src)
            tmp_lib = lib.parent / f".{lib.name}.{os.getpid()}.tmp"
            res = subprocess.run([cc_path, *CFLAGS, str(cpath), "-o", str(tmp_lib), "-lm"],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                if not _WARNED:
                    log(f"fmvmg: C compile failed ({res.stderr.strip()[:200]}); "
                        "the carrier engine runs in CasADi's virtual machine (slower)")
                    _WARNED = True
                return Rollout(M, None, compiled=False)
            os.replace(tmp_lib, lib)
        compile_s = time.perf_counter() - t0
        log(f"fmvmg: compiled the carrier step function in {compile_s:.1f} s (cached in {lib.parent})")
    cdll = ctypes.CDLL(str(lib))
    fn = cdll.fmvmg_rollout_c
    dp = ctypes.POINTER(ctypes.c_double)
    fn.argtypes = [dp, dp, dp, dp, ctypes.c_long, ctypes.c_long]
    fn.restype = ctypes.c_int
    return Rollout(M, fn, compiled=True, compile_s=compile_s, library=str(lib))
