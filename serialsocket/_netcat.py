"""``python -m serialsocket listen|connect PORT``: a netcat over the serial socket.

stdin goes to the link and the link to stdout, byte for byte.  At EOF on
stdin the socket half-closes (the peer reads EOF once every byte arrived);
the program exits when both directions are done, after a graceful close.
``listen`` waits for one connection (after answering a modem call with
``--answer``); ``connect`` dials first with ``--dial NUMBER``.

stdin and stdout are read and written in worker threads, not through
``FdStream``: that would put the caller's terminal or shared pipe into
non-blocking mode (see trio's FdStream warning), and a slow stdout must not
stall the event loop that answers the peer's packets.

``--capture FILE`` writes what crosses the port, both ways and timestamped,
to a pcapng file (:mod:`serialsocket.capture`; from the connection on, not
the modem dialogue).

``--stats`` / ``--json`` print the counters at the end on stderr (stdout
carries the peer's data), however the run ended; a progress line is kept on
stderr while it is a terminal (``--quiet``: none).

Exit status: 0 means exactly that every byte read from stdin was
acknowledged by the peer and every byte the peer sent was written to stdout
(its EOF seen).  Any other ending is 1 (the link, the close or the modem
failed: stderr says what happened, and how many bytes were acknowledged, in
flight and never sent each way), 2 for bad options, 130 for Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from dataclasses import dataclass

import trio

from ._capture import CaptureFile, CapturingStream
from ._config import (
    ADAPTIVE_RECEIVE_LENGTH,
    DEFAULT_MAX_PACKET_TIME,
    MAX_WINDOW,
    EndpointConfig,
)
from ._driver import LinkBroken
from ._encoding import EIGHT_BIT_CLEAN, PRINTABLE, Encoding
from ._errors import LocalProtocolError
from ._hayes import DialError, ModemConnection, answer, dial
from ._port import open_port
from ._socket import SerialSocket, accept, connect
from ._trace import TracingStream
from ._wire import DEFAULT_MAX_PACKET_LENGTH
from .interrupt import run_interruptibly

__all__ = ["add_arguments", "netcat_main"]

_CHUNK = 65536
"""Bytes per stdin read: one read can fill many packets."""

_DEFAULT_BAUD = 9600

_PROFILES: dict[str, Encoding | None] = {
    "auto": None,
    "8bit": EIGHT_BIT_CLEAN,
    "printable": PRINTABLE,
}
"""``--profile``: None leaves the choice to the port (``SerialPort.encoding``)."""


def add_arguments(ap: argparse.ArgumentParser, *, listening: bool) -> None:
    """Options of ``listen`` and ``connect``."""
    ap.add_argument("port", metavar="PORT", help="device path, pty or pyserial URL (loop://...)")
    ap.add_argument(
        "--baud",
        type=int,
        help=f"port speed in bit/s (default {_DEFAULT_BAUD}); when given, the protocol also "
        "paces to it (after dialing, the modem's CONNECT rate is used instead)",
    )
    if listening:
        ap.add_argument(
            "--answer", action="store_true", help="wait for a modem call (RING) and answer it"
        )
    else:
        ap.add_argument("--dial", metavar="NUMBER", help="dial NUMBER through a Hayes modem first")
        ap.add_argument(
            "--connect-timeout",
            type=float,
            help="give up connecting after this many seconds (default: derived from the line)",
        )
    ap.add_argument(
        "--window",
        type=int,
        default=MAX_WINDOW,
        help=f"window, 1..{MAX_WINDOW} (default {MAX_WINDOW}; capped by the line's round trip)",
    )
    ap.add_argument(
        "--max-len",
        type=int,
        default=None,
        help="fixed packet length, MARK..CHECK (default: measured; packets start at "
        f"{DEFAULT_MAX_PACKET_LENGTH} and follow the byte error rate the losses show, up to "
        f"{ADAPTIVE_RECEIVE_LENGTH} on a clean line)",
    )
    ap.add_argument(
        "--max-packet-time",
        type=float,
        default=None,
        metavar="SECONDS",
        help="with the length measured, the most line time one data packet may take (default: "
        "no cap, as suits a byte stream; a command channel's library default is "
        f"{DEFAULT_MAX_PACKET_TIME:g} s, what an urgent message may wait behind)",
    )
    ap.add_argument(
        "--delay",
        type=float,
        default=0.0,
        help="one-way delay of the line in seconds (a hint for the timers; 1.3 for the Moon)",
    )
    ap.add_argument(
        "--profile",
        choices=sorted(_PROFILES),
        default="auto",
        help="what the line carries: 8bit (8N1, 8-bit clean), printable (7 bits, parity, a "
        "terminal server in between), or auto (default: from the port's format, 8N1 here, "
        "so 8bit); between two telelink ends a dense encoding of it is negotiated",
    )
    ap.add_argument(
        "--no-dense",
        dest="dense",
        action="store_false",
        help="offer no dense encoding: classic Kermit prefixing, whose run-length "
        "compression wins on data with long runs of one byte (the dense codes have none)",
    )
    ap.add_argument("--dead-after", type=float, help="declare the link dead after this silence")
    ap.add_argument("--trace", action="store_true", help="log every packet, decoded, to stderr")
    ap.add_argument(
        "--capture",
        metavar="FILE",
        help="write the port's traffic, both ways with timestamps, to FILE.pcapng "
        "(for Wireshark with contrib/wireshark/telelink.lua)",
    )
    report = ap.add_argument_group(
        "reports (on stderr: stdout carries the peer's data)",
    )
    report.add_argument(
        "--stats", action="store_true", help="at the end, the counters in words, however it ended"
    )
    report.add_argument(
        "--json", action="store_true", help="at the end, the counters as one JSON object"
    )
    report.add_argument(
        "--quiet",
        action="store_true",
        help="no progress line (shown only when stderr is a terminal)",
    )


async def _read_stdin() -> bytes:
    # abandon_on_cancel: a read blocked on an idle terminal must not hold up
    # exit; whatever it returns afterwards is not wanted any more.
    return await trio.to_thread.run_sync(os.read, 0, _CHUNK, abandon_on_cancel=True)


def _write_all(data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(1, view) :]


@dataclass
class _Tally:
    """What this run moved, for the final report (whatever ended it)."""

    sock: SerialSocket | None = None
    capture: CaptureFile | None = None
    """The ``--capture`` file, closed by :func:`netcat_main` however the run ended."""
    stdin_bytes: int = 0
    stdout_bytes: int = 0
    peer_eof: bool = False
    connected_at: float | None = None
    """trio time of the connection (the rates count from it)."""
    ended_at: float | None = None

    def record(self, outcome: str) -> dict[str, object]:
        """The counters for ``--stats`` / ``--json``: payload each way, the line, repairs."""
        record: dict[str, object] = {"outcome": outcome}
        if (
            self.sock is None
            or self.connected_at is None
            or self.sock.endpoint.parameters is None  # a deferred request unanswered
        ):
            return record | {"connected": False}
        sock = self.sock.statistics()
        st = sock.link
        # (Outside trio -- the report at exit -- the end is always set.)
        end = self.ended_at if self.ended_at is not None else trio.current_time()
        seconds = max(end - self.connected_at, 1e-9)
        record |= {
            "connected": True,
            "seconds": round(seconds, 3),
            "stdin_bytes_read": self.stdin_bytes,
            "bytes_acknowledged": st.bytes_acknowledged,
            "bytes_in_flight": st.bytes_in_flight,
            "stdout_bytes_written": self.stdout_bytes,
            "peer_eof": self.peer_eof,
            "payload_sent_Bps": round(st.bytes_acknowledged / seconds, 1),
            "payload_received_Bps": round(self.stdout_bytes / seconds, 1),
            "wire_bytes_sent": st.wire_bytes_sent,
            "wire_bytes_received": st.wire_bytes_received,
            "packets_sent": st.packets_sent,
            "packets_received": st.packets_received,
            "retransmissions": st.retransmissions,
            "timeouts": st.timeouts,
            "fast_retransmits": st.fast_retransmits,
            "idle_copies": st.idle_copies,
            "doubled_resends": st.doubled_resends,
            # The first flight (PROTOCOL.md 14): packets sent before the
            # answer, and of those the listener did not take.
            "flight_packets": st.flight_packets,
            "flight_refused": st.flight_refused,
            "naks_sent": st.naks_sent,
            "check_failures": st.check_failures,
            # Corrected data packets (PROTOCOL.md 15): ours sent with sums,
            # and the peer's that failed their check and the sums repaired;
            # repair packets (15.6) we sent, and the peer's that mended nothing.
            "corrected_sent": st.corrected_sent,
            "repaired": st.repaired,
            "repairs_sent": st.repairs_sent,
            "repairs_failed": st.repairs_failed,
            "duplicate_acks_held": st.duplicate_acks_held,
            "garbage_bytes": st.garbage_bytes,
            "smoothed_rtt_s": None if st.smoothed_rtt is None else round(st.smoothed_rtt, 3),
            "window": st.effective_window,
        }
        return record

    def progress(self) -> str:
        """One progress line: bytes each way and the rates so far."""
        if self.sock is None or self.connected_at is None:
            return "connecting..."
        st = self.sock.statistics().link
        seconds = max(trio.current_time() - self.connected_at, 1e-9)
        return (
            f"{seconds:7.1f} s  sent {st.bytes_acknowledged} B acknowledged "
            f"({st.bytes_acknowledged / seconds:.0f} B/s), {st.bytes_in_flight} in flight  "
            f"received {self.stdout_bytes} B ({self.stdout_bytes / seconds:.0f} B/s)  "
            f"retransmissions {st.retransmissions}"
        )

    def report(self) -> str:
        """How far each direction got, in bytes."""
        if self.sock is None:
            return "not connected: nothing was sent or received"
        st = self.sock.statistics().link
        acked, in_flight = st.bytes_acknowledged, st.bytes_in_flight
        # Bytes read from stdin but never handed to the socket count as never sent.
        unsent = max(self.stdin_bytes - acked - in_flight, 0)
        eof = "seen" if self.peer_eof else "not seen"
        return (
            f"stdin: {self.stdin_bytes} bytes read, {acked} acknowledged by the peer, "
            f"{in_flight} in flight (may or may not have arrived), {unsent} never sent; "
            f"stdout: {self.stdout_bytes} bytes written, the peer's EOF {eof}"
        )


async def _pump(sock: SerialSocket, tally: _Tally) -> None:
    async def upstream() -> None:
        while data := await _read_stdin():
            tally.stdin_bytes += len(data)
            await sock.send_all(data)
        await sock.send_eof()

    async def downstream() -> None:
        while data := await sock.receive_some(_CHUNK):
            await trio.to_thread.run_sync(_write_all, data)
            tally.stdout_bytes += len(data)
        tally.peer_eof = True

    async with trio.open_nursery() as nursery:
        nursery.start_soon(upstream)
        nursery.start_soon(downstream)


def _config(args: argparse.Namespace, modem: ModemConnection | None) -> EndpointConfig:
    rate: float | None = None
    if modem is not None and modem.rate is not None:
        rate = modem.rate  # the modems' rate on the phone line, not the DTE's
    elif args.baud is not None:
        rate = args.baud
    return EndpointConfig(
        encoding=_PROFILES[args.profile],
        dense=args.dense,  # a byte stream of any content: dense unless told otherwise
        first_flight=True,  # stdin's first bytes leave behind the request (PROTOCOL.md 14)
        correction=True,  # sums repair single damaged characters (PROTOCOL.md 15)
        window=args.window,
        max_packet_length=args.max_len,
        max_packet_time=args.max_packet_time,
        one_way_delay=args.delay,
        line_rate=rate,
        dead_after=args.dead_after,
        connect_timeout=getattr(args, "connect_timeout", None),
    )


async def _run(args: argparse.Namespace, listening: bool, tally: _Tally) -> None:
    _config(args, None)  # validate the options before touching the port
    if args.capture:
        tally.capture = CaptureFile(args.capture)
    port = await open_port(args.port, args.baud or _DEFAULT_BAUD)
    stream: trio.abc.Stream = port
    try:
        modem: ModemConnection | None = None
        if listening and args.answer:
            modem = await answer(port)
        elif not listening and args.dial:
            modem = await dial(port, args.dial)
        if modem is not None:
            print(f"serialsocket: {modem.result}", file=sys.stderr)
        cfg = _config(args, modem).for_line(port)  # --profile auto: the port's format
        if tally.capture is not None:
            name = "listen" if listening else "connect"
            interface = tally.capture.add_interface(args.port, description=f"serialsocket {name}")
            stream = CapturingStream(port, tally.capture, interface)
        if args.trace:
            stream = TracingStream(stream, cfg.encoding)
    except BaseException:
        await trio.aclose_forcefully(port)
        raise
    async with trio.open_nursery() as nursery:
        if listening:
            sock = await accept(stream, cfg, nursery=nursery)
        else:
            # Deferred: the request goes with stdin's first bytes queued, so
            # they leave right behind it as a first flight instead of after
            # the handshake's round trip (PROTOCOL.md 14); a failed request
            # surfaces at the next read or write, caused by what connect()
            # raises (reported as before: _netcat).
            sock = await connect(stream, cfg, nursery=nursery, defer=True)
        tally.sock = sock
        tally.connected_at = trio.current_time()
        if args.show_progress:
            nursery.start_soon(_show_progress, tally)
        try:
            await _pump(sock, tally)
        finally:
            try:
                await sock.aclose()
            finally:
                # Also when the close is interrupted (Ctrl-C): the report,
                # made after trio has returned, needs the end.
                tally.ended_at = trio.current_time()
                nursery.cancel_scope.cancel()  # the progress line, nothing else is left
        # Exit 0 means delivered: every byte of stdin acknowledged by the peer
        # and the peer's EOF received (so all it sent is on our stdout).  Our
        # own close ending is not that: the close says whether it was
        # (close_error), and anything short of it is a failure, however
        # quietly the close ended.
        if sock.close_error is not None:
            raise IncompleteClose(sock.close_error)


async def _show_progress(tally: _Tally) -> None:
    """Rewrite one line on stderr (a terminal) each second; erased at the end."""
    try:
        while True:
            sys.stderr.write("\r\x1b[K" + tally.progress())
            sys.stderr.flush()
            await trio.sleep(1.0)
    finally:
        sys.stderr.write("\r\x1b[K")
        sys.stderr.flush()


class IncompleteClose(Exception):
    """The transfer ran but did not end delivered both ways (see ``close_error``)."""


def _first_leaf(group: BaseExceptionGroup[BaseException]) -> BaseException:
    """The first real exception in a (nested) nursery exception group."""
    exc: BaseException = group
    while isinstance(exc, BaseExceptionGroup):
        exc = exc.exceptions[0]
    return exc


def netcat_main(args: argparse.Namespace, *, listening: bool) -> int:
    """Run ``listen`` or ``connect``; returns the exit status."""
    if args.trace:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(relativeCreated)9.1f ms %(message)s"))
        trace = logging.getLogger("serialsocket.trace")
        trace.addHandler(handler)
        trace.setLevel(logging.DEBUG)
        trace.propagate = False
    name = "listen" if listening else "connect"
    args.show_progress = not args.quiet and sys.stderr.isatty()
    tally = _Tally()
    status = _netcat(args, listening, name, tally)
    if tally.capture is not None:
        tally.capture.close()
    outcome = {0: "delivered", 2: "bad options", 130: "interrupted"}.get(status, "failed")
    if status != 2 and (args.stats or args.json):
        record = tally.record(outcome)
        if args.json:
            print(json.dumps(record), file=sys.stderr)
        if args.stats:
            words = ", ".join(f"{k} {v}" for k, v in record.items())
            print(f"serialsocket {name}: {words}", file=sys.stderr)
    return status


def _netcat(args: argparse.Namespace, listening: bool, name: str, tally: _Tally) -> int:
    """The run itself; returns the exit status (reports are the caller's)."""
    try:
        try:
            run_interruptibly(_run, args, listening, tally)
        except BaseExceptionGroup as group:
            raise _first_leaf(group) from None
    except LocalProtocolError as exc:
        print(f"serialsocket {name}: {exc}", file=sys.stderr)
        return 2
    except (DialError, OSError, ConnectionRefusedError) as exc:
        _fail(name, str(exc), tally)
        return 1
    except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
        cause = exc.__cause__
        sock = tally.sock
        if isinstance(cause, (TimeoutError, ConnectionRefusedError)) or (
            sock is not None and sock.endpoint.parameters is None
        ):
            # The deferred request failed: said as connect() says it.
            _fail(name, str(cause or exc), tally)
            return 1
        reason = cause if isinstance(cause, LinkBroken) else exc
        _fail(name, f"the link failed: {reason}", tally)
        return 1
    except IncompleteClose as exc:
        _fail(name, str(exc), tally)
        return 1
    except KeyboardInterrupt:
        _fail(name, "interrupted", tally)
        return 130
    return 0


def _fail(name: str, what: str, tally: _Tally) -> None:
    """What ended the run and, once connected, how far each direction got."""
    print(f"serialsocket {name}: {what}", file=sys.stderr)
    # (A deferred request never answered connected nothing: no report.)
    if tally.sock is not None and tally.sock.endpoint.parameters is not None:
        print(f"serialsocket {name}: {tally.report()}", file=sys.stderr)
