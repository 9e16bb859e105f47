#!/usr/bin/env python3
"""Matrix Market round trip through SciPy (used by tests/matrix_market.rs).

Reads every *.mtx file of SRC_DIR with scipy.io.mmread and writes it with scipy.io.mmwrite
into DST_DIR (full 17-digit precision, SciPy's own choice of symmetric/general storage);
other files (dofmap.csv) are copied unchanged.

Usage: mm_roundtrip.py SRC_DIR DST_DIR
"""
import os
import shutil
import sys

import scipy.io
import scipy.sparse


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    src, dst = argv[1], argv[2]
    os.makedirs(dst, exist_ok=True)
    n = 0
    for name in sorted(os.listdir(src)):
        path = os.path.join(src, name)
        if name.endswith(".mtx"):
            a = scipy.sparse.coo_matrix(scipy.io.mmread(path))
            scipy.io.mmwrite(os.path.join(dst, name), a, comment="rewritten by scipy.io.mmwrite",
                             precision=17)
            n += 1
        elif os.path.isfile(path):
            shutil.copy(path, os.path.join(dst, name))
    print(f"rewrote {n} matrices from {src} into {dst}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
