#!/usr/bin/env python3
"""The Python baseline of the MCAP export benchmark (tools/bench/export_mcap.sh).

Writes the same messages as `milv-export mcap DATASET -o OUT` with the `mcap` package's
writer (zstd chunks of 1 MiB, indexes, statistics and summary, its defaults): for every
translated frame of one model, /human/image, /imagined/image (foxglove.CompressedImage,
protobuf), /imagined/latent (milv.Tensor, protobuf), /imagined/action and /quality (JSON)
and the aligned robot frame's /robot/image and /robot/action, episodes laid end to end.
Tables are read with deltalake/pyarrow at their latest version; only the newest scoring
and alignment runs are used, as milv-export does by default.

usage: export_mcap.py DATASET OUT.mcap   (prints a JSON line: messages, bytes, seconds)
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict

import pyarrow.parquet as pq
from deltalake import DeltaTable
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer


def tensor_class():
    """milv.Tensor (schemas/mcap/milv/tensor.proto), built from a descriptor as protoc would."""
    fd = descriptor_pb2.FileDescriptorProto(name="milv/tensor.proto", package="milv", syntax="proto3")
    m = fd.message_type.add(name="Tensor")
    T = descriptor_pb2.FieldDescriptorProto
    for name, num, ty, rep in [("timestamp_ns", 1, T.TYPE_INT64, False), ("episode_id", 2, T.TYPE_STRING, False),
                               ("frame_index", 3, T.TYPE_INT32, False), ("model_id", 4, T.TYPE_STRING, False),
                               ("dtype", 5, T.TYPE_STRING, False), ("shape", 6, T.TYPE_UINT32, True),
                               ("data", 7, T.TYPE_BYTES, False)]:
        m.field.add(name=name, number=num, type=ty, label=T.LABEL_REPEATED if rep else T.LABEL_OPTIONAL)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fd)
    fds = descriptor_pb2.FileDescriptorSet(file=[fd])
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("milv.Tensor")), fds.SerializeToString()


def image_descriptor() -> bytes:
    fds = descriptor_pb2.FileDescriptorSet()
    seen = set()

    def add(f):
        if f.name in seen:
            return
        for d in f.dependencies:
            add(d)
        seen.add(f.name)
        p = descriptor_pb2.FileDescriptorProto()
        f.CopyToProto(p)
        fds.file.append(p)

    add(CompressedImage.DESCRIPTOR.file)
    return fds.SerializeToString()


def newest(table: str, key: str, pred=lambda r: True):
    """The rows of the newest run (by file order of the Delta log) of `key`."""
    t = DeltaTable(table)
    rows = t.to_pyarrow_table().to_pylist()
    files = t.file_uris()
    # Rows of the last file that has a matching row name the newest run.
    last = None
    for f in reversed(files):
        cols = [key] + [c for c in ("source_table", "model_id") if c in pq.read_schema(f).names]
        for r in pq.read_table(f, columns=cols).to_pylist():
            if pred(r):
                last = r[key]
                break
        if last is not None:
            break
    return [r for r in rows if r[key] == last]


def main(ds: str, out: str) -> None:
    t0 = time.perf_counter()
    eps = {r["episode_id"]: r for r in DeltaTable(f"{ds}/episodes").to_pyarrow_table().to_pylist()}
    imagined = DeltaTable(f"{ds}/imagined").to_pyarrow_table().to_pylist()
    model = imagined[0]["model_id"]
    by_ep = defaultdict(list)
    for r in imagined:
        by_ep[r["episode_id"]].append(r)
    frames = {(r["episode_id"], r["frame_index"]): r
              for r in DeltaTable(f"{ds}/frames").to_pyarrow_table().to_pylist()}
    is_model = lambda r: r.get("source_table") == "imagined" and r.get("model_id") == model
    quality = {(r["episode_id"], r["frame_index"]): r for r in newest(f"{ds}/scores", "run_id", is_model)
               if is_model(r)}
    aligned = {}
    for r in newest(f"{ds}/alignments", "run_id"):
        k = (r["human_episode_id"], r["human_frame"])
        v = (r["robot_episode_id"], r["robot_frame"])
        aligned[k] = min(aligned.get(k, v), v)
    names = next((e["action_names"] for e in eps.values() if e["domain"] == "robot" and e["action_names"]),
                 ["dx", "dy"])

    Tensor, tensor_fds = tensor_class()
    with open(out, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="python mcap")
        img_s = w.register_schema("foxglove.CompressedImage", SchemaEncoding.Protobuf, image_descriptor())
        act_s = w.register_schema("milv.Action", SchemaEncoding.JSONSchema, b"{}")
        q_s = w.register_schema("milv.Quality", SchemaEncoding.JSONSchema, b"{}")
        t_s = w.register_schema("milv.Tensor", SchemaEncoding.Protobuf, tensor_fds)
        ch = {t: w.register_channel(t, MessageEncoding.Protobuf, img_s)
              for t in ("/human/image", "/imagined/image", "/robot/image")}
        ch.update({t: w.register_channel(t, MessageEncoding.JSON, act_s) for t in ("/imagined/action", "/robot/action")})
        ch["/quality"] = w.register_channel("/quality", MessageEncoding.JSON, q_s)
        ch["/imagined/latent"] = w.register_channel("/imagined/latent", MessageEncoding.Protobuf, t_s)
        seq, n, offset = 0, 0, 0

        def put(topic, t, data):
            nonlocal seq, n
            seq += 1
            n += 1
            w.add_message(ch[topic], log_time=t, data=data, publish_time=t, sequence=seq)

        def image(topic, t, data, fmt):
            m = CompressedImage(frame_id=topic.strip("/").removesuffix("/image"), data=data, format=fmt)
            m.timestamp.seconds, m.timestamp.nanos = divmod(t, 1_000_000_000)
            put(topic, t, m.SerializeToString())

        def action(topic, t, ep, i, a):
            d = {"episode_id": ep, "frame_index": i}
            d.update(zip(names, a))
            put(topic, t, json.dumps(d).encode())

        for ep in sorted(by_ep):
            rows = sorted(by_ep[ep], key=lambda r: r["frame_index"])
            e = eps[ep]
            fmt = "jpeg" if e["frame_encoding"] == "jpeg" else "png"
            last = 0
            for r in rows:
                i = r["frame_index"]
                t = offset + r["timestamp_ns"]
                last = r["timestamp_ns"]
                image("/human/image", t, frames[(ep, i)]["image"], fmt)
                image("/imagined/image", t, r["image"], "png")
                put("/imagined/latent", t, Tensor(timestamp_ns=r["timestamp_ns"], episode_id=ep, frame_index=i,
                                                  model_id=model, dtype=r["latent_dtype"],
                                                  shape=r["latent_shape"], data=r["latent"]).SerializeToString())
                action("/imagined/action", t, ep, i, r["action"])
                q = quality.get((ep, i))
                if q:
                    put("/quality", t, json.dumps({"episode_id": ep, "frame_index": i, "brenner": q["brenner"],
                                                  "ssim": q["ssim"], "beta": q["beta"], "weight": None}).encode())
                a = aligned.get((ep, i))
                if a:
                    rf = frames[a]
                    image("/robot/image", t, rf["image"], fmt)
                    if rf["action"] is not None:
                        action("/robot/action", t, a[0], a[1], rf["action"])
            offset += last + int(1e9 / e["fps"])
        w.finish()
        f.flush()
        os.fsync(f.fileno())  # as milv-mcap does before its rename
    dt = time.perf_counter() - t0
    print(json.dumps({"messages": n, "bytes": os.path.getsize(out), "seconds": dt}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
