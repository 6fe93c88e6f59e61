"""Kermit file transfer: the Send-Init fields real Kermits exchange, and their negotiation.

The layout is the one in reference/kermit.md section 4 (and
:mod:`serialsocket._params`, whose decoder walks the CAPAS/WINDO/MAXLX part for
us).  :class:`~serialsocket.packets.InitParameters` cannot be reused for *encoding*:
it pins telelink's own SYSID and trailing fields and always offers long
packets and windows, while a file-transfer peer must see exactly what we
support (attributes, binary WHATAMI, long packets only when configured) and we
need the fields telelink's connection protocol ignores (TIME, NPAD, PADC, EOL).

Our S / ACK(S) data field::

    MAXL TIME NPAD PADC EOL QCTL QBIN CHKT REPT CAPAS WINDO MAXLX1 MAXLX2
    CHKPNT CHKINT(3) WHATAMI

WHATAMI carries 32 (valid) | 2 (binary mode) and never 8 (we never offer
streaming: any error while streaming is fatal by design, wrong for an impaired
serial line).  No SYSID is sent, so peers apply no system-specific conversions.
"""

from __future__ import annotations

from dataclasses import dataclass

from serialsocket._checks import BlockCheck
from serialsocket._encoding import Encoding
from serialsocket._errors import LocalProtocolError, RemoteProtocolError
from serialsocket._params import InitParameters
from serialsocket._wire import (
    MAX_NORMAL_LEN,
    MAX_PACKET_LENGTH,
    MIN_PACKET_LENGTH,
    ctl,
    tochar,
    unchar,
)

__all__ = ["KermitConfig", "KermitInit", "KermitNegotiated", "negotiate_kermit"]

_CAP_LONG, _CAP_WINDOWS, _CAP_ATTRIBUTES, _CAP_RESEND = 2, 4, 8, 16
_WHATAMI_VALID, _WHATAMI_STREAM, _WHATAMI_BINARY = 32, 8, 2
_ASSUMED_RATE = 9600
"""bit/s the timers assume when the line rate is not given (the port's default rate)."""
_BITS_PER_CHAR = 10
"""Start bit, 8 data bits, stop bit."""
_ACK_CHARS = 12
"""A long ACK with a CRC and EOL, padding aside: the reverse traffic per D packet."""
TIMER_MARGIN = 1.0
"""Seconds added to every line-derived timeout: process start-up, scheduling, a pty's buffering."""
MIN_TIMEOUT = 2.0
"""The shortest timeout ever used, s (C-Kermit's dynamic timers stop at 1 s; a pty relay
in a busy process needs a little more)."""
INIT_TIMEOUT = 5.0
"""The shortest wait for the answer to S (or for S): the other side may still be starting."""
_NORMAL_PACKET = MAX_NORMAL_LEN + 2
"""96: the longest normal packet, MARK through CHECK (LEN = 94)."""
_ADVERTISED_MAXL = MAX_NORMAL_LEN - 5
"""89: the largest MAXL we advertise.  C-Kermit 10.0 Beta.08 (Debian's ckermit
402~beta08) sends normal packets up to 5 characters longer than the MAXL it was
given (measured here: MAXL 80 -> LEN 85, 88 -> 93, 91 -> 96; davidrg/ckwin
#558), and past 94 it still builds them as *normal* packets with LEN 95+,
which no Kermit can read (ckwin #559).  Asking for at most 89 keeps its packets
legal; our parser accepts the extra characters (see _PARSER_SLACK)."""
MAX_KERMIT_WINDOW = 31
"""The window field is one tochar; 31 is the protocol's limit (E-Kermit P_WSLOTS, ckcker.h)."""
TIMER_WINDOW = 8
"""Packets the timers assume may be queued ahead of a resent one before anything is
measured.  The window offered is larger (31: a paced sender only fills it to cover
repairs, see _sender.py), but a peer that does not pace rarely queues more than
this, and a whole window of long packets at 2400 bit/s would make the first
timeout minutes long."""


