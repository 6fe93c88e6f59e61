"""Kermit server mode, sans-I/O: a loop of transactions driven by the client's packets.

A Kermit server (C-Kermit's SERVER command, ``ckcpro.w``) waits, idle, for a
client's request, carries out one transaction, and waits again:

==========  ==================================================================
client      server
==========  ==================================================================
I           ACK with our Send-Init field (the client's following G or R may
            then carry the negotiated block check)
S           receive files (the client's SEND): a :class:`KermitReceiver`
R filespec  send the files it names (GET): a :class:`KermitSender`
J filespec  REGET: the same, each file with RESEND (C-Kermit's ``reget``)
G D [spec]  REMOTE DIRECTORY: the listing as screen text (S, X, D..., Z, B)
G U         REMOTE SPACE: the free space, in the ACK
G C [dir]   REMOTE CD: change directory (inside the served tree), in the ACK
G E spec    REMOTE DELETE: in the ACK
G F         FINISH: ACK, and the server ends
G L         BYE (logout): ACK, and the server ends
other       E "Unimplemented server function", then idle again
==========  ==================================================================

Every transaction starts at sequence number 0 with a type-1 check (after an
I exchange, G and R may carry the negotiated check: an idle packet whose
check fails is read again with it).  The transactions themselves are the
ordinary sender and receiver machines of this package; this class only
dispatches.  What a request *does* (which files, which directory, what is
refused) is the caller's ``handler``: the core does no file I/O.
"""

from __future__ import annotations

import dataclasses
import enum
import io
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from serialsocket._checks import BlockCheck
from serialsocket._encoding import Encoding
from serialsocket._errors import MalformedDataError
from serialsocket._packet import Packet, build_packet
from serialsocket._parser import PacketParser, PacketReceived, RejectReason
from serialsocket._wire import CR, PacketType, unchar

from ._core import KermitEvent, KermitStatistics, OutgoingFile, TransferComplete, TransferFailed
from ._params import KermitConfig, KermitInit, negotiate_kermit
from ._receiver import AttributePolicy, KermitReceiver
from ._sender import KermitSender

__all__ = [
    "GENERIC_COMMANDS",
    "KermitServer",
    "Refuse",
    "Reply",
    "SendFiles",
    "ServerRequest",
    "ServerState",
    "ShowText",
    "TransactionEnded",
    "TransactionStarted",
]

_PLAIN = Encoding(qbin=None, rept=None)
_MAX_REPLY = 80
"""Characters of a short reply or error text: it must fit one normal packet."""

GENERIC_COMMANDS = {"D": "dir", "U": "space", "C": "cd", "E": "delete", "F": "finish", "L": "bye"}
"""The G subcommands this server answers (letter -> request kind)."""


class ServerState(enum.Enum):
    """The server's states."""

    IDLE = "idle"
    """Waiting for a request."""
    TRANSACTION = "transaction"
    """A sender or receiver is carrying one out."""
    DONE = "done"
    """FINISH or BYE: the server has ended."""


@dataclass(frozen=True, slots=True)
class ServerRequest:
    """What a client asked: ``kind`` is ``get``, ``reget``, ``send`` or one of
    :data:`GENERIC_COMMANDS`' values; ``argument`` is the file spec or the
    directory, decoded (empty when none came)."""

    kind: str
    argument: str = ""


@dataclass(frozen=True, slots=True)
class SendFiles:
    """Answer: send these files (GET)."""

    files: list[OutgoingFile]


@dataclass(frozen=True, slots=True)
class ShowText:
    """Answer: send this text to the client's screen, under an X header."""

    header: str
    text: bytes


@dataclass(frozen=True, slots=True)
class Reply:
    """Answer: a short text in the ACK (REMOTE CD, DELETE, SPACE, FINISH, BYE)."""

    text: str = ""


@dataclass(frozen=True, slots=True)
class Refuse:
    """Answer: an E packet with this text; the server stays up."""

    text: str


ServerAnswer = SendFiles | ShowText | Reply | Refuse
Handler = Callable[[ServerRequest], ServerAnswer]


@dataclass(frozen=True, slots=True)
class TransactionStarted:
    """A request was accepted; the events that follow, up to
    :class:`TransactionEnded`, are its sender's or receiver's."""

    request: ServerRequest


@dataclass(frozen=True, slots=True)
class TransactionEnded:
    """A transaction ended; ``failure`` is its message when it failed.

    ``statistics``: its sender's or receiver's counters (None when it was
    answered in one packet: a reply or a refusal).
    """

    request: ServerRequest
    failure: str | None = None
    statistics: KermitStatistics | None = None


ServerEvent = KermitEvent | TransactionStarted | TransactionEnded


