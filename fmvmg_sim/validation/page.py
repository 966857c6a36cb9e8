"""The validation page: every figure the documentation quotes about the product's accuracy, measured again.

Run from a source checkout (the reference data live under ``tests/data``)::

    python -m fmvmg_sim.validation.page -o docs/validation.md

Each section is a function that measures one claim and returns its markdown and its numbers; the page
is written whole or not at all, and ``--json PATH`` writes its numbers too (not kept in the repository). ``--only`` runs
some sections and writes them to another file (a partial page is never mistaken for the whole one), and
``--quick`` shortens every measurement to check the machinery (its figures are not the page's).

The diagnosis section (minutes per record) is left out of a default run: ``--diagnosis-results DIR`` adds it,
tabulating a finished ``fmvmg diagnose-independent`` output folder (``--benchmark-results DIR``, repeatable, adds the
scores of a finished ``fmvmg diagnose-benchmark`` folder to it), and ``--only diagnosis`` diagnoses the labelled records that
ship in ``tests/data/independent``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..analysis.allan import allan_deviation
from ..averaged import steady_state
from ..carrier.engine import run_carrier
from ..diagram import build_diagram
from ..envelope.engine import run_envelope
from ..jsonout import strict
from ..record import atomic_write_text
from ..scenario import load_scenario
from . import compensation_records as R
from . import independent as I
from .scores_report import targets_table

#: The source checkout this module sits in; its tests/data holds the outside reference data.
REPO = Path(__file__).resolve().parents[2]
#: Paper 000's raw Allan figures of the gyro (deg/sqrt(h): 99.608 deg/h/sqrt(Hz) / 60; deg/h).
ARW_PAPER_DEG_PER_SQRT_H = 1.66
BI_PAPER_DEG_PER_H = 34.66


@dataclass
class Section:
    """One measured section of the page.

    Parameters
    ----------
    title : str
    lines : list of str
        Its markdown, without the title.
    data : dict
        Its numbers, as written by ``--json``.
    """

    title: str
    lines: list = field(default_factory=list)
    data: dict = field(default_factory=dict)


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}"


# --- Allan analysis against outside references -------------------------------------------------------------

def allan_references(quick: bool = False, log=print) -> Section:
    """Our overlapping Allan deviation against Stable32 and NIST SP 1065 on their own data.

    Parameters
    ----------
    quick : bool, optional
        Unused (the section is fast).
    log : callable, optional

    Returns
    -------
    Section
    """
    ref = REPO / "tests" / "data" / "allan-reference"
    rows, data = [], {}

    def add(name, ours, theirs, what):
        rel = np.abs(np.asarray(ours) / np.asarray(theirs) - 1.0)
        data[name] = {"taus": int(len(rel)), "max_rel_diff": float(rel.max())}
        rows.append([name, what, len(rel), f"{rel.max():.1e}"])

    n = [1234567890]
    for _ in range(999):
        n.append(16807 * n[-1] % 2147483647)
    y = np.array(n, dtype=float) / 2147483647.0
    add("NBS-14, 1000 points", allan_deviation(y, 1.0, taus=[1, 10, 100], unit="").adev,
        [2.922319e-1, 9.159953e-2, 3.241343e-2], "NIST SP 1065 published deviations")
    phase = np.loadtxt(ref / "phasedat" / "PHASE.DAT", comments="#")
    s32 = np.loadtxt(ref / "phasedat" / "phase_dat_oadev_octave.txt", comments="#")
    res = allan_deviation(np.diff(phase), 1.0, unit="s/s")
    add("PHASE.DAT, octave taus", res.adev, s32[:, 5], "Stable32 1.60 overlapping ADEV")
    add("PHASE.DAT, interval bounds", np.r_[res.adev_lo, res.adev_hi], np.r_[s32[:, 4], s32[:, 6]],
        "Stable32 chi-square bounds (Greenhall EDF)")
    f = np.loadtxt(ref / "ocxo" / "ocxo_frequency.txt", comments="#")
    s32 = np.loadtxt(ref / "ocxo" / "stable32_oadev_alltau.txt", comments="#")
    add("OCXO, all 273 taus", allan_deviation(f / 1e7 - 1.0, 1.0, taus=s32[:, 1], unit="").adev, s32[:, 5],
        "Stable32 overlapping ADEV")
    lines = ["`fmvmg allan`'s overlapping Allan deviation and its confidence interval, on the reference data of "
             "Stable32 and NIST SP 1065 (copies with their provenance in `tests/data/allan-reference`).", ""]
    lines += _table(["data", "reference", "taus", "largest relative difference"], rows)
    return Section("Allan analysis against Stable32 and NIST", lines, data)


# --- the two engines ---------------------------------------------------------------------------------------

def _scenario(tmp: Path, name: str, duration_s: float, output_rate_Hz: float, body: str = "",
              temperature: str = "start_C = 25.0", state: str = "steady", noise: bool = False,
              device: str = "fmvmg_a") -> Path:
    on = str(noise).lower()
    text = f"""[scenario]
