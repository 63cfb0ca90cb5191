#!/usr/bin/env python3
"""Do two pipeline runs hold the same data? Compares two `tools/demo.sh` output folders.

Every Delta table of `A/dataset` and `B/dataset` is read with the `deltalake` package
(no MILV code involved) at its latest version and compared row for row, sorted by all
columns, with what legitimately differs between runs left out:
  - timestamps (`ingested_at`);
  - ids derived from data-file names (`run_id`, `curation_id`: file names are random),
    replaced by a label made from the content of the rows that carry them;
and the MCAP files (`*.mcap`) are compared message for message (episode, topic, time
within the episode, payload bytes) with the `mcap` reader.

Exit status 0 when everything matches, 1 with a report of what differs.
Run two identical pipelines single-threaded (OMP_NUM_THREADS=1) for bitwise results.

    .venv/bin/python tools/compare_outputs.py out/demo-a out/demo-b [--json]
"""

import argparse
import hashlib
import json
import os
import sys
from pathlib import Path

TABLES = ["episodes", "frames", "alignments", "imagined", "scores", "curated"]
TIME_COLUMNS = {"ingested_at"}
# Ids hashed from data-file names, which are random per run.
FILE_DERIVED_IDS = {"run_id", "curation_id"}


def canonical(value):
    """A JSON-able, order-stable form of one Arrow value."""
    if isinstance(value, bytes):
        return {"sha256": hashlib.sha256(value).hexdigest(), "len": len(value)}
    if isinstance(value, float):
        return repr(value)  # bit-exact, NaN-safe
    if isinstance(value, list):
        return [canonical(v) for v in value]
    if isinstance(value, dict):
        return {k: canonical(v) for k, v in value.items()}
    return value


def row_key(row, columns):
    return json.dumps([canonical(row[c]) for c in columns], sort_keys=True)


def table_rows(root: Path, name: str):
    """The rows of one table, canonical and sorted, or None if the table does not exist."""
    from deltalake import DeltaTable

    path = root / name
    if not (path / "_delta_log").is_dir():
        return None
    rows = DeltaTable(str(path)).to_pyarrow_table().to_pylist()
    if not rows:
        return []
    columns = [c for c in rows[0] if c not in TIME_COLUMNS]
    content = [c for c in columns if c not in FILE_DERIVED_IDS]
    # A file-derived id becomes a label of the content of its rows (stable across runs).
    labels = {}
    for idc in [c for c in columns if c in FILE_DERIVED_IDS]:
        groups = {}
        for r in rows:
            groups.setdefault(r[idc], []).append(row_key(r, content))
        labels[idc] = {
            v: "content:" + hashlib.sha256("\n".join(sorted(g)).encode()).hexdigest()[:16]
            for v, g in groups.items()
        }
    out = []
    for r in rows:
        r = {c: r[c] for c in columns}
        for idc, m in labels.items():
            r[idc] = m[r[idc]]
        out.append(row_key(r, columns))
    out.sort()
    return out, columns


def payload_digest(schema: str, data: bytes, start_ns: int) -> str:
    """Digest of a message's payload; an image's own timestamp is made episode-relative."""
    if schema == "foxglove.CompressedImage":
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        img = CompressedImage()
        img.ParseFromString(data)
        t = img.timestamp.seconds * 1_000_000_000 + img.timestamp.nanos - start_ns
        img.timestamp.seconds, img.timestamp.nanos = divmod(t, 1_000_000_000)
        data = img.SerializeToString(deterministic=True)
    return hashlib.sha256(data).hexdigest()


def mcap_messages(path: Path):
    """Every message as (episode, topic, time within the episode, payload digest), sorted.

    Episodes follow one another on the recording's clock in the order the exporter read
    them, which is the storage order of the episodes table (not fixed between ingests),
    so times are taken relative to each episode's start (its `episode` metadata record).
    """
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        spans = []
        for m in reader.iter_metadata():
            if m.name == "episode":
                md = dict(m.metadata)
                spans.append((int(md["start_ns"]), int(md["end_ns"]), md["episode_id"],
                              {k: v for k, v in md.items() if k not in ("start_ns", "end_ns")}))
        spans.sort()
        out = [("episode-record", ep, json.dumps(md, sort_keys=True)) for _, _, ep, md in spans]
        for schema, ch, m in reader.iter_messages(log_time_order=True):
            span = next((s for s in spans if s[0] <= m.log_time < s[1]), None)
            start, ep = (span[0], span[2]) if span else (0, None)
            out.append((ep, ch.topic, m.log_time - start, m.publish_time - start,
                        payload_digest(schema.name, m.data, start)))
        return sorted(out, key=repr)


def compare(a: Path, b: Path):
    report = {"tables": {}, "mcap": {}, "equal": True}
    for name in TABLES:
        ra, rb = table_rows(a / "dataset", name), table_rows(b / "dataset", name)
        if ra is None and rb is None:
            continue
        if ra is None or rb is None:
            report["tables"][name] = {"equal": False, "why": "missing in one run"}
            report["equal"] = False
            continue
        (rows_a, cols_a), (rows_b, cols_b) = ra, rb
        only_a = sorted(set(rows_a) - set(rows_b))
        only_b = sorted(set(rows_b) - set(rows_a))
        equal = rows_a == rows_b and cols_a == cols_b
        entry = {"equal": equal, "rows": [len(rows_a), len(rows_b)]}
        if not equal:
            entry["columns"] = [cols_a, cols_b] if cols_a != cols_b else cols_a
            entry["distinct_only_in_a"] = len(only_a)
            entry["distinct_only_in_b"] = len(only_b)
            entry["example_a"] = only_a[:1]
            entry["example_b"] = only_b[:1]
            report["equal"] = False
        report["tables"][name] = entry
    for fa in sorted(a.glob("*.mcap")):
        fb = b / fa.name
        if not fb.exists():
            report["mcap"][fa.name] = {"equal": False, "why": "missing in the second run"}
            report["equal"] = False
            continue
        ma, mb = mcap_messages(fa), mcap_messages(fb)
        equal = ma == mb
        entry = {"equal": equal, "messages": [len(ma), len(mb)]}
        if not equal:
            first = next((i for i, (x, y) in enumerate(zip(ma, mb)) if x != y), min(len(ma), len(mb)))
            entry["first_difference"] = first
            report["equal"] = False
        report["mcap"][fa.name] = entry
    return report


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("a", type=Path, help="first output folder (holds dataset/ and *.mcap)")
    p.add_argument("b", type=Path, help="second output folder")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    args = p.parse_args()
    for d in (args.a, args.b):
        if not (d / "dataset").is_dir():
            print(f"compare_outputs: {d}: no dataset/ folder (a tools/demo.sh output expected)", file=sys.stderr)
            sys.stdout.flush()
            os._exit(2)
    report = compare(args.a, args.b)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for name, e in report["tables"].items():
            mark = "equal" if e["equal"] else "DIFFERENT"
            print(f"table {name:11} {mark:9} rows {e.get('rows')}")
            if not e["equal"]:
                print("   ", json.dumps({k: v for k, v in e.items() if k not in ("equal", "rows")})[:2000])
        for name, e in report["mcap"].items():
            mark = "equal" if e["equal"] else "DIFFERENT"
            print(f"mcap  {name:11} {mark:9} messages {e.get('messages')}")
        print("all equal" if report["equal"] else "the runs differ")
    sys.stdout.flush()
    # The deltalake reader can abort at interpreter exit (upstream issue).
    os._exit(0 if report["equal"] else 1)


if __name__ == "__main__":
    main()
