"""Independent references for rfmlab's validation command (tests/suite/validate.rs).

usage: validate_reference.py stats CASES.json   -> JSON: scipy chi2.sf and binom.ppf per case
       validate_reference.py dataset DIR TABLE  -> JSON: rows and unit sums of DIR/TABLE read as
                                                   one hive-partitioned dataset by pyarrow and polars
"""
import json
import sys


def stats(path):
    from scipy import stats as st

    cases = json.load(open(path))
    out = {
        "chi2_sf": [float(st.chi2.sf(x, k)) for x, k in cases["chi2"]],
        "binom_band": [
            [int(st.binom.ppf((1 - q) / 2, n, p)), int(st.binom.ppf((1 + q) / 2, n, p))]
            for n, p, q in cases["binom"]
        ],
    }
    print(json.dumps(out))


def dataset(root, table):
    import pyarrow.dataset as ds
    import polars as pl

    d = ds.dataset(f"{root}/{table}", format="parquet", partitioning="hive")
    t = d.to_table()
    p = pl.scan_parquet(f"{root}/{table}/**/*.parquet", hive_partitioning=True).collect()
    print(
        json.dumps(
            {
                "pyarrow_rows": t.num_rows,
                "pyarrow_shards": sorted(set(int(s) for s in t.column("shard").to_pylist())),
                "pyarrow_unit_sum": int(sum(t.column("unit").to_pylist())),
                "polars_rows": p.height,
                "polars_unit_sum": int(p["unit"].sum()),
            }
        )
    )


if __name__ == "__main__":
    if sys.argv[1] == "stats":
        stats(sys.argv[2])
    else:
        dataset(sys.argv[2], sys.argv[3])