def line_time(chars: int, rate: int | None) -> float:
    """Seconds ``chars`` characters take on the line (``rate`` bit/s, None: assumed 9600)."""
    return chars * _BITS_PER_CHAR / (rate or _ASSUMED_RATE)


def line_timeout(delay: float, rate: int | None, window: int, length: int) -> float:
    """The timeout a line of this delay and rate needs, before anything is measured.

    A resent packet may queue behind a window of packets already handed to
    the port, and its ACK comes back through the delay: one round trip plus
    the line time of ``window`` (at most :data:`TIMER_WINDOW`) packets of
    ``length`` characters and their ACKs, plus :data:`TIMER_MARGIN`; never
    below :data:`MIN_TIMEOUT`.
    """
    busy = line_time(min(window, TIMER_WINDOW) * (length + _ACK_CHARS), rate)
    return max(MIN_TIMEOUT, 2 * delay + busy + TIMER_MARGIN)


@dataclass(frozen=True, slots=True, kw_only=True)
class KermitConfig:
    """Local settings of a Kermit file transfer.

    Attributes:
        max_packet_length: longest packet we receive and send, MARK through
            CHECK (the package's length convention).  96 or less means normal
            packets only; more offers long packets (MAXLX = length - 7).
        window: sliding-window slots we offer, 1..31 (default 31, the most
            Kermit allows; C-Kermit offers 30).  A sender that knows the
            line rate paces its packets at that rate, so a large window only
            lets it keep sending while a damaged packet is repaired (see
            :class:`~serialsocket.kermit.KermitSender`); it does not queue a
            window of packets at the port.
        check: block check we ask for after the Send-Init exchange (type 1, 2
            or 3; both sides must ask for the same, else type 1 is used).
        timeout: fixed local timeout in seconds, or None for timers derived
            from the line (``delay``, ``rate``) and then from measured round
            trips (see :func:`line_timeout`).
        delay: one-way delay of the line, s (a hint for the timers and for
            the packet length; never a truth the transfer breaks on).
        rate: line rate in bit/s, or None (timers assume 9600).
        dynamic_length: the sender chooses the length of its D packets from
            the line and the errors it measures, up to ``max_packet_length``;
            False: always the longest the receiver accepts.
        retry_limit: retransmissions of one packet before giving up with an E
            packet; 0 means no limit.  Raised to window + 1 when smaller, as
            C-Kermit and E-Kermit do.
        seven_bit: the line carries 7 bits only: ask for 8th-bit prefixing.
        repeat: offer repeat-count compression (``~``).
        attributes: offer attribute (A) packets (size, type, date, disposition).
        streaming: the transport below is reliable (a serial socket, TCP):
            offer streaming (WHATAMI bit 8, C-Kermit's SET STREAMING ON /
            SET RELIABLE ON).  Used only when the peer offers it too; then D
            packets are not acknowledged and any transmission error ends the
            transfer, as in C-Kermit.  Never on a raw, impaired line.  None
            (the default): :func:`kermit_send` / :func:`kermit_receive` decide
            from the port -- on for a :class:`serialsocket.SerialSocket`,
            off otherwise (C-Kermit's SET RELIABLE AUTO); the machines take
            None as off.
        force3: FORCE-3 (C-Kermit's SET BLOCK-CHECK 5): CHKT ``5`` and a
            CRC-16 on every packet, S and its ACK included.  A receiver
            answers a FORCE-3 S this way whatever this says.
        recovery: offer the RESEND capability (CAPAS 16); a receiver then
            answers a RESEND with the bytes it already holds.
        resend: the sender asks, for each file, how much the receiver holds
            and sends only the rest (C-Kermit's RESEND; binary files only;
            needs ``recovery`` on both sides).
        text: the sender sends files as text: LF line ends become CRLF on the
            wire and the A packet says ``AMJ``.  A receiver always follows
            the type the A packet announces.
        literal_names: send file names as they are and store them as they
            come; otherwise names go out in common form (upper case, one dot)
            and names that arrive in upper case are stored in lower case, as
            C-Kermit and G-Kermit do by default.
    """

    max_packet_length: int = 1000
    window: int = MAX_KERMIT_WINDOW
    check: BlockCheck = BlockCheck.CRC16
    timeout: float | None = None
    retry_limit: int = 10
    seven_bit: bool = False
    repeat: bool = True
    attributes: bool = True
    delay: float = 0.0
    rate: int | None = None
    dynamic_length: bool = True
    force3: bool = False
    streaming: bool | None = None
    recovery: bool = True
    resend: bool = False
    text: bool = False
    literal_names: bool = False

    def __post_init__(self) -> None:
        if not MIN_PACKET_LENGTH <= self.max_packet_length <= MAX_PACKET_LENGTH:
            raise LocalProtocolError(
                f"packet length {self.max_packet_length} is outside "
                f"{MIN_PACKET_LENGTH}..{MAX_PACKET_LENGTH}: choose e.g. 96 or 1000"
            )
        if not 1 <= self.window <= MAX_KERMIT_WINDOW:
            raise LocalProtocolError(f"window {self.window} is outside 1..{MAX_KERMIT_WINDOW}")
        if self.timeout is not None and not 0 < self.timeout < 86400:
            raise LocalProtocolError(f"timeout {self.timeout} s must be > 0 and below a day")
        if self.retry_limit < 0:
            raise LocalProtocolError("retry limit must be >= 0 (0 = no limit)")
        if not 0 <= self.delay < 86400:
            raise LocalProtocolError(f"delay {self.delay} s must be >= 0 and below a day")
        if self.rate is not None and self.rate <= 0:
            raise LocalProtocolError(f"line rate {self.rate} bit/s must be > 0")

    def initial_timeout(self) -> float:
        """The timeout before anything is measured (``timeout`` when fixed)."""
        if self.timeout is not None:
            return self.timeout
        return line_timeout(self.delay, self.rate, self.window, self.max_packet_length)


