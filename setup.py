"""One build step pyproject.toml cannot declare: the wheel carries the
bundled examples (``examples/``, beside ``src/``) as ``virf/examples``, so an
installed ``virf demo`` and the service's example list have them.  They stay
at the top of the checkout, where the README, the Makefile and the tests name
them; ``virf.files.bundled_examples`` finds either copy."""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

EXAMPLES = Path(__file__).resolve().parent / "examples"


class BuildWithExamples(build_py):
    def run(self) -> None:
        super().run()
        # An editable install runs from the checkout, which has examples/.
        if getattr(self, "editable_mode", False) or not EXAMPLES.is_dir():
            return
        shutil.copytree(
            EXAMPLES,
            Path(self.build_lib, "virf", "examples"),
            dirs_exist_ok=True,
            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
        )


setup(cmdclass={"build_py": BuildWithExamples})
