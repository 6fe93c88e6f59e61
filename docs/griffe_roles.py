"""A griffe extension: the docstrings' Sphinx roles become links in the API reference.

The docstrings cite names the Sphinx way (``:class:`SerialPort```,
``:func:`~serialsocket.packets.build_packet```, ``:mod:`serialsocket.kermit```);
mkdocstrings reads Markdown, where those would show as raw text.  Each role
becomes an *optional* cross-reference (mkdocs-autorefs): a link when the
name has an entry in the reference, plain code when it does not (a private
module, trio), never a warning.  A relative name is looked up from the
package down to the object that cites it, so the public path wins
(``serialsocket.SerialPort``, not ``serialsocket._port.SerialPort``).  The
reST ``::`` that opens a literal block becomes ``:``.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|exc|obj|const):`(~?)([^`]+)`")
_LITERAL = re.compile(r"::$", re.MULTILINE)
TOP_LEVEL = ("serialsocket", "tcpstream", "linksim")


def _exists(collection: griffe.ModulesCollection, path: str) -> bool:
    try:
        collection[path]
    except Exception:  # a missing member, or an alias that points outside
        return False
    return True


def _identifier(obj: griffe.Object, name: str) -> str:
    if name.split(".")[0] in (*TOP_LEVEL, "trio"):
        return name
    top = obj.path.split(".")[0]
    scopes = [top]
    parts = obj.path.split(".")
    scopes += [".".join(parts[:i]) for i in range(len(parts), 1, -1)]
    for scope in scopes:
        if _exists(obj.modules_collection, f"{scope}.{name}"):
            return f"{scope}.{name}"
    return f"{top}.{name}"


def _convert(obj: griffe.Object, text: str) -> str:
    def replace(match: re.Match[str]) -> str:
        short, name = match.groups()
        name = name.strip().removesuffix("()")
        title = name.rsplit(".", 1)[-1] if short else name
        identifier = html.escape(_identifier(obj, name), quote=True)
        code = f"<code>{html.escape(title)}</code>"
        return f'<autoref identifier="{identifier}" optional>{code}</autoref>'

    return _LITERAL.sub(":", _ROLE.sub(replace, text))


class SphinxRoles(griffe.Extension):
    """Rewrites every docstring of a package once the whole package is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self._walk(pkg)

    def _walk(self, obj: griffe.Object) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _convert(obj, obj.docstring.value)
        for member in obj.members.values():
            if not member.is_alias and isinstance(member, griffe.Object):
                self._walk(member)
