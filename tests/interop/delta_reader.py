"""Read MILV Delta tables with the Python `deltalake` package, pyarrow and polars.

Run as a subprocess by test_interop.py, never imported by pytest: the Python
`deltalake` package can abort the interpreter at exit after a read (a known
upstream issue), so this script prints its JSON answer, flushes, and leaves with
``os._exit``.  A crash here shows up as a failed test with stderr attached, not
as a dead pytest.

    python delta_reader.py REQUEST.json

REQUEST.json: {"reads": [READ, ...]} where READ is
    {"path": TABLE_DIR, "version": int | null, "reader": "deltalake" | "polars",
     "dump": bool, "dump_dir": DIR | null}
Answer on stdout: {"results": [RESULT, ...]} where RESULT is
    {"num_rows": int, "loaded_version": int | null,
     "columns": {name: {"type": normalized arrow type, "raw_type": str, "nullable": bool | null}},
     "rows": [dict, ...] | null}
For "deltalake" reads, "nullable" comes from the Delta schema.  With "dump", every
row is returned (timestamps as ISO strings); an `image` column is written to
DUMP_DIR/<row>.bin and replaced by that file name, rows sorted by
(episode_id, frame_index) where those columns exist.
"""

from __future__ import annotations

import json
import os
import sys
import traceback


def _norm_arrow(t) -> str:
    import pyarrow as pa

    if pa.types.is_string(t) or pa.types.is_large_string(t) or pa.types.is_string_view(t):
        return "string"
    if pa.types.is_binary(t) or pa.types.is_large_binary(t) or pa.types.is_binary_view(t):
        return "binary"
    if pa.types.is_list(t) or pa.types.is_large_list(t) or pa.types.is_list_view(t) or pa.types.is_large_list_view(t):
        return f"list<{_norm_arrow(t.value_type)}>"
    if pa.types.is_timestamp(t):
        return f"timestamp[{t.unit}, tz={t.tz}]"
    return str(t)


def _norm_polars(dt) -> str:
    import polars as pl

    if dt == pl.String:
        return "string"
    if dt == pl.Binary:
        return "binary"
    if isinstance(dt, pl.List):
        return f"list<{_norm_polars(dt.inner)}>"
    if isinstance(dt, pl.Datetime):
        return f"timestamp[{dt.time_unit}, tz={dt.time_zone}]"
    simple = {pl.Int32: "int32", pl.Int64: "int64", pl.Float32: "float", pl.Float64: "double",
              pl.Boolean: "bool", pl.Int16: "int16", pl.Int8: "int8", pl.UInt32: "uint32",
              pl.UInt64: "uint64"}
    for k, v in simple.items():
        if dt == k:
            return v
    return str(dt)


def _jsonable(v):
    import datetime

    if isinstance(v, (datetime.datetime, datetime.date)):
        return v.isoformat()
    if isinstance(v, bytes):
        return {"bytes_len": len(v)}
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    if isinstance(v, float) and v != v:
        return "NaN"
    return v


def _dump_rows(rows: list[dict], dump_dir: str | None) -> list[dict]:
    if rows and "episode_id" in rows[0]:
        rows.sort(key=lambda r: (r.get("episode_id") or "", r.get("frame_index") or 0))
    out = []
    for i, r in enumerate(rows):
        r = dict(r)
        if "image" in r and dump_dir is not None:
            img = r.pop("image")
            if img is None:
                r["image_file"] = None
            else:
                name = os.path.join(dump_dir, f"{i}.bin")
                with open(name, "wb") as f:
                    f.write(img)
                r["image_file"] = name
        out.append({k: _jsonable(v) for k, v in r.items()})
    return out


def read_deltalake(req: dict) -> dict:
    from deltalake import DeltaTable

    kwargs = {} if req.get("version") is None else {"version": int(req["version"])}
    dt = DeltaTable(req["path"], **kwargs)
    delta_nullable = {f.name: bool(f.nullable) for f in dt.schema().fields}
    table = dt.to_pyarrow_table()
    columns = {
        f.name: {"type": _norm_arrow(f.type), "raw_type": str(f.type),
                 "nullable": delta_nullable.get(f.name)}
        for f in table.schema
    }
    res = {"num_rows": table.num_rows, "loaded_version": dt.version(), "columns": columns, "rows": None}
    if req.get("dump"):
        res["rows"] = _dump_rows(table.to_pylist(), req.get("dump_dir"))
    return res


def read_polars(req: dict) -> dict:
    import polars as pl

    df = pl.read_delta(req["path"], version=req.get("version"))
    columns = {name: {"type": _norm_polars(dt), "raw_type": str(dt), "nullable": None}
               for name, dt in df.schema.items()}
    res = {"num_rows": df.height, "loaded_version": req.get("version"), "columns": columns, "rows": None}
    if req.get("dump"):
        res["rows"] = _dump_rows(df.to_dicts(), req.get("dump_dir"))
    return res


def main() -> int:
    with open(sys.argv[1]) as f:
        request = json.load(f)
    results = []
    for req in request["reads"]:
        if req.get("dump_dir"):
            os.makedirs(req["dump_dir"], exist_ok=True)
        reader = {"deltalake": read_deltalake, "polars": read_polars}[req["reader"]]
        results.append(reader(req))
    sys.stdout.write(json.dumps({"results": results}))
    return 0


if __name__ == "__main__":
    try:
        code = main()
    except BaseException:  # noqa: BLE001 - report everything to the parent test
        sys.stdout.write(json.dumps({"error": traceback.format_exc()}))
        code = 2
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
