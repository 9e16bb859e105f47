"""Compare every parquet table of two rfmlab results folders, bit for bit.

Usage: python scripts/compare_parquet.py OLD_DIR NEW_DIR [--ignore TABLE ...]

Tables are matched by path relative to the folder (closed-loop tables in closed_loop/ too).
Two tables are the same when they have the same columns in the same order, the same dtypes,
the same number of rows and every value equal (floats compared by their bits, so NaN equals
NaN and -0.0 differs from 0.0), and the same units metadata (`rfmlab.units`). Prints one
line per table and exits 1 when any differs or is missing on one side.
"""

import sys
from pathlib import Path

import numpy as np
import polars as pl


def tables(root: Path) -> dict[str, Path]:
    return {str(p.relative_to(root)): p for p in sorted(root.rglob("*.parquet"))}


def units(path: Path) -> str | None:
    return pl.read_parquet_metadata(path).get("rfmlab.units")


def same_column(a: pl.Series, b: pl.Series) -> str | None:
    if a.dtype != b.dtype:
        return f"dtype {a.dtype} vs {b.dtype}"
    if a.null_count() != b.null_count() or not (a.is_null() == b.is_null()).all():
        return "nulls differ"
    if a.dtype.is_float():
        x = a.to_numpy().astype(np.float64).view(np.uint64)
        y = b.to_numpy().astype(np.float64).view(np.uint64)
        mask = ~a.is_null().to_numpy()
        bad = np.flatnonzero((x != y) & mask)
        if bad.size:
            i = bad[0]
            return f"{bad.size} values differ, first row {i}: {a[int(i)]!r} vs {b[int(i)]!r}"
        return None
    if not a.equals(b, check_names=False, null_equal=True):
        return "values differ"
    return None


def compare(old: Path, new: Path, ignore: set[str]) -> bool:
    to, tn = tables(old), tables(new)
    ok = True
    for name in sorted(set(to) | set(tn)):
        if name.removesuffix(".parquet") in ignore:
            continue
        if name not in to or name not in tn:
            print(f"MISSING {name}: only in {'old' if name in to else 'new'}")
            ok = False
            continue
        a, b = pl.read_parquet(to[name]), pl.read_parquet(tn[name])
        problems = []
        if a.columns != b.columns:
            problems.append(f"columns {a.columns} vs {b.columns}")
        elif a.height != b.height:
            problems.append(f"rows {a.height} vs {b.height}")
        else:
            for c in a.columns:
                p = same_column(a[c], b[c])
                if p:
                    problems.append(f"{c}: {p}")
        if units(to[name]) != units(tn[name]):
            problems.append("units metadata differ")
        if problems:
            ok = False
            print(f"DIFF {name}: " + "; ".join(problems))
        else:
            print(f"same {name} ({a.height} rows x {a.width} columns)")
    return ok


if __name__ == "__main__":
    args = sys.argv[1:]
    ignore = set()
    if "--ignore" in args:
        i = args.index("--ignore")
        ignore = set(args[i + 1 :])
        args = args[:i]
    if len(args) != 2:
        sys.exit(__doc__)
    sys.exit(0 if compare(Path(args[0]), Path(args[1]), ignore) else 1)
