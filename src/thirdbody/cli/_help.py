"""Help screens: a flag takes no value, so it shows no type (typer's rich help wrote
``<bool>`` beside ``--help``, ``--resume``, ``--dry-run``, ...)."""

from __future__ import annotations

from typer.core import TyperCommand, TyperGroup


def _untyped_flags(params: list) -> list:
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


class Command(TyperCommand):
    def get_params(self, ctx):
        return _untyped_flags(super().get_params(ctx))


class Group(TyperGroup):
    def get_params(self, ctx):
        return _untyped_flags(super().get_params(ctx))
