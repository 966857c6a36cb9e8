"""``fmvmg allan RECORD.csv``: overlapping Allan deviation and the IEEE 952 noise terms.

Needs only ``time_s`` and the analysed column. ``--json`` prints one JSON object on stdout
(notes go to stderr); ``-o DIR`` writes ``DIR/allan.json`` and ``DIR/allan.png`` atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..analysis.series import MAX_GAP_STEPS, MAX_NAN_FILL
from ..errors import InputError
from .options import add_json, add_output


def register(subparsers) -> None:
    """Add the ``allan`` sub-command to ``subparsers`` (an ``argparse._SubParsersAction``)."""
    p = subparsers.add_parser(
        "allan", help="Allan deviation with ARW, bias instability and RRW",
        description=("Overlapping Allan deviation (allantools) of one record column with 68 % confidence "
                     "intervals, and the IEEE 952 terms: ARW fitted only on a -1/2 slope region, bias "
                     "instability as the Allan minimum (and /0.664), RRW on a +1/2 region. Time steps must "
                     f"be within 1 % of the median step; up to {MAX_NAN_FILL} missing samples in a row are "
                     "interpolated. --resample interpolates uneven or gapped records onto a uniform grid "
                     f"(gaps up to {MAX_GAP_STEPS} steps)."))
    p.add_argument("record", metavar="RECORD.csv", help="record file (needs time_s and the analysed column)")
    p.add_argument("--column", default="rate_dps",
                   help="column to analyse (default rate_dps; the deg-based terms assume deg/s)")
    add_json(p, "the result")
    add_output(p, None, "write DIR/allan.json and DIR/allan.png")
    p.add_argument("--resample", action="store_true",
                   help=f"interpolate onto a uniform grid at the median step (gaps up to {MAX_GAP_STEPS} steps)")
    p.add_argument("--taus", choices=("octave", "dense"), default="octave",
                   help="octave taus (default) or about 10 log-spaced taus per decade")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``fmvmg allan`` with the parsed ``args``; returns the exit code."""
    from ..analysis.allan import allan_deviation
    from ..analysis.series import series_from_record
    from ..output import check_output_folder, output_folder
    from ..record import atomic_write_text, read_record

    if args.out:
        check_output_folder(args.out)
    rec = read_record(args.record, required=("time_s", args.column))
    series = series_from_record(rec, args.column, resample=args.resample)
    res = allan_deviation(series.values, series.fs_Hz, taus=args.taus, unit=series.unit, column=args.column)
    if not (res.n_clusters >= res.min_clusters).any():
        raise InputError(f"not enough data for an Allan analysis: {res.n_samples} samples of {args.column} "
                         f"({res.n_samples / res.fs_Hz:.3g} s); it needs at least one averaging time with "
                         f"{res.min_clusters} independent clusters, i.e. at least {res.min_clusters} samples "
                         "(many more for bias instability)", str(args.record))
    res.notes[:0] = series.notes
    out = res.to_dict()
    out = {"record": str(args.record), **out, "resampled": series.resampled, "n_filled": series.n_filled}
    for note in res.notes:
        sys.stderr.write(f"fmvmg allan: note: {note}\n")
    if args.out:
        with output_folder(args.out, command="allan") as tmp:
            atomic_write_text(tmp / "allan.json", json.dumps(out, indent=2, allow_nan=False) + "\n")
            shown = Path(*Path(args.record).parts[-2:])  # the record and its folder: out/static/record.csv
            res.plot(tmp / "allan.png", title=f"{shown}: {args.column}")
    if args.json:
        sys.stdout.write(json.dumps(out, allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_table(res, str(args.record)))
    return 0


def _f(v, fmt: str = ".4g") -> str:
    return "n/a" if v is None else format(v, fmt)


def format_table(res, source: str) -> str:
    """Human-readable table of an :class:`~fmvmg_sim.analysis.allan.AllanResult`.

    Parameters
    ----------
    res : AllanResult
        The analysis.
    source : str
        File name shown in the heading.

    Returns
    -------
    str
        The table and the noise terms, newline-terminated.
    """
    u = res.unit or "unit"
    lines = [f"{source}: {res.column} [{u}], {res.n_samples} samples at {res.fs_Hz:.6g} Hz "
             f"({res.n_samples / res.fs_Hz:.6g} s)",
             f"{'tau_s':>11} {'adev':>11} {'adev_lo':>11} {'adev_hi':>11} {'clusters':>9} {'slope':>6} {'alpha':>5}"]
    for i in range(len(res.taus_s)):
        mark = "" if res.n_clusters[i] >= res.min_clusters else "  (few clusters, not fitted)"
        lines.append(f"{res.taus_s[i]:11.4g} {res.adev[i]:11.4g} {res.adev_lo[i]:11.4g} {res.adev_hi[i]:11.4g} "
                     f"{res.n_clusters[i]:9d} {res.slopes[i]:+6.2f} {res.alpha[i]:5d}{mark}")
    lines.append("")

    def region(t):
        return f"fit on {t.region_s[0]:.3g}..{t.region_s[1]:.3g} s" if t.region_s else ""

    if res.is_deg_per_s:
        lines.append(f"ARW  N = {_f(res.arw_deg_per_sqrt_h)} deg/sqrt(h)  {region(res.white) or res.white.reason}")
        lines.append(f"BI   Allan minimum = {_f(res.bias_instability_deg_per_h)} deg/h at tau = {_f(res.tau_min_s)} s; "
                     f"IEEE 952 B = min/0.664 = {_f(res.bias_instability_ieee952_deg_per_h)} deg/h")
        lines.append(f"RRW  K = {_f(res.rrw_deg_per_h_sqrt_h)} deg/h/sqrt(h)  {region(res.random_walk) or res.random_walk.reason}")
        if res.Q is not None:
            lines.append(f"QN   Q = {_f(res.quantization_deg)} deg  {region(res.quantization)}")
    else:
        lines.append(f"white N = {_f(res.N)} {u}*sqrt(s)  {region(res.white) or res.white.reason}")
        lines.append(f"Allan minimum = {_f(res.allan_minimum)} {u} at tau = {_f(res.tau_min_s)} s")
        lines.append(f"random walk K = {_f(res.K)} {u}/sqrt(s)  {region(res.random_walk) or res.random_walk.reason}")
    return "\n".join(lines) + "\n"
