"""Endpoint configuration and the timing figures derived from it.

All timing comes from three physical facts the user states -- one-way delay,
line rate, bits per character -- plus what the endpoint measures.  There is no
fixed second-scale timeout anywhere: a 2400 bit/s line gets timers sized for
2400 bit/s, the Earth-Moon path timers sized for 2.6 s round trips, a fast pty
timers of a few milliseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ._checks import BlockCheck
from ._encoding import EIGHT_BIT_CLEAN, PRINTABLE, Encoding
from ._errors import LocalProtocolError
from ._length import LADDER
from ._packet import data_capacity
from ._params import (
    DENSE_FEATURES,
    FEATURE_EXPEDITED,
    FEATURE_XON_XOFF,
    LANE_CORRECTION,
    LANE_EARLY,
    LANE_LATEST,
    MAX_LONG_WINDOW,
)
from ._wire import DEFAULT_MAX_PACKET_LENGTH, MAX_PACKET_LENGTH

__all__ = [
    "ADAPTIVE_RECEIVE_LENGTH",
    "DEFAULT_BUFFER_CAP",
    "DEFAULT_EARLY_DATA",
    "DEFAULT_MAX_PACKET_TIME",
    "IDLE_COPY_MIN_PACKETS",
    "MAX_EARLY_DATA",
    "MAX_IDLE_COPIES",
    "MAX_WINDOW",
    "MIN_CONNECT_TIMEOUT",
    "MIN_ENDPOINT_PACKET_LENGTH",
    "UNHINTED_CONNECT_TIMEOUT",
    "UNHINTED_INIT_TIMEOUT",
    "UNMEASURED_DEAD_AFTER",
    "EndpointConfig",
    "line_encoding",
]

MAX_WINDOW = 31
"""Largest window: sequence numbers are mod 64 and selective repeat needs the
window to be at most half the space (Kermit's 31; E-Kermit P_WSLOTS)."""

MIN_ENDPOINT_PACKET_LENGTH = 38
"""The init packet is at most 38 characters (31 data + header + CRC: XCAPAS,
XWINDO and XLANES; 37 without the latest-value lane's XLANES, 34 without the
long-sequence offer either, 33 with no XCAPAS at all): each side must receive
it, so no endpoint may announce less (MIN_PACKET_LENGTH bounds the packet
layer alone).  It was 37 until XLANES (PROTOCOL.md section 12): an older
telelink configured for exactly 37 refuses a current endpoint's init."""

DEFAULT_BUFFER_CAP = 16 * 1024 * 1024
"""Most bytes the receive buffer grows to with the bandwidth-delay product:
7 hours of a 9600 bit/s line, four round trips of it at Mars distance."""

_DERIVED_LENGTHS = (DEFAULT_MAX_PACKET_LENGTH, 256, 512, 1024, 2048)
"""Candidate derived packet lengths: the goodput grid's (bench/results/README.md)."""

ADAPTIVE_RECEIVE_LENGTH = 1024
"""The packet length an endpoint without ``max_packet_length`` announces it
receives: room for the sender to lengthen its packets on a clean line
(PROTOCOL.md 4.7).  1024 keeps CRC-16 (its residual-error arithmetic,
PROTOCOL.md 10.3, asks for CRC-32 from about 2000 characters) and a receive
window of 64 such packets in the default 64 KiB buffer; past it the header's
share is under 1.3 % and every further doubling gains under 0.5 %."""

DEFAULT_MAX_PACKET_TIME = 0.54
"""Seconds of line time a data packet may take by default
(``EndpointConfig.max_packet_time``): an emergency stop on the expedited
lane overtakes queued packets but not the one leaving the UART, so this is
what a stop can wait behind.  A 128-character packet's time at 2400 bit/s
(the paper's packet on its line, and every packet before the length was
measured): 2400 bit/s keeps 128, 9600 bit/s may reach 517, 300 bit/s gets
96."""

_LONG_WINDOW_LENGTH = 512
"""The longest derived packet length when long sequence numbers may carry a
wide window (see ``derived_max_packet_length``)."""

_UNKNOWN_RATE_SEND_BUFFER = 64 * 1024
"""Send buffer when the line rate is unknown: a fast line (pty, TCP tunnel)
drains it in milliseconds, and large writes need few wake-ups."""

MIN_CONNECT_TIMEOUT = 120.0
"""Seconds the derived connect timeout is at least when a delay is hinted; the
init is resent with backoff meanwhile, so a silent port costs a few short
packets."""

UNHINTED_CONNECT_TIMEOUT = 3000.0
"""Seconds the derived connect timeout is with no delay hint: 50 minutes, more
than a round trip to Mars at its farthest (2 x 22.4 light-minutes).  Nothing
says the peer is near; ``connect_timeout`` (``--connect-timeout``) sets less."""

UNHINTED_INIT_TIMEOUT = 1.0
"""Seconds before the first connection request is resent when neither rate nor
delay is hinted (RFC 6298's initial retransmission timeout); each further
resend waits twice as long."""

UNMEASURED_DEAD_AFTER = 60.0
"""Seconds of silence the derived ``dead_after`` allows before any round trip
has been measured: the hints may be wrong or absent, and a verdict sized from
them would end a healthy long link before its first answer arrives.  The
first measured round trip replaces it (see ``Endpoint``)."""

IDLE_COPY_MIN_PACKETS = 8
"""Idle copies (``EndpointConfig.idle_copies``) are sent only when the round
trip is at least this many full packets' transmit times: on a shorter line a
repair costs a few packet times, and copies would only double the ACKs."""

DEFAULT_EARLY_DATA = 256
"""Bytes of the stream a connection request may carry by default; the init's
own bound (PROTOCOL.md 13) takes fewer on short lines: about 35 bytes of
random binary (60 of text) at 1.3 s one way, all 256 at 300 s."""

MAX_EARLY_DATA = 512
"""Most bytes ``EndpointConfig.early_data`` may ask for (the init's limit,
:data:`~serialsocket._params.EARLY_INIT_LIMIT` characters, may take fewer)."""

MAX_IDLE_COPIES = 3
"""Most extra copies of one packet: at a packet error rate of 5 % (512
characters at a byte error rate of 1e-4) three copies leave one packet in
160 000 to a repair round trip, and the line's idle time is spent."""

_ACK_WIRE = 10
"""Wire bytes of an ACK (MARK LEN SEQ TYPE + 2 data + 3 CRC + CR)."""


def line_encoding(bytesize: int = 8, parity: str = "N") -> Encoding:
    """The prefix profile a line with this character format carries: 8 data
    bits without parity (8N1) are 8-bit clean, anything else (7 data bits,
    any parity) is printable only (PROTOCOL.md section 8)."""
    return EIGHT_BIT_CLEAN if bytesize == 8 and parity == "N" else PRINTABLE


@dataclass(frozen=True, slots=True, kw_only=True)
class EndpointConfig:
    """What one side of a link wants; the init exchange negotiates the rest.

    Attributes:
        max_packet_length: largest packet this side receives, MARK through
            CHECK, and sends (the peer's value bounds that too).  Given, every
            data packet is cut to it (a fixed length, as classic Kermit).
            None (the default): the packet length is measured, not
            configured (PROTOCOL.md 4.7).  The side announces that it
            receives :data:`ADAPTIVE_RECEIVE_LENGTH`, starts sending at
            :meth:`derived_max_packet_length` (128, the paper's size, unless
            line rate and delay say 31 such packets cannot cover the repair
            of a loss) and then cuts each data packet to the length whose
            goodput is best at the byte error rate its own losses show: up
            to 1024 on a clean line, about 96 at a byte error rate of 1e-3,
            never longer than ``max_packet_time`` allows.  Statistics:
            ``packet_length``, ``byte_error_rate``.
        max_packet_time: with the packet length measured (no
            ``max_packet_length``), the most seconds of line time one data
            packet may take at the line rate in use: an urgent message
            overtakes queued packets but waits for the one leaving the UART
            (default :data:`DEFAULT_MAX_PACKET_TIME`: 128 characters at 2400
            bit/s, 517 at 9600).  None: no cap (a bulk byte stream, as the
            ``serialsocket listen/connect`` netcat sends).
        window: window in packets, 1..31 (default 31, the most the mod-64
            sequence numbers allow), with a peer that does not take long
            sequence numbers (``long_window``).  1 is the paper's
            stop-and-wait.  The
            sender never has more unacknowledged packets than the line
            carries in its repair horizon (the bandwidth-delay bound, see
            PROTOCOL.md 4.6), so a wide window never over-commits a short or
            slow line, while a narrow one starves a long fast one (16 at
            9600 bit/s, 1.3 s keeps the line busy 78 % of the time).
        check: block check asked for (CRC-16 by default).
            ``BlockCheck.CRC32`` asks a telelink peer for CRC-32 (PROTOCOL.md
            10.3; offered anyway when the packet length needs it); a peer
            that does not agree gets CRC-16.
        encoding: what the line carries.  PRINTABLE (8th-bit prefixing) for
            a line that carries only printable ASCII plus SOH and CR (7 data
            bits, parity, a terminal server); EIGHT_BIT_CLEAN for an 8-bit
            clean line (8N1).  None (the default): from the line --
            ``connect``/``accept``/``listen`` over a port from ``open_port``
            take its character format (8N1: 8-bit; 7 bits or parity:
            printable; :func:`line_encoding`), anything else is taken as
            printable.  Between two telelink ends with ``dense`` the agreed
            data encoding is then the escape code or the radix-91 packing;
            with a classic or older peer, this prefix profile.
        dense: offer the dense encodings (XCAPAS bits 2 and 4, PROTOCOL.md
            section 10): about 1.01 wire characters per random byte on an
            8-bit line where Kermit prefixing costs 1.27.  Off by default,
            because they have no run-length compression: a command channel's
            fixed-size packets, mostly runs of zero bytes, took 3.6 times
            the characters with them (tcpstream over the moon preset), so
            only byte streams of arbitrary content should turn it on (the
            ``serialsocket listen/connect`` netcat does; ``--no-dense`` there).
            False sends the classic init (no XCAPAS unless long sequence
            numbers are offered) and answers a request classically.
        expedited: offer the expedited lane (XCAPAS bit 16, PROTOCOL.md
            section 11): small urgent messages that overtake queued stream
            data (:meth:`Endpoint.send_expedited`; tcpstream sends its
            EMERGENCY_STOP there).  On by default; a telelink peer that
            agrees makes the init one character longer (XCAPAS); False keeps
            the classic init unless something else is offered.
        latest: offer the latest-value lane (XLANES bit 1 beside the
            expedited lane's XCAPAS bit 16, PROTOCOL.md section 12): a series
            of values, each superseding the last, where a lost value is never
            repaired once a newer one exists (:meth:`Endpoint.send_latest`;
            tcpstream's teleoperation samples and replies use it).  On by
            default (with ``expedited``; one more init character); False
            clears its XLANES bit.
        early_data: at most this many bytes of the stream, queued with
            ``send`` before ``connect``, ride in the connection request
            (XLANES bit 2 beside the expedited lane, PROTOCOL.md section 13):
            the first byte arrives one one-way delay after connecting instead
            of three.  A listener takes early data unless this is 0.  The
            init's own bound (half a packet, or 0.5 % of the round trip with
            the rate and delay given; PROTOCOL.md 13) may take fewer bytes.
        first_flight: a connector with more queued when it connects than
            its request carries sends a first flight of data packets right
            behind the request, before the answer (XLANES bit 4 beside the
            expedited lane, PROTOCOL.md section 14): the line carries data
            during the handshake's round trip instead of idling.  Off by
            default (the ``serialsocket listen/connect`` netcat turns it on):
            with no hints, the flight's queue moves the pacer's model, and
            in one of the seeds of a 200 KB transfer at 2400 bit/s and 1.3 s
            the model ran late, its short round trips shrank the window,
            and the transfer took 0.87 of the hinted goodput instead of
            0.98 (other seeds gained: tests/serialsocket/test_rate_estimation.py).
        takes_first_flight: a listener takes a first flight it can read
            (PROTOCOL.md 14).  On by default; False drops every flight (its
            bytes come again after the answer).
        correction: offer corrected data packets (XLANES bit 8 beside the
            expedited lane, PROTOCOL.md section 15).  Once agreed, the
            sender chooses per packet, with its length, whether a data
            packet carries sums that let the receiver repair one damaged
            character per block of 255 instead of asking for a resend: only
            when the losses it has measured make that worth the sums' three
            characters per block (a clean line never pays for them).  The
            receiver always reads them.  Off by default (one more bit in the
            init); the ``serialsocket listen/connect`` netcat turns it on.
        xon_xoff: the line uses software flow control: the escape code must
            escape XON/XOFF as well (declared in XCAPAS, bit 32).
        one_way_delay: a hint, where estimation starts: the link's one-way
            propagation delay in seconds (1.3 for the Earth-Moon path), 0
            when unknown.  Sets the first timeout.  Measured: the round trip
            (init exchange, then every ACK of a packet sent once) and the
            path's base round trip without queueing; once the base is
            measured the timers, the NAK horizon and the buffer sizing use
            the smaller of the hint and the measured one-way delay (a hint
            10 times too long is corrected; a short one stays, and the
            retransmission timer follows the measured round trip either
            way).  Statistics: ``smoothed_rtt``, ``rtt_variation``,
            ``base_rtt``.
        line_rate: a hint, where estimation starts: line rate in bits/s, or
            None when unknown or fast (a TCP tunnel, a local pty).  Measured:
            the delivery rate from the ACK clock and the queue in front of
            the line (serialsocket/_rate.py); pacing, serialisation times,
            the bandwidth-delay bound on the window and the timers follow
            the estimate, which a wrong hint (10 times high or low) does not
            hold back.  Without a hint an endpoint stays unpaced until a
            queue shows that pacing is needed.  Statistics: ``line_rate``
            (the estimate in use), ``measured_rate``, ``queue_delay``.
        bits_per_char: bits per character on the line (8N1 = 10).
        long_window: the window offered with long sequence numbers
            (PROTOCOL.md section 9), 1..131071; a telelink peer that offers
            them too gets the smaller offer, a peer that does not gets
            ``window``.  None: do not offer them (mod-64 numbers, window
            ``window``).  Offered only when ``window`` is 31: a narrower
            window is the window wanted.  The bandwidth-delay bound and the
            receive buffer keep what is in flight to what the line needs.
        receive_buffer: bytes of received data held for the application
            (in order, unread) plus out-of-order packets, at least.  When
            full, the advertised window closes; nothing is dropped that is
            not resent.  With a line rate, it grows to four round trips of
            line data (measured round trips once there are some) so that a
            long fast line keeps its window open, up to ``buffer_cap``.
        buffer_cap: the most ``receive_buffer`` grows to (default 16 MiB);
            statistics say when the line wanted more (``buffer_capped``).
        send_buffer: bytes the application may queue beyond what is in flight;
            ``send`` accepts less when it is full (back-pressure).  None
            derives it (:meth:`derived_send_buffer`): what the line carries in
            one round trip when the rate is known, else 64 KiB.
        connect_timeout: give up connecting after this many seconds; None
            derives it: 10 x the initial timeout, at least 120 s, or 50
            minutes with no delay hint (nothing says the peer is not at
            Mars).  The connection request is resent with backoff until then.
        dead_after: declare the link dead after this much silence while
            data or probes are outstanding; None derives it: 10 x the initial
            timeout, at least 2 s.  It is a floor: once a round trip is
            measured the endpoint waits at least two measured round trips
            (an outage that long is ridden out) plus two retransmission
            timeouts, and four of the recent largest gaps between the peer's
            data packets; a derived value is at least 60 s until then, so a
            hint that is too small never ends a healthy link.
        max_retries: per-packet retransmissions before aborting; None means
            unlimited (the right choice for long-delay links: liveness is then
            judged by ``dead_after``).
        auto_accept: a listening side accepts connection requests itself; if
            False it emits ConnectionRequested and waits for accept()/refuse().
        linger: seconds to keep answering the peer's retransmitted EOF after a
            graceful close; None derives it: ``dead_after`` (a new connection
            request ends it early).
        idle_copies: on a long line (a round trip of at least
            ``IDLE_COPY_MIN_PACKETS`` full packets), when a bulk sender's
            line would otherwise idle -- nothing new to send, or the window
            full -- send up to this many extra copies of each unacknowledged
            packet, newest first (PROTOCOL.md 4.4).  The line carries
            nothing else then, so they cost no goodput; a packet damaged
            once among the last round trip's packets is then repaired
            without a round trip of waiting.  Only a sender whose data
            waited for the line in the last two round trips copies: an
            interactive one would make its next packet wait.  0 turns them
            off.  Statistics: ``idle_copies``.
    """

    max_packet_length: int | None = None
    window: int = MAX_WINDOW
    long_window: int | None = MAX_LONG_WINDOW
    check: BlockCheck = BlockCheck.CRC16
    encoding: Encoding | None = None
    dense: bool = False
    expedited: bool = True
    latest: bool = True
    early_data: int = DEFAULT_EARLY_DATA
    first_flight: bool = False
    takes_first_flight: bool = True
    correction: bool = False
    max_packet_time: float | None = DEFAULT_MAX_PACKET_TIME
    xon_xoff: bool = False
    one_way_delay: float = 0.0
    line_rate: float | None = None
    bits_per_char: int = 10
    receive_buffer: int = 64 * 1024
    buffer_cap: int = DEFAULT_BUFFER_CAP
    send_buffer: int | None = None
    connect_timeout: float | None = None
    dead_after: float | None = None
    max_retries: int | None = None
    auto_accept: bool = True
    linger: float | None = None
    idle_copies: int = 2

    def __post_init__(self) -> None:
        def bad(name: str, value: object, allowed: str) -> LocalProtocolError:
            return LocalProtocolError(f"EndpointConfig.{name}={value!r}: must be {allowed}")

        if self.max_packet_length is not None and not (
            MIN_ENDPOINT_PACKET_LENGTH <= self.max_packet_length <= MAX_PACKET_LENGTH
        ):
            raise bad(
                "max_packet_length",
                self.max_packet_length,
                f"{MIN_ENDPOINT_PACKET_LENGTH}..{MAX_PACKET_LENGTH} (MARK through CHECK; "
                "the init packet must fit)",
            )
        if not 1 <= self.window <= MAX_WINDOW:
            raise bad("window", self.window, f"1..{MAX_WINDOW}")
        if self.long_window is not None and not 1 <= self.long_window <= MAX_LONG_WINDOW:
            raise bad("long_window", self.long_window, f"None or 1..{MAX_LONG_WINDOW}")
        if not (math.isfinite(self.one_way_delay) and self.one_way_delay >= 0):
            raise bad("one_way_delay", self.one_way_delay, "a finite number of seconds >= 0")
        if self.line_rate is not None and not (
            math.isfinite(self.line_rate) and self.line_rate > 0
        ):
            raise bad("line_rate", self.line_rate, "None or bits/s > 0")
        if not 5 <= self.bits_per_char <= 16:
            raise bad("bits_per_char", self.bits_per_char, "5..16 (8N1 = 10)")
        if self.receive_buffer < 2 * MAX_PACKET_LENGTH:
            raise bad("receive_buffer", self.receive_buffer, f">= {2 * MAX_PACKET_LENGTH}")
        if self.buffer_cap < self.receive_buffer:
            raise bad("buffer_cap", self.buffer_cap, f">= receive_buffer ({self.receive_buffer})")
        if self.send_buffer is not None and self.send_buffer < 1:
            raise bad("send_buffer", self.send_buffer, "None (derived) or >= 1")
        for name in ("connect_timeout", "dead_after", "linger"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise bad(name, value, "None (derived) or seconds > 0")
        if self.max_retries is not None and self.max_retries < 1:
            raise bad("max_retries", self.max_retries, "None (unlimited) or >= 1")
        if not 0 <= self.early_data <= MAX_EARLY_DATA:
            raise bad("early_data", self.early_data, f"0 (none)..{MAX_EARLY_DATA} bytes")
        if self.max_packet_time is not None and not (
            math.isfinite(self.max_packet_time) and self.max_packet_time > 0
        ):
            raise bad("max_packet_time", self.max_packet_time, "None (no cap) or seconds > 0")
        if not 0 <= self.idle_copies <= MAX_IDLE_COPIES:
            raise bad("idle_copies", self.idle_copies, f"0..{MAX_IDLE_COPIES}")

    # -- derived timing ------------------------------------------------------------

    def transmit_time(self, wire_bytes: int) -> float:
        """Seconds the UART needs to clock out this many bytes (0 if the rate is unknown)."""
        if self.line_rate is None:
            return 0.0
        return wire_bytes * self.bits_per_char / self.line_rate

    def physical_rtt(self, packet_bytes: int) -> float:
        """The least possible round trip for a packet of this size and its ACK.

        No timeout ever shrinks below this (plus a margin): a timer shorter than
        the physics retransmits packets that are merely still in flight.
        """
        return 2 * self.one_way_delay + self.transmit_time(packet_bytes + _ACK_WIRE)

    def initial_timeout(self) -> float:
        """The retransmission timeout before any round trip has been measured.

        Covers the physical round trip of a full packet, the peer's transmit
        queue (the ACK may wait behind two of the peer's own packets, see the
        pacing horizon), and a margin of a quarter of the round trip, at least
        50 ms for process scheduling on either side.
        """
        full = self.derived_max_packet_length() + 1
        base = self.physical_rtt(full) + 2 * self.transmit_time(full)
        return base + max(0.25 * base, 0.05)

    def derived_connect_timeout(self) -> float:
        """``connect_timeout`` or its derived default: 10 initial timeouts, but at
        least :data:`MIN_CONNECT_TIMEOUT` -- the hints may be wrong, and a peer
        a light-minute away cannot answer in half a second -- or, with no delay
        hint at all, :data:`UNHINTED_CONNECT_TIMEOUT`."""
        if self.connect_timeout:
            return self.connect_timeout
        if self.one_way_delay == 0:
            return max(10 * self.initial_timeout(), UNHINTED_CONNECT_TIMEOUT)
        return max(10 * self.initial_timeout(), MIN_CONNECT_TIMEOUT)

    def derived_dead_after(self) -> float:
        """``dead_after`` or its derived default."""
        return self.dead_after or max(10 * self.initial_timeout(), 2.0)

    def derived_max_packet_length(self) -> int:
        """``max_packet_length`` or its derived default.

        128 (the paper's size; every Kermit peer accepts it; within a few per
        cent of the best length on slow lines at any error rate) unless the
        line is known to be fast and long: then the shortest of 256, 512,
        1024, 2048 whose window of 31 packets covers the repair of a loss,
        ``2 x rtt + 2 x tx`` (PROTOCOL.md 4.6), because the window cannot
        grow past 31 and a packet's header is the only other cost.  The error
        rate is not known here, so the rule never goes below 128 and stops
        at the first length that fills the line: longer packets only add
        exposure to errors.  At 2400 bit/s it stays 128 up to 3.6 s one way;
        it is 256 at 9600 bit/s and 512 at 19200 bit/s on the Earth-Moon
        path.  When long sequence numbers may be offered (``long_window``
        set, ``window`` 31) it stops at 512: past that the wide window covers
        the line, and longer packets would only be hit more often.
        """
        if self.max_packet_length is not None:
            return self.max_packet_length
        if self.line_rate is None:
            return DEFAULT_MAX_PACKET_LENGTH
        # With long sequence numbers possible the window, not the packet,
        # covers a longer line: packets stop at 512 (5 % of them hit at a
        # byte error rate of 1e-4, against 18 % at 2048).
        longest = (
            _LONG_WINDOW_LENGTH
            if self.long_window is not None and self.window == MAX_WINDOW
            else _DERIVED_LENGTHS[-1]
        )
        for length in _DERIVED_LENGTHS:
            if length >= longest or self._window_covers(length):
                return length
        return _DERIVED_LENGTHS[-1]

    def receive_max_packet_length(self) -> int:
        """The longest packet this side announces it receives: ``max_packet_length``,
        or with the length measured, :data:`ADAPTIVE_RECEIVE_LENGTH` (at least the
        starting length, :meth:`derived_max_packet_length`)."""
        if self.max_packet_length is not None:
            return self.max_packet_length
        return max(ADAPTIVE_RECEIVE_LENGTH, self.derived_max_packet_length())

    def measured_length_cap(self, peer_max: int, rate: float | None) -> int:
        """The longest data packet the measured length may reach (PROTOCOL.md
        4.7): ``peer_max``, and with ``max_packet_time`` set and the line's
        ``rate`` known (characters a second), the characters the line carries
        in that time, but at least the longest normal packet (96).  With the
        rate not known yet, the starting length: nothing says how long a
        longer packet would hold the line (without hints, 1024-character
        packets unpaced on a 2400 bit/s line, 20 s one way, timed out in a
        storm until the rate was measured: 0.49 of the limit)."""
        if self.max_packet_time is None:
            return peer_max
        if rate is None or not math.isfinite(rate):
            return min(peer_max, self.derived_max_packet_length())
        return min(peer_max, max(LADDER[0], int(self.max_packet_time * rate) - 1))

    def packet_lengths(self, rate: float | None = None) -> tuple[int, ...]:
        """The data packet lengths this side may send to a peer with the same
        receive limit on a line of ``rate`` characters a second (None: not
        known): ``max_packet_length`` alone if given, else the measured
        length's candidates up to :meth:`measured_length_cap`."""
        if self.max_packet_length is not None:
            return (self.max_packet_length,)
        top = self.measured_length_cap(self.receive_max_packet_length(), rate)
        return (*(n for n in LADDER if n < top), top)

    def derived_send_buffer(self) -> int:
        """``send_buffer`` or its derived default.

        On a rate-limited line: the bytes the line carries in one round trip
        (``2 x one_way_delay``), at least two full packets.  That keeps the
        line busy (the window's packets are already out of the buffer) and
        makes ``send`` push back as soon as the line is: a fixed 64 KiB would
        be four and a half minutes of queue at 2400 bit/s, ahead of every
        later write -- an emergency stop included.  Rate unknown (a pty, a
        TCP tunnel): 64 KiB, a few milliseconds on such a line.
        """
        if self.send_buffer is not None:
            return self.send_buffer
        if self.line_rate is None:
            return _UNKNOWN_RATE_SEND_BUFFER
        per_second = self.line_rate / self.bits_per_char
        return max(2 * self.derived_max_packet_length(), int(per_second * 2 * self.one_way_delay))

    def _window_covers(self, length: int) -> bool:
        """31 packets of ``length`` keep the hinted line busy through the repair
        of a loss, ``2 x rtt + 2 x tx`` (PROTOCOL.md 4.6)."""
        tx = self.transmit_time(length + 1)
        return MAX_WINDOW * tx >= 2 * self.physical_rtt(length + 1) + 2 * tx

    def needs_long_window(self) -> bool:
        """Whether a connector offers long sequence numbers (PROTOCOL.md
        section 9): whenever they may be used (``long_window`` set, ``window``
        31), whatever the hints say.  Hints are where estimation starts, not a
        truth: a delay or rate hint 10x too low "showed" that 31 packets keep
        the line busy, and a 20-second line then ran at a third of its speed
        for the whole connection (the offer cannot be made later).  The price
        is two characters a packet, 1.6 % at 128 characters, where the
        classic window would have done.  A listener agrees to a connector's
        offer."""
        return self.long_window is not None and self.window == MAX_WINDOW

    def line_encoding(self) -> Encoding:
        """``encoding``, or PRINTABLE when it is left to the line and no
        line was seen (a sans-I/O endpoint: printable is safe on any line)."""
        return PRINTABLE if self.encoding is None else self.encoding

    def check_early_data(self, data: bytes | bytearray | memoryview) -> None:
        """Refuse bytes to send before connecting that the send buffer cannot
        hold (the sockets' ``early_data``).

        Raises:
            ValueError: with what to do instead.
        """
        room = self.derived_send_buffer()
        if len(data) > room:
            raise ValueError(
                f"early_data is {len(data)} bytes, the send buffer holds {room}: "
                "pass the first bytes as early_data and send the rest once connected"
            )

    def for_line(self, port: object) -> EndpointConfig:
        """This configuration with ``encoding`` chosen from ``port`` if None:
        the port's ``encoding`` attribute (a :class:`SerialPort` from
        ``open_port`` has one: :func:`line_encoding` of its format), else
        unchanged (PRINTABLE then applies)."""
        if self.encoding is not None:
            return self
        chosen = getattr(port, "encoding", None)
        if not isinstance(chosen, Encoding):
            return self
        return replace(self, encoding=chosen)

    def init_features(self) -> int | None:
        """The XCAPAS feature bits this side offers besides long sequence
        numbers (PROTOCOL.md section 10), or None for the classic init."""
        lane = FEATURE_EXPEDITED if self.expedited else 0
        if not self.dense:
            return lane or None
        return DENSE_FEATURES | lane | (FEATURE_XON_XOFF if self.xon_xoff else 0)

    def init_lanes(self) -> int | None:
        """The XLANES bits this side offers (PROTOCOL.md section 12), or None
        for no XLANES field (it rides with the expedited lane's bit 16)."""
        if not self.expedited:
            return None
        # (A first flight's bit goes only in the init that announces one.)
        lanes = (
            (LANE_LATEST if self.latest else 0)
            | (LANE_EARLY if self.early_data else 0)
            | (LANE_CORRECTION if self.correction else 0)
        )
        return lanes or None

    def data_capacity(self, max_packet_length: int, check: BlockCheck) -> int:
        """Data characters per packet for a negotiated length and check."""
        return data_capacity(max_packet_length, check)