name = "{name}"
device_file = "{device}"
duration_s = {duration_s}
output_rate_Hz = {output_rate_Hz}
seed = 1
[initial]
state = "{state}"
[temperature]
{temperature}
[noise]
brownian = {on}
electronic = {on}
flicker = {on}
quantization = {on}
rate_random_walk = {on}
""" + body
    p = tmp / f"{name}.toml"
    p.write_text(text)
    return p


def _both(path: Path, overrides=()) -> tuple:
    c = run_carrier(load_scenario(path, fidelity="carrier", overrides=list(overrides)), progress=False)
    e = run_envelope(load_scenario(path, fidelity="envelope", overrides=list(overrides)), progress=False)
    return c, e


def _mean(res, name: str, a: float, b: float) -> float:
    t = res.time_s
    return float(np.mean(res[name][(t > a) & (t <= b)]))


def engines(quick: bool = False, log=print) -> Section:
    """The averaged (envelope) engine against the carrier engine, noise off, on the cases where they can differ.

    Parameters
    ----------
    quick : bool, optional
        Shorter runs.
    log : callable, optional

    Returns
    -------
    Section
    """
    rows, data = [], {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        steps = ("[rate]\nstart_dps = 0.0\nsegments = [ { hold_s = 0.4 }, { step_to_dps = 20.0 }, { hold_s = 0.4 }, "
                 "{ step_to_dps = -20.0 } ]\n")
        for T in (-40.0, 25.0, 85.0):
            log(f"engines: settled loop and scale factor at {T:g} C")
            c, e = _both(_scenario(tmp, f"settled{T:g}", 1.2, 1000.0, steps, f"start_C = {T}"))
            for label, fn, unit in (
                    ("drive amplitude estimate", lambda r: _mean(r, "drive_amplitude_V", 0.1, 0.4), "V"),
                    ("AGC effort", lambda r: _mean(r, "agc_effort_V", 0.1, 0.4), "V"),
                    ("drive frequency", lambda r: _mean(r, "drive_frequency_Hz", 0.1, 0.4), "Hz"),
                    ("zero-rate output", lambda r: _mean(r, "rate_dps", 0.2, 0.4), "deg/s"),
                    ("scale factor", lambda r: (_mean(r, "rate_V", 0.6, 0.8) - _mean(r, "rate_V", 1.0, 1.2)) / 40.0,
                     "V/(deg/s)")):
                vc, ve = fn(c), fn(e)
                data[f"settled_{T:g}C_{label}"] = {"carrier": vc, "envelope": ve}
                rows.append([f"{label} at {T:g} C ({unit})", _g(vc, 8), _g(ve, 8),
                             f"{abs(ve / vc - 1):.1e}" if vc else f"{abs(ve - vc):.1e} abs"])
        log("engines: set-point dropped to a tenth and restored")
        drop = "[vref]\nsegments = [ { hold_s = 0.2 }, { step_to_factor = 0.1 }, { hold_s = 0.4 }, { step_to_factor = 1.0 } ]\n"
        c, e = _both(_scenario(tmp, "drop", 1.0, 100.0, drop))
        t = e.time_s
        rel = np.abs(e["drive_amplitude_V"] / c["drive_amplitude_V"] - 1.0)
        through, after = float(rel[(t > 0.2) & (t <= 0.6)].max()), float(rel[t > 0.6].max())
        data["setpoint_drop"] = {"max_rel_through_drop": through, "max_rel_after_restore": after}
        rows.append(["drive amplitude, set-point at a tenth from 0.2 to 0.6 s (PI clamped): largest difference "
                     "through the drop / after the restore", "", "", f"{through:.1e} / {after:.1e}"])
        log("engines: start-up from 10 nm")
        c, e = _both(_scenario(tmp, "startup", 0.1, 100.0, state="rest"), ["initial.drive_displacement_m=10e-9"])

        def t90(r):
            a = r.internal["drive_displacement_amplitude_m"]
            k = int(np.flatnonzero(a >= 0.9 * a[-1])[0])
            return float(np.interp(0.9 * a[-1], a[k - 1:k + 1], r.time_s[k - 1:k + 1]))
        data["startup_t90_s"] = {"carrier": t90(c), "envelope": t90(e)}
        rows.append(["start-up from 10 nm: time to 90 % amplitude (ms)", _g(1e3 * t90(c)), _g(1e3 * t90(e)),
                     f"{abs(t90(e) / t90(c) - 1):.1e}"])
        log("engines: a temperature step from -40 to 85 C")
        tstep = "start_C = -40.0\nsegments = [ { hold_s = 0.5 }, { step_to_C = 85.0 } ]"
        c, e = _both(_scenario(tmp, "tstep", 1.0, 200.0, temperature=tstep))
        for a, b, T in ((0.35, 0.5, -40), (0.85, 1.0, 85)):
            vc, ve = _mean(c, "rate_dps", a, b), _mean(e, "rate_dps", a, b)
            data[f"temperature_step_bias_{T}C"] = {"carrier": vc, "envelope": ve}
            rows.append([f"zero-rate output after a step to {T} C (deg/s)", _g(vc, 6), _g(ve, 6),
                         f"{abs(ve / vc - 1):.1e}"])
    lines = ["The envelope engine (the averaged model, one step per 10 ms) against the carrier engine (every drive "
             "cycle, 32 steps per cycle) on config A, noise off: the settled loop and scale factor over the "
             "temperature range, a clamped PI, the start-up through the carrier normaliser's floor and a "
             "temperature step.", ""]
    lines += _table(["quantity", "carrier", "envelope", "relative difference"], rows)
    return Section("The envelope engine against the carrier engine", lines, data)


# --- noise against paper 000 ------------------------------------------------------------------------------

def noise(quick: bool = False, log=print) -> Section:
    """The shipped device's Allan figures against paper 000's, and the ARW reading across output rates.

    Parameters
    ----------
    quick : bool, optional
        A 10 min record instead of 2 h (the figures are then rough).
    log : callable, optional

    Returns
    -------
    Section
    """
    dur = 600.0 if quick else 7200.0
    log(f"noise: static_25C, {dur:g} s at 1 kHz output")
    res = run_envelope(load_scenario("static_25C", overrides=[f"scenario.duration_s={dur}",
                                                              "scenario.output_rate_Hz=1000"]), progress=False)
    r = np.asarray(res["rate_dps"])
    rows, data = [], {}
    for fs in (1000, 100, 50, 10):
        k = 1000 // fs
        y = r[: len(r) // k * k].reshape(-1, k).mean(axis=1)
        a = allan_deviation(y, float(fs))
        data[f"{fs}Hz"] = {"arw_deg_per_sqrt_h": a.arw_deg_per_sqrt_h,
                           "bias_instability_deg_per_h": a.bias_instability_deg_per_h}
        rows.append([fs, _g(a.arw_deg_per_sqrt_h), _g(a.bias_instability_deg_per_h)])
    arws = [d["arw_deg_per_sqrt_h"] for d in data.values()]
    data["arw_spread_rel"] = float((max(arws) - min(arws)) / np.mean(arws))
    lines = [f"`static_25C` (config A at 25 C, zero rate, noise on) simulated for {dur / 3600:g} h at 1 kHz output "
             "and averaged down to each output rate; `fmvmg allan` read on each. Paper 000 reports "
             f"{ARW_PAPER_DEG_PER_SQRT_H} deg/sqrt(h) and a bias instability (the Allan minimum) of "
             f"{BI_PAPER_DEG_PER_H} deg/h for the raw output; the ARW here is the white term of the power-law fit "
             "from the first tau the output filter does not shape.", ""]
    lines += _table(["output rate (Hz)", "ARW (deg/sqrt(h))", "bias instability (deg/h)"], rows)
    lines += ["", f"Spread of the ARW over the output rates: {100 * data['arw_spread_rel']:.1f} %."]
    return Section("Noise against paper 000", lines, data)


def compensation_records(quick: bool = False, log=print) -> Section:
    """Every compensator on the measured records of ``tests/data``, beside a bias calibration, a line in T and
    the records' noise floor (:mod:`.compensation_records`).

    Parameters
    ----------
    quick : bool, optional
        Only the polynomial, physics and line (the decomposition methods refuse these records anyway).
    log : callable, optional

    Returns
    -------
    Section
    """
    records, skipped = R.load_records(REPO / "tests" / "data")
    cases = R.make_cases(records)
    methods = ("poly-baseline", "physics", "line") if quick else R.METHODS
    for c in cases:
        log(f"compensation: {c.record}, {c.direction}")
        R.evaluate_case(c, methods)
    lines = ["Held-out RMS of the compensated rate divided by the RMS a bias calibration from the training part "
             "leaves (1 = no better than a bias calibration); `floor` is the test part's deviation from its own "
             "5 s means, what a perfect drift model would still leave. Each record is fitted on its first half in "
             "time and applied to its second, and the reverse; records of one sensor and axis at temperatures that "
             "do not overlap are also crossed. The records and their provenance are in `tests/data`.", "",
             R.report(cases, skipped, methods).rstrip("\n")]
    checks = [R.target_check(c) for c in cases]
    data = {"pairs": len(cases), "default_within_1p05_of_best": sum(bool(t["ok"]) for t in checks),
            "line_wins": sum(t["winner"] == "line" for t in checks), **R.to_dict(cases, skipped)}
    return Section("Compensation on measured records", lines, data)


#: Labelled records made elsewhere that ship with the source (the diagnosis section's default).
INDEPENDENT_RECORDS = REPO / "tests" / "data" / "independent"
#: The scenarios the diagnosis section scores: the physics brief's nominal model, and one stating the independent
#: generator's nominal laws.
DIAGNOSIS_SCENARIOS = ("nominal_a", "nominal_a_stable_electronics")


def benchmark_lines(folder: str) -> list[str]:
    """The scores of a finished ``fmvmg diagnose-benchmark`` output folder (its ``scores.json``) against their targets.

    Parameters
    ----------
    folder : str

    Returns
    -------
    list of str
        A sentence saying what was run, then :func:`.scores_report.targets_table`.
    """
    sc = json.loads((Path(folder) / "scores.json").read_text())
    errors = int(sc.get("errors", 0))
    mix = sc.get("mix") or {}
    drawn = {(1.0, 0.0): ("no effect in any (`--mix null`: the false-alarm rate alone)", " --mix null"),
             (0.0, 1.0): ("one effect each (`--mix single`)", " --mix single"),
             (0.0, 0.0): ("two effects each (`--mix pair`)", " --mix pair")}.get(
        (mix.get("p_null"), mix.get("p_single")), ("an effect mix withheld", ""))
    return [f"On the project's own cases (`fmvmg diagnose-benchmark --cases N --seed S{drawn[1]} -o out/bench`, units "
            f"drawn across the nominal model's stated uncertainty, {drawn[0]}; `--benchmark-results out/bench` adds "
            f"this table): {sc['cases']} cases of seed {sc.get('seed', '-')}, {sc.get('null_runs', '-')} null "
            f"re-simulations per diagnosis, {errors} error{'' if errors == 1 else 's'}; Wilson 95 % intervals.", ""] \
        + targets_table(sc)


def diagnosis_records(quick: bool = False, log=print, results: str | None = None,
                      benchmark: str | list | None = None) -> Section:
    """The diagnosis on labelled records of an independent generator, with each scenario of
    :data:`DIAGNOSIS_SCENARIOS` (:mod:`.independent`).

    Parameters
    ----------
    quick : bool, optional
        One scenario, two null re-simulations.
    log : callable, optional
    results : str, optional
        A finished ``fmvmg diagnose-independent`` output folder (its ``scores.json``) to tabulate instead of
        diagnosing the shipped records again.
    benchmark : str or list of str, optional
        Finished ``fmvmg diagnose-benchmark`` output folders whose scores are added (:func:`benchmark_lines`).

    Returns
    -------
    Section
    """
    if results is not None:
        res = json.loads((Path(results) / "scores.json").read_text())
    else:
        scen = DIAGNOSIS_SCENARIOS[:1] if quick else DIAGNOSIS_SCENARIOS
        log(f"diagnosis: {INDEPENDENT_RECORDS} against {', '.join(scen)}")
        with tempfile.TemporaryDirectory() as d:
            res = I.run_independent(INDEPENDENT_RECORDS, [REPO / "scenarios" / f"{s}.toml" for s in scen], Path(d),
                                    n_null=2 if quick else I.N_NULL, progress=False)
    names = list(res["scenarios"])
    n_rec = len(next(iter(res["scenarios"].values()))["rows"]) if names else 0
    lines = ["`fmvmg diagnose` on labelled records of a generator this project did not write (its own laws, "
             "tolerances, channel offsets and gains, noise and effect implementations), diagnosed with each scenario "
             "and scored against the truth: a null unit is right when the verdict is `none`, a single effect when it "
             "is accepted first or named in its ambiguity set, a pair when the accepted set is exact. Targets: null "
             "units `none` in 8 of 10, clear single effects found in 8 of 10 (with `nominal_a`), no effect accepted "
             f"with a held-out shrink below {res['shrink_floor']:g}. Regenerate with `fmvmg diagnose-independent "
             "FOLDER --scenario nominal_a --scenario nominal_a_stable_electronics -o out/indep` and "
             "`python -m fmvmg_sim.validation.page --diagnosis-results out/indep -o docs/validation.md`; without "
             "`--diagnosis-results` the section diagnoses the records that ship in `tests/data/independent`. "
             f"Records: {n_rec} (folder `{Path(res['folder']).name}`).", ""]
    lines += I.format_table(res, numbered=True).rstrip("\n").split("\n")
    for folder in [benchmark] if isinstance(benchmark, str) else benchmark or []:
        lines += [""] + benchmark_lines(folder)
    data = {n: res["scenarios"][n]["summary"] for n in names}
    return Section("Diagnosis on records made elsewhere", lines, data)


#: The page's sections, in order: (key, function).
SECTIONS: list[tuple[str, Callable]] = [
    ("allan", allan_references),
    ("engines", engines),
    ("noise", noise),
    ("compensation", compensation_records),
    ("diagnosis", diagnosis_records),
]
#: Sections a default run leaves out (minutes per record): run them with ``--only`` or ``--diagnosis-results``.
OPT_IN = ("diagnosis",)


def build_page(keys: list[str] | None = None, quick: bool = False, log=print,
               options: dict | None = None) -> tuple[str, dict]:
    """Measure the sections and assemble the page.

    Parameters
    ----------
    keys : list of str, optional
        Sections to run (default: all of :data:`SECTIONS` but the :data:`OPT_IN` ones).
    quick : bool, optional
    log : callable, optional
    options : dict, optional
        ``{section key: keyword arguments}`` for sections that take more (``diagnosis``: ``results``).

    Returns
    -------
    (str, dict)
        The markdown page and its numbers.
    """
    run = [(k, f) for k, f in SECTIONS if (k not in OPT_IN if keys is None else k in keys)]
    options = options or {}
    md = ["# Validation", "",
          "What the product's accuracy claims rest on, each measured against outside reference data, records the "
          "project did not make, a closed form or the other engine. Every number on this page is regenerated by", "",
          "    python -m fmvmg_sim.validation.page -o docs/validation.md", "",
          *(["with the diagnosis section (left out by default: minutes per record) added by "
             "`--diagnosis-results DIR`, a finished `fmvmg diagnose-independent` output folder (its own section "
             "gives the command),", ""] if any(k == "diagnosis" for k, _ in run) else []),
          "from a source checkout (" + ("quick run: shortened measurements, not the page's figures" if quick else
                                        "the whole page") + ").", ""]
    data = {}
    for k, f in run:
        t0 = time.perf_counter()
        sec = f(quick=quick, log=log, **options.get(k, {}))
        data[k] = dict(sec.data, wall_time_s=time.perf_counter() - t0)
        md += [f"## {sec.title}", ""] + sec.lines + [""]
    return "\n".join(md), data


def main(argv: list[str] | None = None) -> int:
    """Command line: write the page and its numbers.

    Parameters
    ----------
    argv : list of str, optional

    Returns
    -------
    int
        Exit code.
    """
    ap = argparse.ArgumentParser(prog="python -m fmvmg_sim.validation.page", description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", default="docs/validation.md", help="page to write")
    ap.add_argument("--json", default=None, metavar="PATH", help="also write the page's numbers to this JSON file")
    ap.add_argument("--only", default=None, help="comma-separated sections: " + ", ".join(k for k, _ in SECTIONS))
    ap.add_argument("--quick", action="store_true", help="shortened measurements (checks the machinery)")
    ap.add_argument("--diagnosis-results", default=None, metavar="DIR",
                    help="add the diagnosis section (left out by default: minutes per record), tabulating a finished "
                         "`fmvmg diagnose-independent` output folder")
    ap.add_argument("--benchmark-results", action="append", default=[], metavar="DIR",
                    help="with --diagnosis-results: add the scores of a finished `fmvmg diagnose-benchmark` output "
                         "folder to the diagnosis section (repeat for several runs, e.g. the default mix and "
                         "--mix null)")
    a = ap.parse_args(argv)
    keys = None
    options = {}
    checks = [("--diagnosis-results", a.diagnosis_results, "scenarios", "diagnose-independent")] \
        + [("--benchmark-results", b, "cases", "diagnose-benchmark") for b in a.benchmark_results]
    for opt, folder, key, cmd in checks:
        if not folder:
            continue
        f = Path(folder) / "scores.json"
        if not f.is_file():
            print(f"{opt}: no scores.json in {folder}", file=sys.stderr)
            return 2
        try:
            sc = json.loads(f.read_text())
            ok = isinstance(sc, dict) and key in sc
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            print(f"{opt}: {f} is not a scores JSON object ({e})", file=sys.stderr)
            return 2
        if not ok:
            print(f"{opt}: {f} has no '{key}' key (not the scores of a finished `fmvmg {cmd}`)", file=sys.stderr)
            return 2
    if a.benchmark_results and not a.diagnosis_results:
        print("--benchmark-results: needs --diagnosis-results (the section it is added to)", file=sys.stderr)
        return 2
    if a.diagnosis_results:
        options["diagnosis"] = {"results": a.diagnosis_results, "benchmark": a.benchmark_results or None}
    if a.only:
        keys = [k.strip() for k in a.only.split(",")]
        bad = [k for k in keys if k not in dict(SECTIONS)]
        if bad:
            print(f"--only: unknown section(s) {', '.join(bad)}; known: {', '.join(k for k, _ in SECTIONS)}",
                  file=sys.stderr)
            return 2
    if not (REPO / "tests" / "data").is_dir():
        print(f"the validation page needs a source checkout ({REPO / 'tests' / 'data'} not found)", file=sys.stderr)
        return 2
    if a.diagnosis_results and keys is None:
        keys = [k for k, _ in SECTIONS]
    out = Path(a.out)
    if (a.only or a.quick) and out.resolve() == (REPO / "docs" / "validation.md").resolve():
        print("--only and --quick write a partial page: give another -o", file=sys.stderr)
        return 2
    md, data = build_page(keys, a.quick, log=lambda m: print(m, file=sys.stderr), options=options)
    if a.json:
        atomic_write_text(Path(a.json), json.dumps(strict(data), indent=1) + "\n")
    atomic_write_text(out, md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
