"""How ``virf ... --help`` names parameters.

Typer 0.29 writes every parameter's Python type into help (``--json
<bool>``) and a required argument as ``{scene}`` on the usage line.  A flag
takes no value, so a type there reads as if one were expected; and braces
read as a set to choose from.  The command classes here keep typer's layout
and change only those two: a flag shows no type, and arguments are written
in the usual way, ``SCENE``, ``[FOLDER]`` when optional, ``FILE...`` when
repeated.  :func:`use_help_classes` makes every command of a typer app (and
of its sub-apps) one of these.
"""

from __future__ import annotations

from typing import Any

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption
from typer.models import DefaultPlaceholder


def _without_flag_type(param: Any) -> None:
    # Typer shows a parameter's metavar in place of its type when it has
    # one; an empty one shows nothing.  A metavar the command set stays.
    if isinstance(param, TyperOption) and param.is_flag and param.metavar is None:
        param.metavar = ""


def _usage_name(argument: TyperArgument) -> str:
    name = (argument.metavar or argument.name or "").upper()
    repeated = "..." if argument.nargs != 1 else ""
    return f"{name}{repeated}" if argument.required else f"[{name}]{repeated}"


def _usage_pieces(command: TyperCommand | TyperGroup, ctx: Any) -> list[str]:
    pieces = [command.options_metavar] if command.options_metavar else []
    for param in command.get_params(ctx):
        if isinstance(param, TyperArgument):
            pieces.append(_usage_name(param))
        else:
            pieces.extend(param.get_usage_pieces(ctx))
    return pieces


class _NoFlagTypes:
    """Mixed into a typer command or group: its flags, ``--help`` included,
    show no type."""

    params: list[Any]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            _without_flag_type(param)

    def get_help_option(self, ctx: Any) -> Any:
        option = super().get_help_option(ctx)  # type: ignore[misc]
        _without_flag_type(option)
        return option


class HelpCommand(_NoFlagTypes, TyperCommand):
    """A command whose help shows no type on flags and plain argument names."""

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        return _usage_pieces(self, ctx)


class HelpGroup(_NoFlagTypes, TyperGroup):
    """A group whose help, like :class:`HelpCommand`'s, shows no type on flags."""

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        return [*_usage_pieces(self, ctx), self.subcommand_metavar]


def use_help_classes(app: typer.Typer) -> typer.Typer:
    """``app`` with its commands and sub-apps, at any depth, built as
    :class:`HelpCommand` and :class:`HelpGroup`, unless one names a class
    of its own.  Typer records a command's class when it is registered, so
    this sets the records; it changes nothing already built."""
    for command in app.registered_commands:
        if command.cls is None or command.cls is TyperCommand:
            command.cls = HelpCommand
    for group in app.registered_groups:
        if isinstance(group.cls, DefaultPlaceholder) or group.cls in (None, TyperGroup):
            own = group.typer_instance.info.cls if group.typer_instance else None
            if isinstance(own, DefaultPlaceholder) or own in (None, TyperGroup):
                group.cls = HelpGroup
        if group.typer_instance is not None:
            use_help_classes(group.typer_instance)
    return app
