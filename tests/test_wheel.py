"""A built wheel is a working VIRF: the knowledge artifact, the ontology
modules and the prompts are inside it, and ``virf verify`` answers from a
folder that is not the checkout."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
WALKTHROUGH = ROOT / "examples" / "walkthrough"


@pytest.fixture(scope="module")
def wheel_python(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("wheel")
    source = work / "src"
    # Build from a copy: the build writes build/ and *.egg-info next to the sources.
    shutil.copytree(
        ROOT,
        source,
        ignore=shutil.ignore_patterns(
            ".venv*",
            ".git",
            "runs",
            "build",
            "*.egg-info",
            "__pycache__",
            ".*_cache",
            ".hypothesis",
        ),
    )
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"), "."],
        cwd=source,
        capture_output=True,
        text=True,
        timeout=600,
    )
    if built.returncode != 0:
        pytest.fail(f"pip wheel failed: {built.stderr[-2000:]}")
    wheel = next((work / "dist").glob("virf-*.whl"))
    env_dir = work / "venv"
    venv.create(env_dir, with_pip=False)
    python = env_dir / "bin" / "python"
    # The new environment borrows this one's dependencies (no package index
    # needed) but not its editable VIRF: a .pth line adds the folder to the
    # path without running the editable install's own .pth hook.
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    Path(site, "borrowed.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    installed = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--no-deps",
            "-q",
            str(wheel),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if installed.returncode != 0:
        pytest.fail(f"pip install of the wheel failed: {installed.stderr[-2000:]}")
    return python


def test_the_wheel_verifies_from_anywhere(wheel_python: Path, tmp_path: Path) -> None:
    where = subprocess.run(
        [str(wheel_python), "-c", "import virf; print(virf.__file__)"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
    ).stdout
    assert "site-packages" in where and str(ROOT / "src") not in where
    virf = wheel_python.with_name("virf")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run(
        [str(virf), "verify", str(WALKTHROUGH / "scene.json"), str(WALKTHROUGH / "plan.txt")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=300,
    )
    assert run.returncode == 1, run.stdout + run.stderr
    assert "Verdict: UNSAFE at step 7" in run.stdout


def test_the_wheel_carries_every_artifact(wheel_python: Path, tmp_path: Path) -> None:
    probe = (
        "from virf.ontology.tbox import load_tbox, scenario_names\n"
        "from virf.ontology.compile import stale_artifacts\n"
        "print(stale_artifacts(), len(scenario_names()),"
        " {load_tbox(s).source for s in scenario_names()})\n"
    )
    run = subprocess.run(
        [str(wheel_python), "-c", probe], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert run.stdout.strip() == "[] 9 {'artifact'}", run.stderr