@dataclass(frozen=True, slots=True, kw_only=True)
class KermitInit:
    """One side's Send-Init fields, decoded.

    Attributes:
        max_packet_length: longest packet this side receives, MARK through CHECK.
        timeout: seconds the other side should wait for this side's packets (TIME).
        npad, padc: padding this side needs before each packet.
        eol: the byte this side wants after each packet.
        qctl: the control prefix this side sends.
        qbin: ``Y``, ``N`` or the 8th-bit prefix this side wants.
        check: block check this side asks for (1, 2 or 3).
        rept: repeat prefix proposed, or None.
        long_packets, windows, attributes, recovery: CAPAS bits.
        window: window slots offered (1 without the windows capability).
    """

    max_packet_length: int
    timeout: float
    npad: int
    padc: int
    eol: int
    qctl: int
    qbin: int
    check: BlockCheck
    rept: int | None
    long_packets: bool
    windows: bool
    attributes: bool
    window: int
    recovery: bool = False
    force3: bool = False
    streaming: bool = False

    @classmethod
    def mine(cls, config: KermitConfig) -> KermitInit:
        """What a side with this configuration offers."""
        long_packets = config.max_packet_length > _NORMAL_PACKET
        return cls(
            max_packet_length=config.max_packet_length,
            timeout=config.initial_timeout(),
            npad=0,
            padc=0,
            eol=0x0D,
            qctl=ord("#"),
            qbin=ord("&") if config.seven_bit else ord("Y"),
            check=config.check,
            rept=ord("~") if config.repeat else None,
            long_packets=long_packets,
            windows=config.window > 1,
            attributes=config.attributes,
            window=config.window,
            recovery=config.recovery and config.attributes,
            force3=config.force3,
            streaming=bool(config.streaming),
        )

    def encode(self) -> bytes:
        """The S / ACK(S) data field: printable, sent without prefix encoding."""
        caps = (
            (_CAP_LONG if self.long_packets else 0)
            | (_CAP_WINDOWS if self.windows else 0)
            | (_CAP_ATTRIBUTES if self.attributes else 0)
            | (_CAP_RESEND if self.recovery else 0)
        )
        n = min(self.max_packet_length - 7, 94 * 95 + 94)
        return bytes(
            [
                tochar(min(_ADVERTISED_MAXL, self.max_packet_length - 2)),
                tochar(min(94, max(1, round(self.timeout)))),
                tochar(self.npad),
                ctl(self.padc),
                tochar(self.eol),
                self.qctl,
                self.qbin,
                ord("5") if self.force3 else ord(str(int(self.check))),
                self.rept if self.rept is not None else 32,
                tochar(caps),
                tochar(self.window),
                tochar(n // 95),
                tochar(n % 95),
                ord("0"),
                *b"___",
                tochar(
                    _WHATAMI_VALID | _WHATAMI_BINARY | (_WHATAMI_STREAM if self.streaming else 0)
                ),
            ]
        )

    @classmethod
    def decode(cls, data: bytes) -> KermitInit:
        """Parse a peer's S or ACK(S) field; missing trailing fields take Kermit defaults.

        Raises:
            RemoteProtocolError: a field is out of range (``error_hint`` is the
                E-packet text).
        """
        common = InitParameters.decode(data)  # MAXL, QCTL, QBIN, CHKT, REPT, CAPAS..MAXLX

        def at(i: int, default: int) -> int:
            return data[i] if i < len(data) else default

        caps = unchar(at(9, 32))
        eol = unchar(at(4, tochar(13)))
        if not 1 <= eol <= 31:
            eol = 13  # C-Kermit accepts 1..31, otherwise CR (ckcfns.c spar).
        npad = unchar(at(2, 32))
        if not 0 <= npad <= 94:
            raise RemoteProtocolError(
                f"Send-Init: bad NPAD in {data!r}", error_hint="Bad init field: NPAD"
            )
        qctl = common.qctl
        if not (33 <= qctl <= 62 or 96 <= qctl <= 126):
            raise RemoteProtocolError(
                f"Send-Init: bad QCTL in {data!r}", error_hint="Bad init field: QCTL"
            )
        long_packets = bool(caps & _CAP_LONG) and caps >= 0
        return cls(
            max_packet_length=common.max_packet_length,
            timeout=float(max(0, unchar(at(1, tochar(0))))),
            npad=npad,
            padc=ctl(at(3, ctl(0))),
            eol=eol,
            qctl=qctl,
            qbin=common.qbin,
            check=common.check,
            rept=common.rept,
            long_packets=long_packets,
            windows=caps >= 0 and bool(caps & _CAP_WINDOWS),
            attributes=caps >= 0 and bool(caps & _CAP_ATTRIBUTES),
            window=common.window,
            recovery=caps >= 0 and bool(caps & _CAP_RESEND),
            force3=common.force_check,
            streaming=bool(_whatami(data) & _WHATAMI_STREAM),
        )


def _whatami(data: bytes) -> int:
    """The WHATAMI bits of an init field (0 when absent or not marked valid)."""
    i = 9  # CAPAS, then as many more CAPAS bytes as have the continuation bit
    while i < len(data) and unchar(data[i]) & 1:
        i += 1
    at = i + 8  # WINDO, MAXLX1, MAXLX2, CHKPNT, CHKINT x 3, then WHATAMI
    if at >= len(data):
        return 0
    bits = unchar(data[at])
    return bits if bits & _WHATAMI_VALID else 0


@dataclass(frozen=True, slots=True, kw_only=True)
class KermitNegotiated:
    """The parameters both sides use after the Send-Init exchange.

    Attributes:
        send_max_length: longest packet we send (MARK through CHECK): the
            smaller of our configured length and what the peer accepts.
        window: the smaller window offer (1 unless both have the capability).
        check: block check on every packet after the exchange.
        send_encoding: prefixes we use (our QCTL, the agreed QBIN and REPT).
        receive_encoding: prefixes the peer uses (its QCTL).
        attributes: both sides do A packets.
        recovery: both sides do RESEND (CAPAS 16, with attributes).
        streaming: both sides offered streaming (WHATAMI bit 8): D packets
            are not acknowledged.
        timeout: our timeout before anything is measured, s: the fixed one,
            else the line's (:func:`line_timeout`; a receiver also waits at
            least the peer's TIME).
        peer_time: the peer's TIME field, s (0: none).
        retry_limit: retries per packet, 0 = unlimited.
        eol, padding: what to put after and before each packet we send.
    """

    send_max_length: int
    window: int
    check: BlockCheck
    send_encoding: Encoding
    receive_encoding: Encoding
    attributes: bool
    recovery: bool
    streaming: bool
    timeout: float
    peer_time: float
    retry_limit: int
    eol: int
    padding: bytes


def negotiate_kermit(
    config: KermitConfig, mine: KermitInit, theirs: KermitInit
) -> KermitNegotiated:
    """Combine the two Send-Init fields (both sides reach the same answer).

    Raises:
        RemoteProtocolError: we need 8th-bit prefixing (a 7-bit line) and the
            peer refuses it, or the peer's prefixes collide.
    """
    check = mine.check if mine.check == theirs.check else BlockCheck.SUM6
    if mine.force3 or theirs.force3:
        # FORCE-3 ('5') with '3' or '5': CRC-16 on everything (C-Kermit's bctf).
        crc = BlockCheck.CRC16
        check = crc if mine.check is crc and theirs.check is crc else BlockCheck.SUM6
    qbin: int | None = None
    for want, other in ((mine.qbin, theirs.qbin), (theirs.qbin, mine.qbin)):
        if want not in b"YN" and (other == ord("Y") or other == want):
            qbin = want
    if mine.qbin not in b"YN" and qbin is None:
        raise RemoteProtocolError(
            "the line is 7-bit but the peer refuses 8th-bit prefixing",
            error_hint="8th-bit prefixing refused: a 7-bit line cannot carry the data",
        )
    if qbin is not None and not (33 <= qbin <= 62 or 96 <= qbin <= 126):
        qbin = None  # an illegal QBIN char means "none" (ckcfns.c spar)
    rept = mine.rept if mine.rept is not None and mine.rept == theirs.rept else None
    try:
        send_encoding = Encoding(qctl=mine.qctl, qbin=qbin, rept=rept)
        receive_encoding = Encoding(qctl=theirs.qctl, qbin=qbin, rept=rept)
    except LocalProtocolError as exc:
        raise RemoteProtocolError(
            f"the peer's prefix characters collide: {exc}",
            error_hint="Prefix characters collide",
        ) from exc
    if mine.long_packets and theirs.long_packets:
        peer_max = theirs.max_packet_length
    else:
        # Normal packets only: the peer's MAXL is a LEN, our lengths count MARK and LEN too.
        peer_max = min(theirs.max_packet_length, _NORMAL_PACKET)
    window = min(mine.window, theirs.window) if mine.windows and theirs.windows else 1
    retry_limit = config.retry_limit
    if retry_limit and retry_limit < window + 1:
        retry_limit = window + 1
    send_max = max(MIN_PACKET_LENGTH, min(config.max_packet_length, peer_max))
    timeout = config.timeout
    if timeout is None:
        timeout = line_timeout(config.delay, config.rate, window, max(send_max, 96))
    return KermitNegotiated(
        send_max_length=send_max,
        window=window,
        check=check,
        send_encoding=send_encoding,
        receive_encoding=receive_encoding,
        attributes=mine.attributes and theirs.attributes,
        recovery=mine.recovery and theirs.recovery and mine.attributes and theirs.attributes,
        streaming=mine.streaming and theirs.streaming,
        timeout=timeout,
        peer_time=theirs.timeout,
        retry_limit=retry_limit,
        eol=theirs.eol,
        padding=bytes([theirs.padc]) * theirs.npad,
    )
