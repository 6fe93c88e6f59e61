"""atheris harness: the ARQ endpoint's receive path (serialsocket.Endpoint).

Two endpoints connect honestly (A connects, B listens and accepts); then the
fuzz input is read as a script of operations on B: well-formed packets of any
type, sequence number and data (valid block check, so they reach the ARQ
logic rather than dying in the parser), raw line bytes, time steps that fire
due timers, application reads and writes on both sides, and honest exchanges
of what each side queued.

Each side's configuration comes first: a flag byte (bit 1: long sequence
numbers; 0x02: offer corrected data packets; 0x08: take no first flight;
0x10: send one, with bytes from the
input queued before connecting; 0x20: offer the dense encodings; 0x40: the
line uses XON/XOFF; 0x80: ask for CRC-32 -- PROTOCOL.md sections 9, 10, 14
and 15), the window unless
long, a 16-bit packet length (0xF000 and above: measured, PROTOCOL.md 4.7)
and the line (even: printable, odd: 8-bit).  Two dense sides agree on the
escape code (8-bit; with XON/XOFF escaped if either declares it) or the
radix-91 packing (printable), and on CRC-32 if either asks.  Op 9 hands a
fresh listener a request whose data field is the input's (what decodes is
answered, the rest refused: never an exception).  Forged packets
are then built with the agreed check, and op 1 encodes a ``D`` packet's data
with the agreed encoding (after the two high sequence characters, from the
input, when long sequence numbers are agreed); with corrected data packets
agreed it may send that ``D`` as a ``d`` packet (sums behind its data) with
one character replaced by the input's, which the receiver repairs or
rejects, or send it damaged the same way and then the repair packet for it
(``r``, PROTOCOL.md 15.6), which the receiver mends it by or answers; op 0
forges ``r`` packets of any content too.  Properties (any violation raises):

* ``receive_data``, ``handle_timer``, ``data_to_send``, ``read`` and
  ``statistics`` never raise, whatever arrives: a bad packet is counted;
* the application calls raise only ``LocalProtocolError`` (a local misuse,
  such as sending after ``send_eof``);
* the receive buffer never holds more than its limit (``receive_buffer``, grown
  with the bandwidth-delay product up to ``buffer_cap``);
* no timer stays due after it was handled and the output flushed (an event
  loop driving the endpoint would spin).
"""

from __future__ import annotations

import contextlib
import sys

from fuzz._instrument import instrumented
from fuzz._reader import Reader

with instrumented(__name__ == "__main__"):
    from serialsocket import (
        ConnectionRequested,
        Endpoint,
        EndpointConfig,
        LocalProtocolError,
        State,
    )
    from serialsocket.packets import (
        EIGHT_BIT_CLEAN,
        PRINTABLE,
        BlockCheck,
        Packet,
        build_corrected,
        build_packet,
        repair_field,
    )

_TYPES = "DYNZEISBFXARr?"
_TIMER_SPIN_LIMIT = 64
"""Consecutive timer firings at one instant before it counts as a spin."""


_CORRECTION = 0x02
_NO_FLIGHT = 0x08
_FLIGHT = 0x10
_DENSE = 0x20
_XON_XOFF = 0x40
_CRC32 = 0x80
_MEASURED = 0xF000
"""Packet lengths from here on mean "measured" (``max_packet_length=None``)."""


def _config(r: Reader) -> EndpointConfig:
    # Half the inputs hint a line 31 packets cannot fill: long sequence
    # numbers (PROTOCOL.md section 9) are negotiated and their heads parsed.
    flags = r.byte()
    long = flags % 2 == 1
    window = 31 if long else 1 + r.byte() % 31
    length = r.u16()
    return EndpointConfig(
        window=window,
        max_packet_length=None if length >= _MEASURED else 40 + length % 1500,
        encoding=(PRINTABLE, EIGHT_BIT_CLEAN)[r.byte() % 2],
        dense=bool(flags & _DENSE),
        xon_xoff=bool(flags & _XON_XOFF),
        check=BlockCheck.CRC32 if flags & _CRC32 else BlockCheck.CRC16,
        first_flight=bool(flags & _FLIGHT),
        correction=bool(flags & _CORRECTION),
        takes_first_flight=not flags & _NO_FLIGHT,
        one_way_delay=60.0 if long else 1.0,
        line_rate=9600.0 if long else None,
        receive_buffer=2 * 9031,
        send_buffer=8192,
    )


