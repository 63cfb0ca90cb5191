"""Read MILV Delta tables with the Python `deltalake` package, in a subprocess.

    python delta_dump.py OUT.pkl TABLE_DIR [TABLE_DIR ...]

Writes a pickle: a list with, per table, {"version": int, "schema": {name: arrow type str},
"rows": [dict, ...]} (binary columns stay bytes, list<float> columns become Python floats,
which hold float32 values exactly). Run as a subprocess and left with os._exit because the
`deltalake` package can abort the interpreter at exit after a read (see tests/interop).
"""

from __future__ import annotations

import os
import pickle
import sys
import traceback


def main() -> int:
    from deltalake import DeltaTable

    out = []
    for path in sys.argv[2:]:
        dt = DeltaTable(path)
        table = dt.to_pyarrow_table()
        out.append({
            "version": dt.version(),
            "schema": {f.name: str(f.type) for f in table.schema},
            "rows": table.to_pylist(),
        })
    with open(sys.argv[1], "wb") as f:
        pickle.dump(out, f)
    return 0


if __name__ == "__main__":
    try:
        code = main()
    except BaseException:  # noqa: BLE001 - the parent test shows it
        traceback.print_exc()
        code = 2
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
