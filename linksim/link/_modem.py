"""Two emulated Hayes 2400-baud modems joined by a line (sans-I/O).

:class:`ModemPair` holds modem 0 and modem 1.  Each faces a DTE (the user's
program on a pty) and the line (the impaired link to the other modem).  The
caller feeds bytes and ``now`` in and collects bytes out::

    pair.from_dte(side, data, now)     # what the program wrote
    pair.from_line(side, data, now)    # what the line delivered to this modem
    pair.set_signal(side, present, now)  # line signal into this modem (outages)
    pair.handle_timer(now)             # at or after pair.next_timer()
    pair.data_to_dte(side)             # responses, echo, data for the program
    pair.data_to_line(side)            # data this modem puts on the line

The AT command set is what a Hayes Smartmodem 2400 answers: ``Z``, ``E0/1``,
``V0/1``, ``Q0/1``, ``I``, ``&F``, ``Sn=v``, ``Sn?``, ``D[T|P]number``, ``A``,
``H``, ``O``; responses ``OK``, ``CONNECT 2400``, ``RING``, ``NO CARRIER``,
``ERROR``, ``BUSY``, ``NO ANSWER`` (verbose with CR LF framing, or numeric
with ``V0``).  Registers: S0 rings before auto-answer (0 = never), S1 ring
count, S2 escape character (``+``), S3 CR, S5 backspace, S7 seconds to wait
for an answer, S10 carrier-loss limit in tenths of a second, S12 escape guard
time in fiftieths of a second.  A call rings the other modem; numbers listed
in the phone book as ``BUSY`` or ``NO_ANSWER`` get that result instead.

States and transitions are in :data:`TRANSITIONS`; an illegal transition
raises :class:`ModemStateError` (a bug in this module, never the user's input).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

__all__ = [
    "TRANSITIONS",
    "CallOutcome",
    "ModemConfig",
    "ModemPair",
    "ModemState",
    "ModemStateError",
]


class ModemState(enum.Enum):
    """Where one modem is."""

    IDLE = "idle"  # on hook, command mode
    DIALING = "dialing"  # off hook, waiting for the call's outcome
    RINGING = "ringing"  # on hook, an incoming call rings
    ANSWERING = "answering"  # carrier training before CONNECT
    ONLINE = "online"  # data mode
    ONLINE_COMMAND = "online-command"  # call up, command mode after +++


TRANSITIONS: dict[ModemState, frozenset[ModemState]] = {
    ModemState.IDLE: frozenset({ModemState.DIALING, ModemState.RINGING}),
    ModemState.DIALING: frozenset({ModemState.IDLE, ModemState.ANSWERING}),
    ModemState.RINGING: frozenset({ModemState.IDLE, ModemState.ANSWERING}),
    ModemState.ANSWERING: frozenset({ModemState.IDLE, ModemState.ONLINE}),
    ModemState.ONLINE: frozenset({ModemState.IDLE, ModemState.ONLINE_COMMAND}),
    ModemState.ONLINE_COMMAND: frozenset({ModemState.IDLE, ModemState.ONLINE}),
}
_CALL_UP = frozenset({ModemState.ANSWERING, ModemState.ONLINE, ModemState.ONLINE_COMMAND})


class ModemStateError(RuntimeError):
    """An illegal state transition: a defect in the emulator."""


class CallOutcome(enum.Enum):
    """What dialing a number in the phone book gives."""

    ANSWER = "answer"  # rings the other modem
    BUSY = "busy"
    NO_ANSWER = "no-answer"


# Hayes result codes (Smartmodem 2400 manual, "Result codes"): verbose text -> number.
_RESULT_CODES = {
    "OK": 0,
    "CONNECT": 1,
    "RING": 2,
    "NO CARRIER": 3,
    "ERROR": 4,
    "CONNECT 1200": 5,
    "NO DIALTONE": 6,
    "BUSY": 7,
    "NO ANSWER": 8,
    "CONNECT 2400": 10,
    "CONNECT 4800": 11,
    "CONNECT 9600": 12,
}
# Power-on register values (Hayes defaults).
_DEFAULT_S = {
    0: 0,
    1: 0,
    2: 43,
    3: 13,
    4: 10,
    5: 8,
    6: 2,
    7: 50,
    8: 2,
    9: 6,
    10: 14,
    11: 95,
    12: 50,
}
_N_REGISTERS = 28


@dataclass(frozen=True, slots=True)
class ModemConfig:
    """Timing of the emulated telephone network and modems (seconds).

    ``dial_time``: from ATD to the first RING (or BUSY); ``ring_interval``:
    between RINGs (US cadence: 2 s on, 4 s off); ``handshake_time``: from
    answer to CONNECT (carrier training); ``connect_rate``: the rate in
    ``CONNECT <rate>``; ``phone_book``: numbers with a fixed outcome.
    """

    dial_time: float = 2.0
    ring_interval: float = 6.0
    handshake_time: float = 1.5
    connect_rate: int = 2400
    phone_book: Mapping[str, CallOutcome] = field(default_factory=dict)


class _Modem:
    """State of one modem (plain data; the logic lives in ModemPair)."""

    def __init__(self) -> None:
        self.state = ModemState.IDLE
        self.s = dict.fromkeys(range(_N_REGISTERS), 0) | _DEFAULT_S
        self.echo = True
        self.verbose = True
        self.quiet = False
        self.line = bytearray()  # command line being typed
        self.to_dte = bytearray()
        self.to_line = bytearray()
        self.timers: dict[str, float] = {}
        self.signal = True  # line signal from the far modem's direction
        self.last_dte = -math.inf  # time of the last DTE byte in data mode
        self.esc_count = 0
        self.esc_last = -math.inf

    def reset(self) -> None:
        self.s = dict.fromkeys(range(_N_REGISTERS), 0) | _DEFAULT_S
        self.echo, self.verbose, self.quiet = True, True, False


class ModemPair:
    """Modem 0 and modem 1 on one telephone line (see the module docstring)."""

    def __init__(self, config: ModemConfig | None = None) -> None:
        self.config = config or ModemConfig()
        self._m = (_Modem(), _Modem())

    # -- public interface -------------------------------------------------------

    def state(self, side: int) -> ModemState:
        """The state of modem ``side``."""
        return self._m[side].state

    def register(self, side: int, n: int) -> int:
        """S-register ``n`` of modem ``side``."""
        return self._m[side].s[n]

    def data_to_dte(self, side: int) -> bytes:
        """Bytes for the program attached to ``side`` (and clears them)."""
        m = self._m[side]
        out = bytes(m.to_dte)
        m.to_dte.clear()
        return out

    def data_to_line(self, side: int) -> bytes:
        """Bytes modem ``side`` transmits towards the other modem (and clears them)."""
        m = self._m[side]
        out = bytes(m.to_line)
        m.to_line.clear()
        return out

    def next_timer(self) -> float | None:
        """The earliest pending deadline, or None."""
        times = [t for m in self._m for t in m.timers.values()]
        return min(times) if times else None

    def from_line(self, side: int, data: bytes, now: float) -> None:
        """Bytes the line delivered to modem ``side``: passed to the DTE in data mode."""
        self.handle_timer(now)
        if self._m[side].state is ModemState.ONLINE:
            self._m[side].to_dte += data

    def set_signal(self, side: int, present: bool, now: float) -> None:
        """Whether the far modem's signal reaches modem ``side`` (False during an outage)."""
        self.handle_timer(now)
        self._m[side].signal = present
        self._update_carrier(now)

    def from_dte(self, side: int, data: bytes, now: float) -> None:
        """Bytes the program attached to ``side`` wrote."""
        self.handle_timer(now)
        m = self._m[side]
        if m.state is ModemState.ONLINE:
            self._data_mode_input(side, data, now)
            return
        if m.state in (ModemState.DIALING, ModemState.ANSWERING):
            # Any key aborts a call in progress (Hayes behaviour).
            self._hang_up(side, now)
            self._result(side, "NO CARRIER")
            return
        for byte in data:
            self._command_char(side, byte, now)

    def handle_timer(self, now: float) -> None:
        """Fire every deadline that is due at ``now``, earliest first."""
        while True:
            due = [
                (t, side, name) for side, m in enumerate(self._m) for name, t in m.timers.items()
            ]
            due = [d for d in due if d[0] <= now]
            if not due:
                return
            t, side, name = min(due)
            del self._m[side].timers[name]
            self._fire(side, name, t)

    # -- transitions --------------------------------------------------------------

    def _goto(self, side: int, new: ModemState) -> None:
        m = self._m[side]
        if new not in TRANSITIONS[m.state]:
            raise ModemStateError(f"modem {side}: {m.state.value} -> {new.value}")
        m.state = new

    def _result(self, side: int, text: str) -> None:
        m = self._m[side]
        if m.quiet:
            return
        if m.verbose:
            m.to_dte += b"\r\n" + text.encode() + b"\r\n"
        else:
            m.to_dte += str(_RESULT_CODES.get(text, 1)).encode() + b"\r"

    def _fire(self, side: int, name: str, now: float) -> None:
        m, peer = self._m[side], 1 - side
        if name == "dial-result":  # BUSY from the network
            self._goto(side, ModemState.IDLE)
            m.timers.clear()
            self._result(side, "BUSY")
        elif name == "no-answer":  # S7 expired on the caller
            if self._m[peer].state is ModemState.RINGING:
                self._goto(peer, ModemState.IDLE)
                self._m[peer].timers.clear()
            self._goto(side, ModemState.IDLE)
            m.timers.clear()
            self._result(side, "NO ANSWER")
        elif name == "ring":
            m.s[1] += 1
            self._result(side, "RING")
            if m.s[0] and m.s[1] >= m.s[0]:
                self._answer(side, now)
            else:
                m.timers["ring"] = now + self.config.ring_interval
        elif name == "connect":
            self._goto(side, ModemState.ONLINE)
            m.last_dte = now
            self._result(side, f"CONNECT {self.config.connect_rate}")
            self._update_carrier(now)
        elif name == "escape":
            m.esc_count = 0
            self._goto(side, ModemState.ONLINE_COMMAND)
            self._result(side, "OK")
        elif name == "carrier-lost":
            self._hang_up(side, now)
            self._result(side, "NO CARRIER")

    def _dial(self, side: int, number: str, now: float) -> None:
        m, peer = self._m[side], 1 - side
        self._goto(side, ModemState.DIALING)
        outcome = self.config.phone_book.get(number, CallOutcome.ANSWER)
        if outcome is CallOutcome.ANSWER and self._m[peer].state is not ModemState.IDLE:
            outcome = CallOutcome.BUSY
        if outcome is CallOutcome.BUSY:
            m.timers["dial-result"] = now + self.config.dial_time
            return
        m.timers["no-answer"] = now + m.s[7]
        if outcome is CallOutcome.ANSWER:
            self._goto(peer, ModemState.RINGING)
            self._m[peer].s[1] = 0
            self._m[peer].timers["ring"] = now + self.config.dial_time

    def _answer(self, side: int, now: float) -> None:
        peer = 1 - side
        for s in (side, peer):
            self._m[s].timers.clear()
            self._goto(s, ModemState.ANSWERING)
            self._m[s].timers["connect"] = now + self.config.handshake_time
        self._m[side].s[1] = 0

    def _hang_up(self, side: int, now: float) -> None:
        m, peer = self._m[side], 1 - side
        m.timers.clear()
        m.esc_count = 0
        if m.state is ModemState.DIALING and self._m[peer].state is ModemState.RINGING:
            self._goto(peer, ModemState.IDLE)
            self._m[peer].timers.clear()
        if m.state is not ModemState.IDLE:
            self._goto(side, ModemState.IDLE)
        self._update_carrier(now)

    def _update_carrier(self, now: float) -> None:
        """Start or stop each connected modem's carrier-loss timer (S10 tenths)."""
        for side, m in enumerate(self._m):
            if m.state not in _CALL_UP:
                continue
            present = m.signal and self._m[1 - side].state in _CALL_UP
            if present:
                m.timers.pop("carrier-lost", None)
            elif "carrier-lost" not in m.timers:
                m.timers["carrier-lost"] = now + m.s[10] / 10

    # -- data mode ---------------------------------------------------------------

    def _data_mode_input(self, side: int, data: bytes, now: float) -> None:
        """Send DTE data to the line, watching for ``+++`` between guard times (S12)."""
        m = self._m[side]
        m.to_line += data
        esc = bytes([m.s[2]])
        guard = m.s[12] / 50
        only_esc = m.s[2] <= 127 and data == esc * len(data)
        if only_esc and 0 < m.esc_count < 3 and now - m.esc_last < guard:
            m.esc_count += len(data)
        elif only_esc and m.esc_count == 0 and now - m.last_dte >= guard:
            m.esc_count = len(data)
        else:
            m.esc_count = 0
        m.esc_last = m.last_dte = now
        m.timers.pop("escape", None)
        if m.esc_count == 3:
            m.timers["escape"] = now + guard
        elif m.esc_count > 3:
            m.esc_count = 0

    # -- command mode ------------------------------------------------------------

    def _command_char(self, side: int, byte: int, now: float) -> None:
        m = self._m[side]
        if m.echo:
            m.to_dte.append(byte)
        if byte == m.s[3]:
            line = m.line.decode("latin-1").strip()
            m.line.clear()
            if line[:2].upper() == "AT":
                self._execute(side, line[2:], now)
        elif byte == m.s[5]:
            del m.line[-1:]
        elif byte != m.s[4] and len(m.line) < 80:  # Hayes' 40-char buffer, doubled
            m.line.append(byte)

    def _execute(self, side: int, cmds: str, now: float) -> None:
        """Run one AT command line; exactly one final result code is produced."""
        m = self._m[side]
        i = 0
        text = cmds.replace(" ", "")
        while i < len(text):
            c = text[i].upper()
            i += 1
            num = ""
            while c in "EVQZHOI&S" and i < len(text) and text[i].isdigit() and c != "S":
                num += text[i]
                i += 1
            if c == "D":
                if m.state is not ModemState.IDLE:
                    self._result(side, "ERROR")
                    return
                number = "".join(ch for ch in text[i:] if ch.isdigit() or ch in "*#")
                self._dial(side, number, now)
                return  # D ends the line; the result code comes from the call
            if c == "A":
                if m.state is ModemState.RINGING:
                    self._answer(side, now)
                else:
                    self._result(side, "NO CARRIER")
                return
            if c == "O":
                if m.state is not ModemState.ONLINE_COMMAND:
                    self._result(side, "ERROR")
                    return
                self._goto(side, ModemState.ONLINE)
                m.last_dte = now
                self._result(side, f"CONNECT {self.config.connect_rate}")
                return
            if c in "EVQ" and num in ("", "0", "1"):
                value = num == "1"
                if c == "E":
                    m.echo = value
                elif c == "V":
                    m.verbose = value
                else:
                    m.quiet = value
            elif c == "Z" and num in ("", "0"):
                if m.state is not ModemState.IDLE:
                    self._hang_up(side, now)
                m.reset()
            elif c == "H" and num in ("", "0"):
                self._hang_up(side, now)
            elif c == "I" and num in ("", "0"):
                m.to_dte += b"\r\n242\r\n" if m.verbose else b"242\r"
            elif c == "&" and i < len(text) and text[i].upper() == "F":
                i += 1
                m.reset()
            elif c == "S":
                i = self._register(side, text, i)
                if i < 0:
                    self._result(side, "ERROR")
                    return
            else:
                self._result(side, "ERROR")
                return
        self._result(side, "OK")

    def _register(self, side: int, text: str, i: int) -> int:
        """Parse ``n=v`` or ``n?`` after an ``S``; returns the next index or -1 on error."""
        m = self._m[side]
        j = i
        while j < len(text) and text[j].isdigit():
            j += 1
        if j == i or int(text[i:j]) >= _N_REGISTERS or j >= len(text):
            return -1
        n = int(text[i:j])
        if text[j] == "?":
            m.to_dte += (
                f"\r\n{m.s[n]:03d}\r\n".encode() if m.verbose else f"{m.s[n]:03d}\r".encode()
            )
            return j + 1
        if text[j] != "=":
            return -1
        k = j + 1
        while k < len(text) and text[k].isdigit():
            k += 1
        if k == j + 1 or int(text[j + 1 : k]) > 255:
            return -1
        m.s[n] = int(text[j + 1 : k])
        return k
