"""The ``virf`` console entry point (``virf.cli.main:main``).  The root app
finds its commands in the sibling modules when they are run
(:data:`virf.cli.app.COMMANDS`): importing them all up front cost a cold
``virf verify`` about 40 ms before it began."""

from __future__ import annotations

from virf.cli.app import app, main

__all__ = ["app", "main"]

if __name__ == "__main__":
    main()
