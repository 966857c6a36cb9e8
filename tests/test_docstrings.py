"""Every public function and class is documented, numpydoc style (as python-control enforces for itself)."""

import importlib
import inspect
import pkgutil

import pytest

import blocks
import fmvmg_sim


def _modules():
    for pkg in (blocks, fmvmg_sim):
        yield pkg.__name__
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if ".cli." in info.name or info.name.endswith("__main__"):
                continue
            yield info.name


def _public_callables(mod):
    for name, obj in vars(mod).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
            continue
        if inspect.isfunction(obj):
            yield f"{mod.__name__}.{name}", obj
        elif inspect.isclass(obj):
            yield f"{mod.__name__}.{name}", obj
            for mname, m in vars(obj).items():
                if mname.startswith("_") or not inspect.isfunction(m):
                    continue
                yield f"{mod.__name__}.{name}.{mname}", m


def _undocumented():
    bad = []
    for modname in _modules():
        try:
            mod = importlib.import_module(modname)
        except ImportError:
            continue
        for qual, obj in _public_callables(mod):
            doc = inspect.getdoc(obj) or ""
            if not doc.strip():
                bad.append(f"{qual}: no docstring")
                continue
            if inspect.isfunction(obj):
                params = [p for p in inspect.signature(obj).parameters if p not in ("self", "cls")]
                params = [p for p in params if not p.startswith("_")]
                if params and "Parameters" not in doc and len(doc.splitlines()) > 1:
                    bad.append(f"{qual}: documents no Parameters section for {params}")
    return bad


def test_public_api_is_documented():
    bad = _undocumented()
    assert not bad, "\n".join(bad[:50])
