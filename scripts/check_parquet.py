#!/usr/bin/env python3
"""Check that every parquet table of an rfmlab results folder reads with Python tools.

Usage: check_parquet.py RESULTS_FOLDER [--json]

Every ``*.parquet`` under RESULTS_FOLDER (recursively) is read with polars and with pandas
(pyarrow engine). For each file the script prints the columns, their dtypes and units, and the
row count; it fails (exit code 1) when a file cannot be read by either library, when the two
libraries disagree (column names, row count or values), when the rfmlab units metadata
(key ``rfmlab.units``: a JSON object column -> unit) is missing or does not cover every column,
or when no parquet file is found. Exit code 2: bad command line or Python modules missing.
With ``--json`` a machine-readable summary is printed to stdout instead of the text listing.
"""

import json
import math
import sys
from pathlib import Path


def fail_usage(msg):
    print(f"check_parquet: {msg}", file=sys.stderr)
    sys.exit(2)


try:
    import pandas as pd
    import polars as pl
    import pyarrow.parquet as pq
except ImportError as e:  # pragma: no cover - environment problem
    fail_usage(f"missing Python module ({e}); install with: pip install polars pandas pyarrow")


def same_value(a, b):
    a_missing = a is None or (isinstance(a, float) and math.isnan(a))
    b_missing = b is None or (isinstance(b, float) and math.isnan(b))
    if a_missing or b_missing:
        return a_missing and b_missing
    return a == b


def check_file(path):
    """Return (summary dict, list of problems)."""
    problems = []
    pl_df = pl.read_parquet(path)
    pd_df = pd.read_parquet(path, engine="pyarrow")
    meta = pq.ParquetFile(path).metadata.metadata or {}
    units_raw = meta.get(b"rfmlab.units")
    units = json.loads(units_raw.decode("utf-8")) if units_raw is not None else None
    table = meta.get(b"rfmlab.table", b"").decode("utf-8") or None

    if list(pl_df.columns) != list(pd_df.columns):
        problems.append(f"polars columns {pl_df.columns} != pandas columns {list(pd_df.columns)}")
    if pl_df.height != len(pd_df):
        problems.append(f"polars rows {pl_df.height} != pandas rows {len(pd_df)}")
    if units is None:
        problems.append("no 'rfmlab.units' metadata (units of the columns are undocumented)")
    else:
        missing = [c for c in pl_df.columns if c not in units]
        if missing:
            problems.append(f"columns without a unit in 'rfmlab.units': {missing}")
    if not problems:
        for col in pl_df.columns:
            a = pl_df[col].to_list()
            b = pd_df[col].tolist()
            bad = next((i for i, (x, y) in enumerate(zip(a, b)) if not same_value(x, y)), None)
            if bad is not None:
                problems.append(
                    f"column '{col}' row {bad}: polars {a[bad]!r} != pandas {b[bad]!r}"
                )
    summary = {
        "file": str(path),
        "table": table,
        "rows": pl_df.height,
        "columns": [
            {
                "name": c,
                "polars_dtype": str(pl_df.schema[c]),
                "pandas_dtype": str(pd_df[c].dtype) if c in pd_df.columns else None,
                "unit": (units or {}).get(c),
            }
            for c in pl_df.columns
        ],
    }
    return summary, problems


def main(argv):
    args = [a for a in argv[1:] if not a.startswith("--")]
    flags = {a for a in argv[1:] if a.startswith("--")}
    unknown = flags - {"--json"}
    if len(args) != 1 or unknown:
        fail_usage("usage: check_parquet.py RESULTS_FOLDER [--json]")
    root = Path(args[0])
    if not root.is_dir():
        fail_usage(f"'{root}' is not a folder")
    files = sorted(root.rglob("*.parquet"))
    if not files:
        print(f"check_parquet: no .parquet file under '{root}'", file=sys.stderr)
        return 1
    summaries, n_bad = [], 0
    for path in files:
        try:
            summary, problems = check_file(path)
        except Exception as e:  # any reader failure is a check failure
            summary, problems = {"file": str(path)}, [f"cannot read: {type(e).__name__}: {e}"]
        summary["problems"] = problems
        summaries.append(summary)
        n_bad += bool(problems)
        if "--json" not in flags:
            print(f"{path}: table={summary.get('table')} rows={summary.get('rows')}")
            for c in summary.get("columns", []):
                print(
                    f"    {c['name']:<28} {c['polars_dtype']:<10} {c['pandas_dtype']:<10}"
                    f" unit={c['unit']!r}"
                )
            for p in problems:
                print(f"    PROBLEM: {p}")
    if "--json" in flags:
        print(json.dumps(summaries, indent=1))
    print(f"check_parquet: {len(files)} file(s), {n_bad} with problems", file=sys.stderr)
    return 1 if n_bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
