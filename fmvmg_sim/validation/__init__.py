"""Validation harnesses: what measures the product, kept out of the path a user's command takes.

Nothing in :mod:`fmvmg_sim` outside this package imports it. It holds the diagnosis benchmark (labelled case
generation, Dask runs, scores, their report and the paired comparison of two runs) and the held-out evaluation
of the drift compensators. ``fmvmg diagnose-benchmark`` and ``fmvmg compensate-eval`` are its command-line faces.
"""