class KermitServer:
    """Serves requests until FINISH or BYE (see the module doc).

    Args:
        config: local settings for every transaction.
        now: the current time.
        handler: answers each request (the caller's code: file I/O, the
            served tree, what is refused).
        policy: decides on each uploaded file's attributes (as
            :class:`KermitReceiver`'s).
    """

    def __init__(
        self,
        config: KermitConfig,
        now: float,
        handler: Handler,
        policy: AttributePolicy | None = None,
    ) -> None:
        self.config = config
        self._handler = handler
        self._policy = policy
        self._state = ServerState.IDLE
        self._mine = KermitInit.mine(config)
        self._parser = self._idle_parser(BlockCheck.SUM6)
        self._alternate = BlockCheck.SUM6  # the check an I exchange agreed on
        self._side: KermitSender | KermitReceiver | None = None
        self._request = ServerRequest("")
        self._out = bytearray()
        self._events: deque[ServerEvent] = deque()
        self._last: KermitStatistics | None = None
        self.transactions = 0
        """Transactions carried out (or refused)."""
        self._now = now

    # -- the sans-I/O surface -----------------------------------------------------------

    @property
    def state(self) -> ServerState:
        """The current state."""
        return self._state

    @property
    def finished(self) -> bool:
        """True once FINISH or BYE was answered."""
        return self._state is ServerState.DONE

    @property
    def request(self) -> ServerRequest:
        """The request being (or last) carried out."""
        return self._request

    @property
    def receiver(self) -> KermitReceiver | None:
        """The receiver of an upload in progress (its attributes), else None."""
        return self._side if isinstance(self._side, KermitReceiver) else None

    def data_to_send(self) -> bytes:
        """Bytes for the line."""
        if self._side is not None:
            self._out += self._side.data_to_send()
        out = bytes(self._out)
        self._out.clear()
        return out

    def next_event(self) -> ServerEvent | None:
        """The next event, or None."""
        self._pump()
        return self._events.popleft() if self._events else None

    def get_timer(self) -> float | None:
        """The transaction's timer; None while idle (a server waits for ever)."""
        return self._side.get_timer() if self._side is not None else None

    def handle_timer(self, now: float) -> None:
        """Call at :meth:`get_timer`'s time."""
        if self._side is not None:
            self._side.handle_timer(now)
            self._pump()

    def receive_data(self, data: bytes | bytearray | memoryview, now: float) -> None:
        """Bytes from the line."""
        self._now = now
        if self._state is ServerState.DONE:
            return
        if self._side is not None:
            self._side.receive_data(data, now)
            self._pump()
            if self._current() is not None or self.finished:
                return
            # The transaction ended inside this chunk; what followed its last
            # packet may be the next request (a client sends it as soon as it
            # has ACKed B).  The idle loop reads the chunk again: the
            # transaction's own packets (ACKs, D, Z, B) are ignored there.
        self._parser.receive_data(data)
        while self._side is None and not self.finished:
            event = self._parser.next_event()
            if event is None:
                return
            if not isinstance(event, PacketReceived):
                if event.reason is RejectReason.BAD_CHECK:
                    rescued = self._reparse(event.raw)
                    if rescued is not None:
                        self._on_request(rescued.packet, now)
                continue
            self._on_request(event.packet, now)
        side = self._current()
        if side is not None:
            # Bytes after the request that started the transaction belong to it.
            rest = self._parser_leftover()
            if rest:
                side.receive_data(rest, now)
            self._pump()

    def abort(self, reason: str) -> None:
        """Stop the transaction in progress with an E packet; the server stays up."""
        if self._side is not None:
            self._side.abort(reason)
            self._pump()

    def statistics(self) -> KermitStatistics | None:
        """The counters of the transaction in progress, else of the last one."""
        if self._side is not None:
            return self._side.statistics()
        return self._last

    # -- idle: requests -----------------------------------------------------------------

    def _current(self) -> KermitSender | KermitReceiver | None:
        return self._side

    def _idle_parser(self, check: BlockCheck) -> PacketParser:
        return PacketParser(
            max_length=max(self.config.max_packet_length, 96) + 16,
            check=check,
            init_check=BlockCheck.SUM6,
        )

    def _reparse(self, raw: bytes) -> PacketReceived | None:
        for check in dict.fromkeys((self._alternate, BlockCheck.CRC16)):
            parser = self._idle_parser(check)
            parser.init_check = BlockCheck.CRC16  # a FORCE-3 I or S
            parser.receive_data(raw)
            got = parser.next_event()
            if isinstance(got, PacketReceived):
                return got
        return None

    def _parser_leftover(self) -> bytes:
        left = bytearray()
        while True:  # drain what the idle parser still holds, re-framed
            event = self._parser.next_event()
            if event is None:
                break
            if isinstance(event, PacketReceived):
                left += build_packet(event.packet, self._alternate, eol=CR)
        self._parser = self._idle_parser(BlockCheck.SUM6)
        return bytes(left)

    def _reply(self, seq: int, ptype: str, text: str) -> None:
        field, _ = _PLAIN.encode_prefix(
            text[:_MAX_REPLY].encode("utf-8", "replace"), 4 * _MAX_REPLY
        )
        self._out += build_packet(Packet(seq=seq, type=ptype, data=field), BlockCheck.SUM6, eol=CR)

    def _on_request(self, packet: Packet, now: float) -> None:
        ptype = packet.type
        if ptype == PacketType.INIT:
            peer = KermitInit.decode(packet.data)
            neg = negotiate_kermit(self.config, self._mine, peer)
            self._alternate = neg.check
            self._out += build_packet(
                Packet(seq=packet.seq, type=PacketType.ACK, data=self._mine.encode()),
                BlockCheck.SUM6,
                eol=CR,
            )
            return
        if ptype == PacketType.SEND_INIT:
            self._begin(ServerRequest("send"))
            receiver = KermitReceiver(self.config, now, policy=self._policy)
            self._side = receiver
            receiver.receive_data(build_packet(packet, BlockCheck.SUM6, eol=CR), now)
            return
        if ptype == PacketType.RECEIVE_INIT:
            self._answer(packet, ServerRequest("get", self._text(packet.data)), now)
            return
        if ptype == "J":  # REGET: GET, sending each file with RESEND (C-Kermit)
            self._answer(packet, ServerRequest("reget", self._text(packet.data)), now)
            return
        if ptype == PacketType.GENERIC:
            field = _decoded(packet.data)
            kind = GENERIC_COMMANDS.get(chr(field[0]) if field else "")
            if kind is None:
                self.transactions += 1
                self._reply(packet.seq, PacketType.ERROR, "Unimplemented server function")
                return
            self._answer(packet, ServerRequest(kind, _first_argument(field[1:])), now)
            return
        if ptype in (PacketType.COMMAND, "K", "H", "V", "W", "O"):
            self.transactions += 1
            self._reply(packet.seq, PacketType.ERROR, "Unimplemented server function")
        # Anything else (a NAK, a stray ACK, an echo) is ignored while idle.

    def _answer(self, packet: Packet, request: ServerRequest, now: float) -> None:
        self._begin(request)
        answer = self._handler(request)
        if isinstance(answer, Refuse):
            self._reply(packet.seq, PacketType.ERROR, answer.text)
            self._end(answer.text)
        elif isinstance(answer, Reply):
            self._reply(packet.seq, PacketType.ACK, answer.text)
            self._end(None)
            if request.kind in ("finish", "bye"):
                self._state = ServerState.DONE
        elif isinstance(answer, SendFiles):
            config = self.config
            if request.kind == "reget":
                config = dataclasses.replace(config, resend=True, text=False)
            self._side = KermitSender(answer.files, config, now)
        else:
            screen = OutgoingFile(
                answer.header, len(answer.text), io.BytesIO(answer.text), screen=True
            )
            self._side = KermitSender([screen], self.config, now)

    def _text(self, field: bytes) -> str:
        return _decoded(field).decode("utf-8", "replace")

    def _begin(self, request: ServerRequest) -> None:
        self.transactions += 1
        self._request = request
        self._state = ServerState.TRANSACTION
        self._events.append(TransactionStarted(request))

    def _end(self, failure: str | None, stats: KermitStatistics | None = None) -> None:
        self._events.append(TransactionEnded(self._request, failure, stats))
        self._state = ServerState.IDLE

    def _pump(self) -> None:
        """Move the transaction's events out; back to idle when it is over."""
        side = self._side
        if side is None:
            return
        failure: str | None = None
        while (event := side.next_event()) is not None:
            if isinstance(event, TransferFailed):
                failure = event.message
            self._events.append(event)
            if isinstance(event, TransferComplete | TransferFailed):
                self._out += side.data_to_send()
                self._last = side.statistics()
                self._side = None
                self._end(failure, self._last)
                return


def _decoded(field: bytes) -> bytes:
    try:
        return _PLAIN.decode(field)
    except MalformedDataError:
        return field


def _first_argument(field: bytes) -> str:
    """A G packet's first argument: ``tochar(len)`` then that many bytes."""
    if not field:
        return ""
    n = unchar(field[0])
    if n < 0:
        return ""
    return field[1 : 1 + n].decode("utf-8", "replace")
