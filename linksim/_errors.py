"""Errors shared by the sub-packages (a leaf: imports nothing from linksim)."""

from __future__ import annotations

__all__ = ["ConfigError"]


class ConfigError(ValueError):
    """A link parameter is out of range or malformed (the message names the field)."""
