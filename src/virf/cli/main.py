"""The ``virf`` console entry point (``virf.cli.main:main``): the commands of
the sibling modules put together on the root app, in the order ``virf --help``
lists them."""

from __future__ import annotations

from virf.cli import bench, kb, perceive, plan, scene, serve, verify
from virf.cli.app import app, main

app.command()(verify.verify)
app.command()(verify.demo)
app.command()(plan.plan)
app.command()(perceive.perceive)
app.command()(serve.serve)
app.add_typer(kb.kb_app, name="kb")
app.add_typer(scene.scene_app, name="scene")
app.add_typer(bench.bench_app, name="bench")

__all__ = ["app", "main"]

if __name__ == "__main__":
    main()
