"""Hayes AT dialing: dial, answer and hang up a modem on a port.

The modem sits between the port and the telephone line.  In command mode it
answers each command line with a result code (``OK``, ``CONNECT 2400``,
``BUSY``, ...; verbose text or, after ``ATV0``, a number); after ``CONNECT``
it is in data mode and every byte goes to the far end until carrier is lost
or the escape sequence -- a guard time of silence, ``+++``, another guard
time -- returns it to command mode.

Reads during command mode take one byte at a time, so nothing that follows
``CONNECT`` (the far end's first data) is consumed here: the port is handed
to the serial socket exactly at the start of data mode.

Every wait is bounded (``command_timeout``, ``timeout``) and cancellable; a
dial that times out or is cancelled aborts the call (any character does, on a
Hayes modem) before the error propagates.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import trio

__all__ = [
    "DialError",
    "LineBusy",
    "ModemConnection",
    "ModemError",
    "ModemTimeout",
    "NoAnswer",
    "NoCarrier",
    "NoDialtone",
    "answer",
    "dial",
    "hangup",
]

_MAX_LINE = 256
"""Longest response line kept: Hayes result codes and ATI text are far
shorter; a longer run without CR/LF is line noise and is cut."""

_NUMERIC = {
    "0": "OK",
    "1": "CONNECT",
    "2": "RING",
    "3": "NO CARRIER",
    "4": "ERROR",
    "5": "CONNECT 1200",
    "6": "NO DIALTONE",
    "7": "BUSY",
    "8": "NO ANSWER",
    "10": "CONNECT 2400",
    "11": "CONNECT 4800",
    "12": "CONNECT 9600",
}
"""Hayes numeric result codes (``ATV0``), Smartmodem 2400 manual."""

_CONNECT = re.compile(r"CONNECT(?:\s+(\d+))?")
_DIAL_CHARS = re.compile(r"[0-9*#,WwPpTt!@ ()-]+")


class DialError(Exception):
    """The modem could not set up (or tear down) a call.

    Attributes:
        result: the modem's result line ("" when it said nothing).
    """

    def __init__(self, message: str, result: str = "") -> None:
        super().__init__(message)
        self.result = result


class LineBusy(DialError):
    """The number is busy (``BUSY``)."""


class NoCarrier(DialError):
    """No carrier: the call failed or the far modem hung up (``NO CARRIER``)."""


class NoAnswer(DialError):
    """The far end rang but nobody answered (``NO ANSWER``)."""


class NoDialtone(DialError):
    """No dial tone on the line (``NO DIALTONE``)."""


class ModemError(DialError):
    """The modem rejected a command (``ERROR``) or answered nonsense."""


class ModemTimeout(ModemError, TimeoutError):
    """The modem did not answer in time (is it there, powered, at this baud rate?)."""


@dataclass(frozen=True, slots=True)
class ModemConnection:
    """A call in data mode.

    Attributes:
        rate: the rate in the CONNECT message (bit/s), or None for a bare
            ``CONNECT`` (300 bit/s on an original Hayes; unknown here).
        result: the full result line, e.g. ``CONNECT 2400``.
    """

    rate: int | None
    result: str


class _Responses:
    """Result lines from the modem, one byte read at a time (never past a line)."""

    def __init__(self, port: trio.abc.Stream) -> None:
        self.port = port
        self.buf = bytearray()
        self.verbose = True  # the last line was text (CR LF framed), not a number

    async def end_of_line(self, wait: float) -> None:
        """Consume the LF that follows the CR of a verbose result code.

        Called after CONNECT so the LF does not reach the serial socket as
        line noise.  The modem sends CR LF together; if the next byte is not
        an LF after all it is data and is dropped (the parser above would
        have discarded it as garbage anyway; the peer's ARQ resends it).
        """
        if self.verbose:
            with trio.move_on_after(wait):
                await self.port.receive_some(1)

    async def line(self) -> str:
        """The next non-empty line, with numeric codes translated to their text."""
        while True:
            data = await self.port.receive_some(1)
            if not data:
                raise ModemError("the port reached EOF while talking to the modem")
            byte = data[0]
            if byte in b"\r\n":
                text = self.buf.decode("latin-1").strip()
                self.buf.clear()
                if text:
                    self.verbose = text not in _NUMERIC
                    return _NUMERIC.get(text, text).upper()
            elif len(self.buf) < _MAX_LINE:
                self.buf.append(byte)


async def _command(
    port: trio.abc.Stream, resp: _Responses, command: str, command_timeout: float
) -> None:
    """Send one AT command line and wait for OK."""
    await port.send_all(command.encode("ascii") + b"\r")
    with trio.move_on_after(command_timeout) as scope:
        while True:
            text = await resp.line()
            if text == "OK":
                return
            if text == "ERROR":
                raise ModemError(
                    f"the modem answered ERROR to {command!r}: it does not support this "
                    "command; check the init string",
                    text,
                )
            # Anything else is our own echo (E1) or unsolicited text: skip it.
    if scope.cancelled_caught:
        raise ModemTimeout(
            f"no OK from the modem within {command_timeout} s after {command!r}: is a "
            "Hayes modem attached to this port, powered on, and set to this baud rate?"
        )


def _connected(text: str) -> ModemConnection | None:
    m = _CONNECT.match(text)
    if m is None:
        return None
    return ModemConnection(int(m.group(1)) if m.group(1) else None, text)


def _call_failure(text: str, number: str) -> DialError | None:
    """The typed error for a final result code of a call, or None if it is not one."""
    if text == "BUSY":
        return LineBusy(f"{number} is busy: try again later", text)
    if text == "NO ANSWER":
        return NoAnswer(
            f"{number} rang but did not answer: is the remote modem set to auto-answer "
            "(ATS0=1) or is its program waiting for RING?",
            text,
        )
    if text in ("NO DIALTONE", "NO DIAL TONE"):
        return NoDialtone(
            "no dial tone: check that the modem's line cable is plugged in (or dial with "
            "X0/X3 if the exchange's tone is unusual)",
            text,
        )
    if text == "NO CARRIER":
        return NoCarrier(
            f"no carrier from {number}: the call did not reach a modem, or the carrier "
            "handshake failed; check the number and try again",
            text,
        )
    if text == "ERROR":
        return ModemError(f"the modem rejected the dial command for {number!r}", text)
    return None


async def dial(
    port: trio.abc.Stream,
    number: str,
    *,
    timeout: float = 60.0,
    command_timeout: float = 5.0,
    init: str | None = None,
    pulse: bool = False,
) -> ModemConnection:
    """Dial ``number`` and wait until the modem is in data mode.

    Sends ``ATZ`` (reset), then ``init`` if given (e.g. ``"ATE0 S7=30"``),
    then ``ATDT<number>`` (``ATDP`` with ``pulse``), and waits for CONNECT.

    Args:
        port: the modem's port.
        number: digits and dial modifiers (``0-9 * # , W``).
        timeout: seconds from ATD to CONNECT (a Hayes modem gives up after
            S7 = 50 s by itself).
        command_timeout: seconds to wait for OK after each setup command.

    Returns:
        The connection (its rate); the port now carries data.

    Raises:
        LineBusy, NoAnswer, NoCarrier, NoDialtone: the call failed.
        ModemError: the modem answered ERROR.
        ModemTimeout: no result in time (the call is aborted first).
        ValueError: ``number`` has characters a modem does not dial.
    """
    if not _DIAL_CHARS.fullmatch(number):
        raise ValueError(f"cannot dial {number!r}: use digits and , W * # only")
    resp = _Responses(port)
    await _command(port, resp, "ATZ", command_timeout)
    if init:
        await _command(port, resp, init, command_timeout)
    await port.send_all(f"ATD{'P' if pulse else 'T'}{number}\r".encode("ascii"))
    try:
        with trio.fail_after(timeout):
            while True:
                text = await resp.line()
                if (conn := _connected(text)) is not None:
                    await resp.end_of_line(command_timeout)
                    return conn
                if (err := _call_failure(text, number)) is not None:
                    raise err
                # Our echo ("ATDT...") and progress text: keep waiting.
    except (trio.TooSlowError, trio.Cancelled) as exc:
        # Any character aborts a call in progress on a Hayes modem; shielded
        # and bounded so that cancellation still ends promptly.
        with trio.CancelScope(shield=True), trio.move_on_after(command_timeout):
            await port.send_all(b"\r")
        if isinstance(exc, trio.TooSlowError):
            raise ModemTimeout(
                f"no CONNECT from {number} within {timeout} s: the call was aborted; "
                "try again or raise the timeout"
            ) from None
        raise


async def answer(
    port: trio.abc.Stream,
    *,
    rings: int = 1,
    auto_answer: bool = False,
    timeout: float | None = None,
    connect_timeout: float = 60.0,
    command_timeout: float = 5.0,
) -> ModemConnection:
    """Wait for a call and answer it; returns when the modem is in data mode.

    Resets the modem (``ATZ``).  With ``auto_answer`` it sets ``S0=<rings>``
    and lets the modem pick up by itself; otherwise it counts ``rings`` RING
    messages and sends ``ATA``.

    Args:
        rings: rings before answering (>= 1).
        timeout: seconds to wait for the call to ring; None waits until
            cancelled (a server waiting for its controller to call).
        connect_timeout: seconds from answering to CONNECT.

    Raises:
        NoCarrier: the caller hung up or the carrier handshake failed.
        ModemTimeout: no call within ``timeout``, or no CONNECT in time.
        ModemError: the modem answered ERROR.
    """
    if rings < 1:
        raise ValueError("rings must be >= 1")
    resp = _Responses(port)
    await _command(port, resp, "ATZ", command_timeout)
    if auto_answer:
        await _command(port, resp, f"ATS0={min(rings, 255)}", command_timeout)
    seen = 0
    with trio.move_on_after(timeout if timeout is not None else float("inf")) as ringing:
        while True:
            text = await resp.line()
            if text == "RING":
                seen += 1
                if not auto_answer and seen >= rings:
                    break
            elif (conn := _connected(text)) is not None:
                await resp.end_of_line(command_timeout)
                return conn  # auto-answered
            elif text == "NO CARRIER":
                seen = 0  # the caller gave up; wait for the next call
    if ringing.cancelled_caught:
        raise ModemTimeout(f"no call within {timeout} s")
    await port.send_all(b"ATA\r")
    with trio.move_on_after(connect_timeout) as connecting:
        while True:
            text = await resp.line()
            if (conn := _connected(text)) is not None:
                await resp.end_of_line(command_timeout)
                return conn
            if text == "NO CARRIER":
                raise NoCarrier(
                    "no carrier after answering: the caller hung up or the modems could "
                    "not agree on a carrier",
                    text,
                )
            if text == "ERROR":
                raise ModemError("the modem rejected ATA (the call was gone)", text)
    assert connecting.cancelled_caught
    with trio.CancelScope(shield=True), trio.move_on_after(command_timeout):
        await port.send_all(b"\r")  # abort the handshake
    raise ModemTimeout(f"no CONNECT within {connect_timeout} s after answering")


async def hangup(
    port: trio.abc.Stream, *, guard_time: float = 1.0, command_timeout: float = 5.0
) -> None:
    """Escape to command mode (silence, ``+++``, silence) and hang up (``ATH``).

    ``guard_time`` must be at least the modem's S12 guard time (S12 = 50
    fiftieths: 1 s by default); each guard here is 20 % longer for margin.
    Nothing else may write to the port meanwhile (close the serial socket
    first).  If the carrier was already lost, the modem is in command mode
    and says nothing to ``+++``: that costs one full wait (1.2 x guard time +
    ``command_timeout``) before ATH is sent and acknowledged.

    Raises:
        ModemTimeout: the modem did not acknowledge the escape and ATH.
    """
    resp = _Responses(port)
    await trio.sleep(guard_time * 1.2)
    await port.send_all(b"+++")
    # The modem says OK one guard time after the escape; data arriving from the
    # far end before then is still passed through, so skip unknown lines.
    with trio.move_on_after(guard_time * 1.2 + command_timeout):
        while await resp.line() not in ("OK", "NO CARRIER"):
            pass
    # CR first: if the modem was already in command mode, it ends the line
    # holding "+++" (not a command: ignored) so that ATH is read by itself.
    await port.send_all(b"\r")
    try:
        await _command(port, resp, "ATH", command_timeout)
    except ModemTimeout:
        raise ModemTimeout(
            "the modem did not acknowledge +++ and ATH: it may still be in data mode; "
            "check the guard time (S12) and the escape character (S2), or drop DTR"
        ) from None
