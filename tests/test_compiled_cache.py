"""The compiled-step cache: an entry is loaded only after its content hash matches; a bad one is rebuilt."""

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]

# A one-state model (x+ = a x + b w, accumulated): small enough to compile in a fraction of a second.
_PROGRAM = textwrap.dedent("""
    import sys
    import numpy as np
    from fmvmg_sim.numerics.layout import Layout
    from fmvmg_sim.compiled import StepModel, load_rollout

    def step(x, p, w, ops):
        return [p[0] * x[0] + p[1] * w[0], x[1] + x[0]]

    model = StepModel("fmvmg_cachetest", Layout([("x", ()), ("acc", ())]), Layout([("a", ()), ("b", ())]), 1, step,
                      reset=("acc",))
    roll = load_rollout(model)
    assert roll.compiled, "no compiler"
    X = roll(np.array([1.0, 0.0]), np.array([[0.5, 0.0]]), np.zeros((3, 1)), 3)
    print("X", repr(X.tolist()), roll.library)
""")


def _run(cache: Path):
    env = {**os.environ, "FMVMG_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    env.pop("FMVMG_NO_COMPILE", None)
    return subprocess.run([sys.executable, "-c", _PROGRAM], capture_output=True, text=True, env=env, timeout=300)


@pytest.fixture
def cache(tmp_path):
    if shutil.which(os.environ.get("CC") or "gcc") is None:
        pytest.skip("no C compiler on this machine")
    first = _run(tmp_path)
    assert first.returncode == 0, first.stderr
    assert "compiled the fmvmg_cachetest step function" in first.stderr
    return tmp_path


def _library(cache: Path) -> Path:
    (lib,) = cache.glob("fmvmg_cachetest_*.so")
    return lib


def _expected_output(res) -> list:
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("X "))
    return line.split(" ", 1)[1].rsplit(" ", 1)[0]


def test_good_entry_is_loaded_without_a_rebuild(cache):
    again = _run(cache)
    assert again.returncode == 0, again.stderr
    assert again.stderr == ""  # loaded from the cache: nothing compiled, nothing rebuilt
    # x: 1 -> 0.5 -> 0.25 -> 0.125; the accumulator sums the states entering each step: 1 + 0.5 + 0.25
    assert _expected_output(again) == "[[0.125, 1.75]]"


@pytest.mark.parametrize("damage", ["truncate", "alter", "empty"])
def test_bad_entry_is_rebuilt_with_one_warning_line(cache, damage):
    lib = _library(cache)
    data = lib.read_bytes()
    if damage == "truncate":  # what a crash or a full disk leaves; loading it used to end in a bus error
        lib.write_bytes(data[: len(data) // 2])
    elif damage == "alter":
        mid = len(data) // 2
        lib.write_bytes(data[:mid] + bytes([data[mid] ^ 0xFF]) + data[mid + 1:])
    else:
        lib.write_bytes(b"")
    res = _run(cache)
    assert res.returncode == 0, (res.returncode, res.stderr)
    warnings = [ln for ln in res.stderr.splitlines() if "failed its content check" in ln]
    assert len(warnings) == 1 and str(lib) in warnings[0]
    assert _expected_output(res) == "[[0.125, 1.75]]"
    assert _library(cache).read_bytes() == data  # the same build again, under the same name
    quiet = _run(cache)  # the rebuilt entry passes its check
    assert quiet.returncode == 0 and quiet.stderr == ""


def test_library_name_carries_its_content_hash(cache):
    import hashlib
    lib = _library(cache)
    assert hashlib.sha256(lib.read_bytes()).hexdigest().startswith(lib.stem.rsplit("_", 1)[-1])
    assert not list(cache.glob(".*.tmp"))  # no temporary files left behind
