"""Where the SafeAgentBench dev split is, and the benchmark commands run as a
user runs them.

The split lives outside the repository (``../shared`` beside the clone); tests
that need it skip when it is absent.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

SAB = ROOT.parent / "shared" / "benchmarks" / "safeagentbench"
needs_shared = pytest.mark.skipif(
    not SAB.is_dir(), reason=f"the SafeAgentBench split is not at {SAB}"
)


def bench_agents(*args: str | Path, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    """``virf bench agents ARGS`` in a fresh interpreter, with no OpenAI
    settings leaking in from the environment."""
    environ = {k: v for k, v in os.environ.items() if not k.startswith("OPENAI_")}
    return subprocess.run(
        [sys.executable, "-m", "virf.cli.main", "bench", "agents", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        # A guard against a hang, not a time limit: the kitchen replay takes
        # about a minute on an idle machine, several when the cores are shared.
        timeout=900,
        check=False,
        env=environ,
    )
