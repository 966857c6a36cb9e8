"""The shipped scenarios and devices (``*.toml``, ``devices/*.toml``), installed as package data.

Found through :mod:`fmvmg_sim.paths`; this file makes the folder a regular package so that
:func:`importlib.resources.files` gives one real directory.
"""
