"""``fmvmg compensate-eval [--methods M,...] [--seeds N] [--quick] [-o DIR] [--json]``.

The honest evaluation of drift compensators (see
:mod:`fmvmg_sim.validation.compensation_eval`): each method is fitted on one simulated oven run and
evaluated on another with a different seed and temperature profile (both directions,
thermal lag on), over several seeds, with the papers' Allan readings beside readings
filtering cannot fake, truth errors, bias per degC and the gain/phase at 1, 10 and 50 Hz
from a rate table. Writes ``DIR/compensation_eval.md``, ``DIR/compensation_eval.json`` and
``DIR/compensation_eval_{allan,traces,summary}.png``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import InputError
from ..record import atomic_write_text
from .options import add_json, add_no_plots, add_no_progress, add_output


def _parse_methods(text: str) -> list[str]:
    from ..validation.compensation_eval import ALL_METHODS
    if text.strip().lower() == "all":
        return list(ALL_METHODS)
    ms = [m.strip() for m in text.split(",") if m.strip()]
    if not ms:
        raise InputError("empty method list", "--methods")
    return ms


def _parse_params(items: list[str] | None) -> dict:
    """``METHOD:KEY=VALUE`` strings -> {method: {key: value}} (values parsed as JSON where possible)."""
    out: dict = {}
    for it in items or []:
        if ":" not in it or "=" not in it.split(":", 1)[1]:
            raise InputError(f"expected METHOD:KEY=VALUE, got {it!r}", "--param")
        m, kv = it.split(":", 1)
        k, v = kv.split("=", 1)
        try:
            val = json.loads(v)
        except json.JSONDecodeError:
            val = v
        out.setdefault(m.strip(), {})[k.strip()] = val
    return out


def run(args) -> int:
    """Execute ``fmvmg compensate-eval`` with parsed ``args``; returns the exit code."""
    from ..validation.compensation_eval import evaluate, markdown_table, plot_allan, plot_summary, plot_traces
    from ..output import OutputFolder

    methods = _parse_methods(args.methods)
    outdir = Path(args.out)
    staged = OutputFolder(outdir, command="compensate-eval")  # refused now, before the evaluation, if unwritable
    ev = evaluate(methods, seeds=args.seeds, quick=args.quick, in_sample=args.in_sample,
                  bandwidth=not args.no_bandwidth, method_params=_parse_params(args.param),
                  progress=not args.no_progress, seed_offset=args.seed_offset)
    md = markdown_table(ev)
    data = ev.to_dict()
    atomic_write_text(staged.path / "compensation_eval.md", md)
    atomic_write_text(staged.path / "compensation_eval.json", json.dumps(data, indent=1) + "\n")
    plots = {}
    if not args.no_plots:
        for name, fn in (("allan", plot_allan), ("traces", plot_traces), ("summary", plot_summary)):
            p = outdir / f"compensation_eval_{name}.png"
            fn(ev, staged.path / p.name)
            plots[name] = str(p)
    staged.commit()
    if args.json:
        sys.stdout.write(json.dumps({"summary": data["summary"], "config": data["config"], "plots": plots,
                                     "output": str(outdir)}) + "\n")
    else:
        sys.stdout.write(md)
        sys.stdout.write(f"\nwritten to {outdir}/\n")
    return 0


def register(sub) -> None:
    """Add the ``compensate-eval`` sub-command to the ``fmvmg`` parser."""
    p = sub.add_parser("compensate-eval", help="honest held-out evaluation of drift compensators",
                       description=__doc__.splitlines()[0])
    p.add_argument("--methods", default="raw,line,poly-baseline,physics", metavar="M,...",
                   help="comma-separated methods ('raw' = uncompensated; 'line' = a line in T, the baseline to "
                        "beat; 'all' = every method); default raw,line,poly-baseline,physics")
    p.add_argument("--seeds", type=int, default=5, metavar="N", help="evaluation seeds (default 5)")
    p.add_argument("--seed-offset", type=int, default=0, metavar="S", help="first evaluation seed (default 0)")
    p.add_argument("--quick", action="store_true", help="short low-rate runs (smoke tests)")
    p.add_argument("--in-sample", action="store_true",
                   help="also read the paper-way Allan figures in-sample (fit and apply on the training run)")
    p.add_argument("--no-bandwidth", action="store_true", help="skip the rate-table check")
    p.add_argument("--param", action="append", metavar="METHOD:KEY=VALUE",
                   help="constructor argument of a method (repeatable), e.g. vmd-wflp-cssvr:budget=300")
    add_output(p, "compensation_eval")
    add_no_plots(p)
    add_no_progress(p)
    add_json(p)
    p.set_defaults(func=run)
