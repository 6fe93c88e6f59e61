"""The state diagram as text, rendered from the table in :mod:`serialsocket._state`.

PROTOCOL.md section 7 holds exactly :func:`render`'s output, and a test
keeps it so: change the table, then paste ``python -m serialsocket._diagram``
into the document.
"""

from __future__ import annotations

from ._state import STATE_SETS, TRANSITIONS, State, Trigger

__all__ = ["render"]


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> list[str]:
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]

    def line(cells: tuple[str, ...]) -> str:
        return "  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)).rstrip()

    return [line(header), line(tuple("-" * w for w in widths)), *(line(r) for r in rows)]


def render() -> str:
    """The transitions (state x trigger -> next state, in enum order) and, for
    each state, the named state sets it belongs to; newline-terminated."""
    trigger_order = list(Trigger)
    pairs = sorted(
        TRANSITIONS.items(),
        key=lambda item: (list(State).index(item[0][0]), trigger_order.index(item[0][1])),
    )
    transitions = _table(
        ("state", "trigger", "next", "the trigger"),
        [(s.name, t.name, n.name, t.value) for (s, t), n in pairs],
    )
    names = list(STATE_SETS)
    membership = _table(
        ("state", *names),
        [
            (state.name, *("x" if state in STATE_SETS[n][0] else "-" for n in names))
            for state in State
        ],
    )
    legend = [f"{name}: {meaning}" for name, (_, meaning) in STATE_SETS.items()]
    return "\n".join([*transitions, "", *membership, "", *legend]) + "\n"


if __name__ == "__main__":
    print(render(), end="")