def _fire(ep: Endpoint, now: float) -> bytes:
    """Handle every due timer at ``now``; return what went out.  Raise on a spin."""
    out = ep.data_to_send(now)
    for _ in range(_TIMER_SPIN_LIMIT):
        timers = [t for t in (ep.get_timer(), ep.get_send_timer()) if t is not None]
        if not timers or min(timers) > now:
            return out
        ep.handle_timer(now)
        out += ep.data_to_send(now)
    raise AssertionError(f"timer spin at t={now} in state {ep.state}")


def _connect(a: Endpoint, b: Endpoint) -> float:
    now = 0.0
    b.listen()
    a.connect(now)
    for _ in range(8):
        b.receive_data(a.data_to_send(now), now)
        for ev in b.events():
            if isinstance(ev, ConnectionRequested):
                b.accept(now)
        a.receive_data(b.data_to_send(now), now)
        a.events()
        if a.state is State.ESTABLISHED and b.state is State.ESTABLISHED:
            break
        now += 1.0
    return now


def one_input(data: bytes) -> None:
    r = Reader(data)
    a = Endpoint(_config(r))
    b = Endpoint(_config(r))
    if a.config.first_flight:
        a.send(r.take(r.u16() % 4096), 0.0)  # more than the init carries: a flight
    now = _connect(a, b)
    agreed = b.parameters
    check = agreed.check if agreed is not None else BlockCheck.CRC16
    long_seq = agreed is not None and agreed.long_seq
    while r.remaining:
        op = r.byte() % 10
        if op in (0, 1):  # a well-formed packet of any type, seq and (encoded or not) data
            ptype = _TYPES[r.byte() % len(_TYPES)]
            seq = r.byte() % 64
            payload = r.take(r.byte()).replace(b"\x01", b"#")  # SOH never inside a packet
            if op == 1 and ptype == "D" and agreed is not None:
                payload = agreed.encoding.encode(payload)
                if long_seq:  # the two high sequence characters (PROTOCOL.md 9)
                    payload = bytes((32 + r.byte() % 64, 32 + r.byte() % 64)) + payload
            wire_check = check if r.byte() % 8 else BlockCheck.SUM6
            wire = build_packet(Packet(seq=seq, type=ptype, data=payload), wire_check)
            if op == 1 and ptype == "D" and agreed is not None and agreed.correction:
                how = r.u16()
                if how & 1:  # as a d packet, one character of it the input's
                    damaged = bytearray(build_corrected(seq, payload, check))
                    damaged[1 + (how >> 1) % (len(damaged) - 2)] = r.byte() or 2
                    wire = bytes(damaged)
                elif how & 2:  # damaged, then the repair packet for it (PROTOCOL.md 15.6)
                    damaged = bytearray(wire)
                    damaged[1 + (how >> 2) % (len(damaged) - 2)] = r.byte() or 2
                    b.receive_data(bytes(damaged), now)
                    field = repair_field(wire[:-1], int(check))
                    head = payload[:2] if long_seq else b""
                    wire = build_packet(Packet(seq=seq, type="r", data=head + field), check)
            b.receive_data(wire, now)
        elif op == 2:  # raw bytes on the line
            b.receive_data(r.take(r.byte()), now)
        elif op == 3:  # time passes; timers fire on both sides
            now += r.byte() * 0.25
            _fire(a, now)
            _fire(b, now)
        elif op == 4:
            got = b.read(r.byte() or None, now)
            if b.readable > b.statistics().receive_buffer:
                raise AssertionError(f"{b.readable} bytes buffered")
            del got
        elif op in (5, 6):
            ep = b if op == 5 else a
            # Sending after EOF or once the connection ended is a local misuse.
            with contextlib.suppress(LocalProtocolError):
                ep.send(r.take(r.byte()), now)
        elif op == 7:  # an honest exchange
            b.receive_data(_fire(a, now), now)
            a.receive_data(_fire(b, now), now)
        elif op == 9:  # any request to a fresh listener (XEARLY, XFLIGHT, ...)
            c = Endpoint(b.config)
            c.listen()
            field = r.take(r.byte() + r.byte()).replace(b"\x01", b"#")
            c.receive_data(build_packet(Packet(seq=0, type="I", data=field), BlockCheck.CRC16), now)
            c.events()
            _fire(c, now)
        else:
            verb = r.byte() % 4
            try:
                if verb == 0:
                    b.send_eof(now)
                elif verb == 1:
                    b.close(now)
                elif verb == 2:
                    a.send_eof(now)
                else:
                    a.abort("fuzz", now)
            except LocalProtocolError:
                pass
        b.events()
        a.events()
        b.statistics()
        _fire(b, now)
        if b.readable > b.statistics().receive_buffer:
            raise AssertionError(f"{b.readable} bytes buffered")


if __name__ == "__main__":
    from fuzz._atheris import run

    run(one_input)
    sys.exit(0)
