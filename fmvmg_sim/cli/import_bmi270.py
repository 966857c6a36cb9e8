"""``fmvmg import-bmi270 LOG.csv -o RECORD.csv``: a BMI270 PuTTY log as a record.

Corrupted lines are skipped and listed on stderr (``--json``: in the JSON object on stdout).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import InputError
from ..io.bmi270 import read_bmi270_log
from ..record import write_record


def register(subparsers) -> None:
    """Add the ``import-bmi270`` sub-command to ``subparsers`` (an ``argparse._SubParsersAction``)."""
    p = subparsers.add_parser(
        "import-bmi270", help="convert a BMI270 serial log into a record",
        description=("Convert a Bosch BMI270 PuTTY log (temperature, accel x/y/z, gyro x/y/z per line, no time "
                     "column) into a record: time_s from the logging rate, temperature_C, rate_dps from one "
                     "gyro axis, the other axes as extra columns. Corrupted lines inside the log become rows "
                     "of missing values; cut first/last lines are dropped; each is reported."))
    p.add_argument("log", metavar="LOG.csv", help="BMI270 PuTTY log")
    p.add_argument("-o", "--output", metavar="RECORD.csv", required=True, help="record file to write")
    p.add_argument("--axis", choices=("x", "y", "z"), default="z", help="gyro axis for rate_dps (default z)")
    p.add_argument("--rate-Hz", type=float, default=50.0, help="logging rate in Hz (default 50)")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout and nothing else")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``fmvmg import-bmi270`` with the parsed ``args``; returns the exit code."""
    out = Path(args.output)
    if out.is_dir():
        raise InputError("expected a file path for -o, got a directory", str(out))
    imp = read_bmi270_log(args.log, axis=args.axis, rate_Hz=args.rate_Hz)
    write_record(out, imp.record)
    summary = {"log": str(args.log), "output": str(out), **imp.summary()}
    if args.json:
        sys.stdout.write(json.dumps(summary) + "\n")
        return 0
    for s in imp.skipped:
        sys.stderr.write(f"fmvmg import-bmi270: skipped {args.log} line {s.line}: {s.reason}: {s.text!r}\n")
    sys.stdout.write(f"wrote {out}: {summary['n_samples']} samples ({summary['duration_s']:.6g} s at "
                     f"{imp.rate_Hz:g} Hz), rate_dps = gyro {imp.axis}, {imp.n_missing} missing sample(s), "
                     f"{len(imp.skipped)} corrupted line(s) skipped\n")
    return 0
