"""A real PostgreSQL server for the tests, started in a temporary folder.

Debian's ``postgresql`` package provides the server (``make test`` installs
it when missing).  The server refuses to run as root, so under root it runs
as the ``postgres`` user the package creates.  It listens on 127.0.0.1 only,
on a free port, and trusts local connections: no other machine can reach it
(another user of this one could, while it runs; it holds only test data),
and it is stopped and deleted at the end of the session.
"""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


def server_bin() -> Path | None:
    """The folder of initdb and pg_ctl, or None when no server is installed."""
    found = shutil.which("pg_config")
    if found:
        out = subprocess.run([found, "--bindir"], capture_output=True, text=True, check=False)
        folder = Path(out.stdout.strip())
        if (folder / "initdb").is_file():
            return folder
    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(versions[-1]).parent if versions else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    folder = server_bin()
    if folder is None:
        pytest.skip("no PostgreSQL server installed (make test installs Debian's postgresql)")
    as_root = os.geteuid() == 0
    if as_root and shutil.which("runuser") is None:
        pytest.skip("running as root needs runuser to start PostgreSQL as its own user")
    prefix = ["runuser", "-u", "postgres", "--"] if as_root else []
    work = Path(tempfile.mkdtemp(prefix="virf-pg-"))
    data = work / "data"
    if as_root:
        shutil.chown(work, "postgres")
        work.chmod(0o700)
    port = _free_port()
    log = work / "server.log"

    def run(*args: str) -> None:
        result = subprocess.run(
            [*prefix, *args], capture_output=True, text=True, timeout=120, check=False
        )
        if result.returncode != 0:
            detail = (result.stderr or result.stdout).strip().splitlines()
            raise RuntimeError(f"{args[0]} failed: {detail[-1] if detail else result.returncode}")

    options = f"-p {port} -k {work} -c listen_addresses=127.0.0.1 -c fsync=off"
    try:
        run(str(folder / "initdb"), "-D", str(data), "-U", "virf", "--auth=trust", "-E", "UTF8")
        run(str(folder / "pg_ctl"), "-D", str(data), "-l", str(log), "-o", options, "-w", "start")
        yield f"postgresql://virf@127.0.0.1:{port}/postgres"
    finally:
        # Also after a start that timed out: the server may be up all the same.
        subprocess.run(
            [*prefix, str(folder / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop"],
            capture_output=True,
            timeout=60,
            check=False,
        )
        shutil.rmtree(work, ignore_errors=True)
