#!/usr/bin/env python3
"""The commands users wait for, timed against a stored baseline.

Runs each command N times (default 3) with the release binary, takes the median wall time and
the median of each manifest step (where the command writes one), and prints them beside the
medians stored in benches/baseline.json with their ratio; a ratio above --threshold (default
1.15) is flagged as a slowdown and makes the exit code 1. `--save` stores this run's medians
as the new baseline (with the git revision, the date and the machine's load).

    python3 scripts/bench_commands.py                   # every command, 3 runs each
    python3 scripts/bench_commands.py default_cached bayes --runs 5
    python3 scripts/bench_commands.py --save            # after a change that is meant to stay

Only the Python standard library: it runs on a fresh machine beside `cargo build --release`.
Each run writes into a fresh temporary folder (the ROM cache is shared across runs unless a
command says --no-cache; sampler checkpoints are not: every run samples from scratch).
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "benches" / "baseline.json"
BIN = ROOT / "target" / "release" / "rfmlab"

# name -> (arguments after the binary, whether the run needs the shared ROM cache warm first)
COMMANDS = {
    "default_cached": (["run", "studies/default.toml", "--no-figures"], True),
    "default_uncached": (["run", "studies/default.toml", "--no-figures", "--no-cache"], False),
    "bayes": (["run", "studies/bayes.toml", "--no-figures"], True),
    "diagnose_mass": (["diagnose", "studies/closed_loop_mass.toml", "--no-figures"], True),
    "diagnose_springs": (["diagnose", "studies/closed_loop_virtual_springs.toml", "--no-figures"], True),
    # a fresh machine: the ROM and the springs' term ROM built and certified in the run
    "diagnose_springs_uncached": (
        ["diagnose", "studies/closed_loop_virtual_springs.toml", "--no-figures", "--no-cache"],
        False,
    ),
    "check_default": (["check", "studies/default.toml"], True),
}


def load_avg():
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def git_rev():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_once(args, cache_dir):
    """Wall seconds and the manifest's step timings (dict) of one run in a fresh folder."""
    work = Path(tempfile.mkdtemp(prefix="rfmlab-bench-"))
    out = work / "out"
    cmd = [str(BIN)] + args
    if args[0] in ("run", "diagnose"):
        cmd += ["-o", str(out)]
    env = dict(os.environ, RFMLAB_ROM_CACHE=str(cache_dir))
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    steps = {}
    manifest = next(iter(sorted(out.rglob("manifest.json"))), None) if out.exists() else None
    if manifest is not None:
        for t in json.loads(manifest.read_text()).get("timings", []):
            steps[t["step"].strip()] = steps.get(t["step"].strip(), 0.0) + t["seconds"]
    shutil.rmtree(work, ignore_errors=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return wall, steps


def measure(name, runs, cache_dir):
    args, warm = COMMANDS[name]
    if warm:
        run_once(args, cache_dir)  # fills the shared ROM cache; not timed
    walls, steps = [], {}
    for _ in range(runs):
        w, s = run_once(args, cache_dir)
        walls.append(w)
        for k, v in s.items():
            steps.setdefault(k, []).append(v)
    return {
        "median_s": statistics.median(walls),
        "runs_s": walls,
        "steps_median_s": {k: statistics.median(v) for k, v in steps.items()},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"commands (default: all of {list(COMMANDS)})")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--threshold", type=float, default=1.15)
    ap.add_argument("--save", action="store_true", help="store these medians as the baseline")
    ap.add_argument("--steps", action="store_true", help="print each manifest step too")
    a = ap.parse_args()
    names = a.names or list(COMMANDS)
    for n in names:
        if n not in COMMANDS:
            sys.exit(f"unknown command {n!r}: choose from {list(COMMANDS)}")
    if not BIN.exists():
        sys.exit(f"{BIN} missing: run `cargo build --release` first")
    base = json.loads(BASELINE.read_text()) if BASELINE.exists() else {"commands": {}}
    cache = Path(tempfile.mkdtemp(prefix="rfmlab-bench-cache-"))
    load0 = load_avg()
    now = {}
    slow = []
    print(f"{'command':<18} {'median s':>9} {'baseline s':>11} {'ratio':>6}   runs")
    for n in names:
        r = measure(n, a.runs, cache)
        now[n] = r
        b = base["commands"].get(n)
        ratio = r["median_s"] / b["median_s"] if b else float("nan")
        flag = "  SLOWER" if ratio > a.threshold else ""
        if ratio > a.threshold:
            slow.append(n)
        runs = ", ".join(f"{w:.1f}" for w in r["runs_s"])
        print(f"{n:<18} {r['median_s']:>9.1f} {b['median_s'] if b else float('nan'):>11.1f} "
              f"{ratio:>6.2f}   {runs}{flag}")
        if a.steps:
            bs = (b or {}).get("steps_median_s", {})
            for k, v in r["steps_median_s"].items():
                ref = bs.get(k)
                print(f"    {k:<44} {v:>8.2f} {ref if ref is not None else float('nan'):>8.2f}")
    shutil.rmtree(cache, ignore_errors=True)
    print(f"load average: {load0:.2f} before, {load_avg():.2f} after "
          f"(baseline: {base.get('load_average', float('nan'))}, {base.get('revision', '-')})")
    if a.save:
        merged = dict(base.get("commands", {}))
        merged.update(now)
        BASELINE.parent.mkdir(exist_ok=True)
        BASELINE.write_text(json.dumps({
            "revision": git_rev(),
            "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "machine": f"{os.cpu_count()} cores",
            "load_average": round(load0, 2),
            "runs": a.runs,
            "commands": merged,
        }, indent=1) + "\n")
        print(f"baseline saved to {BASELINE.relative_to(ROOT)}")
    if slow and not a.save:
        print(f"slower than the baseline by more than {a.threshold:.2f}x: {', '.join(slow)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
