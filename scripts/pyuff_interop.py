#!/usr/bin/env python3
"""pyuff interop for rfmlab's UFF58 tests (pyuff 2.5.8 as the independent reader/writer).

  pyuff_interop.py dump OUT.json FILE...   read every dataset 58 with pyuff, dump values to JSON
  pyuff_interop.py write OUT_DIR           write test files with pyuff (ASCII even/uneven complex
                                           double, ASCII single, binary even complex double) plus
                                           OUT_DIR/expected.json with the exact values written
JSON per file: list of {func_type, rsp_node, rsp_dir, ref_node, ref_dir, x, re, im} (im null if real).
"""
import json
import sys

import numpy as np
import pyuff


def dump(out, files):
    res = {}
    for f in files:
        try:
            sets = pyuff.UFF(f).read_sets()
        except Exception as e:  # pyuff cannot read some valid files; the Rust test reports them
            res[f] = {'error': repr(e)}
            continue
        if isinstance(sets, dict):
            sets = [sets]
        rows = []
        for s in sets:
            if s.get('type') != 58:
                continue
            d = np.asarray(s['data'])
            rows.append({
                'func_type': int(s['func_type']), 'rsp_node': int(s['rsp_node']), 'rsp_dir': int(s['rsp_dir']),
                'ref_node': int(s['ref_node']), 'ref_dir': int(s['ref_dir']),
                'x': [float(v) for v in np.asarray(s['x'])],
                're': [float(v) for v in d.real],
                'im': [float(v) for v in d.imag] if np.iscomplexobj(d) else None,
            })
        res[f] = rows
    with open(out, 'w') as fh:
        json.dump(res, fh)


def write(out_dir):
    rng = np.random.default_rng(7)
    f = np.arange(1.0, 101.0)  # 1..100 Hz, 1 Hz
    h = rng.normal(size=100) * 1e-3 + 1j * rng.normal(size=100) * 1e-3
    fu = np.sort(rng.uniform(10.0, 1000.0, size=50))
    hu = rng.normal(size=50) + 1j * rng.normal(size=50)
    common = dict(func_type=4, rsp_node=2, rsp_dir=3, ref_node=1, ref_dir=3, id1='pyuff interop',
                  abscissa_spec_data_type=18, abscissa_axis_units_lab='Hz', ordinate_spec_data_type=12,
                  ordinate_axis_units_lab='m/s^2', orddenom_spec_data_type=13, orddenom_axis_units_lab='N')
    exp = {}
    ds = pyuff.prepare_58(binary=0, data=h, x=f, abscissa_spacing=1, **common)
    pyuff.UFF(f'{out_dir}/py_even_double.uff').write_sets(ds, mode='overwrite')
    exp['py_even_double.uff'] = (f, h)
    ds = pyuff.prepare_58(binary=0, data=hu, x=fu, abscissa_spacing=0, **common)
    pyuff.UFF(f'{out_dir}/py_uneven_double.uff').write_sets(ds, mode='overwrite')
    exp['py_uneven_double.uff'] = (fu, hu)
    ds = pyuff.prepare_58(binary=1, data=h, x=f, abscissa_spacing=1, **common)
    pyuff.UFF(f'{out_dir}/py_even_double_bin.uff').write_sets(ds, mode='add')
    exp['py_even_double_bin.uff'] = (f, h)
    ds = pyuff.prepare_58(binary=0, data=h, x=f, abscissa_spacing=1, **common)
    ds['ord_data_type'] = 5
    pyuff.UFF(f'{out_dir}/py_even_single.uff').write_sets(ds, mode='overwrite', force_double=False)
    exp['py_even_single.uff'] = (f, h)
    with open(f'{out_dir}/expected.json', 'w') as fh:
        json.dump({k: {'x': list(map(float, x)), 're': list(map(float, v.real)), 'im': list(map(float, v.imag))}
                   for k, (x, v) in exp.items()}, fh)


if __name__ == '__main__':
    if len(sys.argv) >= 3 and sys.argv[1] == 'dump':
        dump(sys.argv[2], sys.argv[3:])
    elif len(sys.argv) == 3 and sys.argv[1] == 'write':
        write(sys.argv[2])
    else:
        sys.exit(__doc__)
