"""Port I/O: pty pairs, device paths through pyserial, pyserial URLs (real I/O, hang-guarded)."""

from __future__ import annotations

import errno
import pathlib
import termios
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import pytest
import trio

from serialsocket import PortStatistics, SerialPort, open_port, open_pty_pair

LIMIT = 20.0  # hang guard only: these tests move a few KB


def run(fn: Callable[[], Awaitable[None]]) -> None:
    async def guarded() -> None:
        with trio.fail_after(LIMIT):
            await fn()

    trio.run(guarded)


async def read_exactly(port: trio.abc.ReceiveStream, n: int) -> bytes:
    got = bytearray()
    while len(got) < n:
        chunk = await port.receive_some(n - len(got))
        assert chunk, "unexpected EOF"
        got += chunk
    return bytes(got)


def test_pty_pair_is_raw_and_counts() -> None:
    data = bytes(range(256)) * 16  # every byte value, incl. ^C, ^D, ^S, CR: raw mode

    async def main() -> None:
        a, b = open_pty_pair()
        async with a, b:
            async with trio.open_nursery() as nursery:
                nursery.start_soon(a.send_all, data)
                assert await read_exactly(b, len(data)) == data
            await b.send_all(b"\r\n")
            assert await read_exactly(a, 2) == b"\r\n"  # no CR/LF translation
            sa, sb = a.statistics(), b.statistics()
            assert (sa.bytes_out, sa.bytes_in, sa.writes, sa.errors) == (len(data), 2, 1, 0)
            assert (sb.bytes_in, sb.bytes_out, sb.writes) == (len(data), 2, 1)
            assert sb.name.startswith("/dev/")
            assert isinstance(sa, PortStatistics)

    run(main)


def test_other_side_closing_is_broken_with_the_os_error() -> None:
    async def main() -> None:
        a, b = open_pty_pair()
        await b.aclose()
        with pytest.raises(trio.BrokenResourceError, match="the other end of the pty") as info:
            await a.receive_some()
        cause = info.value.__cause__
        assert isinstance(cause, OSError)
        assert cause.errno == errno.EIO
        assert a.statistics().errors == 1
        await a.aclose()

    run(main)


def test_close_wakes_a_blocked_reader_and_later_use_is_closed() -> None:
    async def main() -> None:
        a, b = open_pty_pair()
        async with b:
            async with trio.open_nursery() as nursery:

                async def blocked() -> None:
                    with pytest.raises(trio.ClosedResourceError):
                        await a.receive_some()

                nursery.start_soon(blocked)
                await trio.sleep(0.05)
                await a.aclose()
            with pytest.raises(trio.ClosedResourceError, match="was closed"):
                await a.send_all(b"x")
            with pytest.raises(trio.ClosedResourceError):
                await a.receive_some()
            await a.aclose()  # idempotent

    run(main)


def test_device_path_through_pyserial_sets_8n1_raw_and_baud() -> None:
    async def main() -> None:
        master, slave = open_pty_pair()
        async with master, slave:
            # A pty slave has no modem lines: the DTR/RTS ioctls fail and are ignored.
            port = await open_port(slave.name, 19200)
            async with port:
                assert port.serial is not None
                assert port.serial.baudrate == 19200
                fd = port.serial.fd
                iflag, _oflag, cflag, _lflag, ispeed, _ospeed, _cc = termios.tcgetattr(fd)
                assert ispeed == termios.B19200
                assert cflag & termios.CSIZE == termios.CS8
                assert not cflag & (termios.PARENB | termios.CSTOPB | termios.CRTSCTS)
                assert not iflag & (termios.IXON | termios.IXOFF | termios.ICRNL)
                await port.send_all(b"\x00\x11\x13\r\xff")  # XON/XOFF pass: no flow control
                assert await read_exactly(master, 5) == b"\x00\x11\x13\r\xff"
                await master.send_all(b"reply")
                assert await read_exactly(port, 5) == b"reply"

    run(main)


def test_open_errors_say_what_to_check() -> None:
    async def main() -> None:
        with pytest.raises(OSError, match="check the path and its permissions") as info:
            await open_port("/dev/does-not-exist-telelink")
        assert info.value.errno == errno.ENOENT
        with pytest.raises(ValueError, match="invalid URL"):
            await open_port("nosuchscheme://x")

    run(main)


def test_loop_url_thread_adapter_loses_nothing_on_cancel() -> None:
    async def main() -> None:
        port = await open_port("loop://", 9600)
        assert isinstance(port, SerialPort)
        async with port:
            with trio.move_on_after(0.1) as scope:
                await port.receive_some()  # nothing there: cancelled while waiting
            assert scope.cancelled_caught
            payload = bytes(range(256)) * 40
            await port.send_all(payload)
            assert await read_exactly(port, len(payload)) == payload
            assert port.statistics().bytes_in == len(payload)
        with pytest.raises(trio.ClosedResourceError):
            await port.receive_some()

    run(main)


def test_socket_url_and_peer_disconnect() -> None:
    async def main() -> None:
        listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
        addr = listeners[0].socket.getsockname()
        async with listeners[0] as listener:
            port = await open_port(f"socket://{addr[0]}:{addr[1]}")
            async with port:
                peer = await listener.accept()
                await port.send_all(b"over tcp")
                assert await read_exactly(peer, 8) == b"over tcp"
                await peer.send_all(b"and back")
                assert await read_exactly(port, 8) == b"and back"
                await peer.aclose()
                with pytest.raises(trio.BrokenResourceError) as info:
                    await port.receive_some()
                assert isinstance(info.value.__cause__, OSError)

    run(main)


def test_spy_url_logs_the_traffic(tmp_path: pathlib.Path) -> None:
    log = tmp_path / "spy.txt"

    async def main() -> None:
        master, slave = open_pty_pair()
        async with master, slave:
            port = await open_port(f"spy://{slave.name}?file={log}", 9600)
            async with port:
                await port.send_all(b"spy me")
                assert await read_exactly(master, 6) == b"spy me"

    run(main)
    assert "TX" in log.read_text()
    assert "spy me" in log.read_text()


def test_device_port_waits_for_data_instead_of_reading_eof() -> None:
    # pyserial leaves VMIN = 0, where a tty read with no data returns b""
    # (it would look like EOF); the port must wait for the next byte instead.
    async def main() -> None:
        master, slave = open_pty_pair()
        async with master, slave:
            port = await open_port(slave.name, 9600)
            async with port, trio.open_nursery() as nursery:

                async def late() -> None:
                    await trio.sleep(0.1)
                    await master.send_all(b"late")

                nursery.start_soon(late)
                assert await read_exactly(port, 4) == b"late"

    run(main)


def test_one_receiver_and_one_sender_at_a_time() -> None:
    async def main() -> None:
        port = await open_port("loop://")
        async with port, trio.open_nursery() as nursery:
            nursery.start_soon(port.receive_some)
            await trio.sleep(0.05)
            with pytest.raises(trio.BusyResourceError, match="already receiving"):
                await port.receive_some()
            await port.send_all(b"x")  # lets the first receiver finish

    run(main)


@asynccontextmanager
async def _socket_url_port() -> AsyncIterator[tuple[SerialPort, trio.SocketListener]]:
    """A ``socket://`` port to a loopback listener, whose peer is still to accept."""
    listeners = await trio.open_tcp_listeners(0, host="127.0.0.1")
    addr = listeners[0].socket.getsockname()
    async with listeners[0] as listener, await open_port(f"socket://{addr[0]}:{addr[1]}") as port:
        yield port, listener


def test_socket_url_reads_a_burst_in_a_few_hand_offs() -> None:
    """pyserial's socket:// says in_waiting is 0 or 1; reading 1 + in_waiting
    moved at most two bytes per hand-off to trio (20 KB: ~10 000 of them)."""
    payload = bytes(range(256)) * 80  # 20 480 bytes

    async def main() -> None:
        async with _socket_url_port() as (port, listener):
            peer = await listener.accept()
            await peer.send_all(payload)
            assert await read_exactly(port, len(payload)) == payload
            # Each read returned one hand-off's worth (read_exactly asks
            # for everything still missing, so reads == hand-offs).
            assert port.statistics().reads <= 50, port.statistics()
            await peer.aclose()

    run(main)


def test_socket_url_reads_what_tcp_has_queued_in_one_call() -> None:
    """pyserial's socket:// read(1) + in_waiting made two system calls a
    byte: a receiving end over socket:// read 0.08 MB/s (26 MB/s now, at
    4096-character packets: ``linksim bench pty --port socket``)."""
    payload = bytes(range(256)) * 80  # 20 480 bytes

    async def main() -> None:
        async with _socket_url_port() as (port, listener):
            reads = 0
            read = port.serial.read

            def counted(size: int = 1) -> bytes:
                nonlocal reads
                reads += 1
                return bytes(read(size))

            port.serial.read = counted  # the reader thread's next read is counted
            peer = await listener.accept()
            await peer.send_all(payload)
            assert await read_exactly(port, len(payload)) == payload
            assert reads <= 100, reads
            await peer.aclose()

    run(main)


def test_open_port_refuses_bad_line_settings_at_once() -> None:
    import serial

    async def main() -> None:
        for baud in (0, -9600, 9600.5, True):
            with pytest.raises(ValueError, match="baud must be a positive integer"):
                await open_port("loop://", baud)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="bytesize"):
            await open_port("loop://", bytesize=9)
        with pytest.raises(ValueError, match="parity"):
            await open_port("loop://", parity="X")
        with pytest.raises(ValueError, match="stopbits"):
            await open_port("loop://", stopbits=3)
        # An already-open pyserial port used to hang ("://" in a Serial iterates it).
        ser = serial.serial_for_url("loop://")
        try:
            with trio.fail_after(1.0), pytest.raises(TypeError, match="path or a pyserial URL"):
                await open_port(ser)  # type: ignore[arg-type]
        finally:
            ser.close()

    run(main)


def test_a_seven_bit_even_parity_line_opens_and_carries_printable_bytes() -> None:
    async def main() -> None:
        port = await open_port("loop://", 2400, bytesize=7, parity="E", stopbits=1)
        async with port:
            assert port.serial is not None
            assert (port.serial.bytesize, port.serial.parity) == (7, "E")
            await port.send_all(b"\x01# ~Kermit\r")
            assert await read_exactly(port, 11) == b"\x01# ~Kermit\r"

    run(main)


def test_an_open_error_names_the_errno_once() -> None:
    async def main() -> None:
        with pytest.raises(OSError, match="No such file") as info:
            await open_port("/dev/ttyNOPE-telelink")
        assert str(info.value).count("Errno") == 1, str(info.value)
        assert str(info.value).count("ttyNOPE") == 1, str(info.value)

    run(main)


def test_a_bad_url_option_is_a_value_error_not_a_key_error() -> None:
    async def main() -> None:
        with pytest.raises(ValueError, match=r"bad option in 'loop://\?logging=nope'"):
            await open_port("loop://?logging=nope")

    run(main)


def test_a_pty_master_gives_its_slave_time_to_read_what_it_wrote_last() -> None:
    """Closing a pty master discards what the slave has not read yet (Linux
    hangs the slave up): a socket closing right after its last ACK lost it on
    a loaded machine, and the peer reported an unclean close.  The master now
    waits PTY_MASTER_CLOSE_GRACE first; a peer that reads within it gets the
    bytes."""

    async def main() -> bytes:
        master, slave = open_pty_pair()
        await master.send_all(b"the last ACK")
        async with trio.open_nursery() as nursery:
            nursery.start_soon(master.aclose)
            await trio.sleep(0.02)  # a peer slow to read
            got = await slave.receive_some()
        await slave.aclose()
        return got

    assert trio.run(main) == b"the last ACK"


def test_an_asyncio_pty_master_waits_too() -> None:
    import asyncio

    import serialsocket.asyncio as sa

    async def main() -> bytes:
        master, slave = sa.open_pty_pair()
        await master.write(b"the last ACK")
        closing = asyncio.ensure_future(master.aclose())
        await asyncio.sleep(0.02)
        got = await slave.read()
        await closing
        await slave.aclose()
        return got

    assert asyncio.run(main()) == b"the last ACK"


# -- dropping what was not sent (an expedited packet cuts in: PROTOCOL.md 11) ---------


def test_a_pty_has_nothing_of_ours_to_drop() -> None:
    """A pty hands each write to its other side at once (TCOFLUSH drops
    nothing there), so a serial socket on it does not cut in: it would only
    send again what already went."""
    from serialsocket._pyserial import holds_output

    async def main() -> None:
        a, b = open_pty_pair()
        async with a, b:
            assert not a.can_discard_output
            assert not b.can_discard_output
            await a.send_all(b"kept")
            a.discard_output()  # nothing happens
            assert await read_exactly(b, 4) == b"kept"
            device = await open_port(b.name, 2400)
            async with device:
                assert not device.can_discard_output
                assert not holds_output(device.serial.fd)
        with pytest.raises(trio.ClosedResourceError):
            a.discard_output()

    run(main)


def test_a_flush_that_fails_is_the_ports_broken_error() -> None:
    """The flush itself (forced on a descriptor that is no terminal): its
    termios error, not an OSError, becomes the port's broken error."""
    import os

    from serialsocket._port import _FdTransport

    async def main() -> None:
        r, w = os.pipe()
        try:
            port = SerialPort(_FdTransport(w, can_discard=True), "a pipe")
            assert port.can_discard_output
            with pytest.raises(trio.BrokenResourceError, match="a pipe failed") as info:
                port.discard_output()
            assert isinstance(info.value.__cause__, OSError)
            assert port.statistics().errors == 1
            await port.aclose()
        finally:
            os.close(r)
            os.close(w)

    run(main)


def test_the_asyncio_port_says_the_same() -> None:
    import asyncio
    import os

    import serialsocket.asyncio as sa
    from serialsocket._asyncio_port import AsyncioSerialPort
    from serialsocket._asyncio_port import _FdTransport as AsyncFd

    async def main() -> None:
        master, slave = sa.open_pty_pair()
        assert not master.can_discard_output
        master.discard_output()
        await master.aclose()
        await slave.aclose()
        with pytest.raises(OSError, match="was closed"):
            master.discard_output()
        r, w = os.pipe()
        try:
            port = AsyncioSerialPort(AsyncFd(w, can_discard=True), "a pipe")
            with pytest.raises(OSError, match=r"Inappropriate ioctl"):
                port.discard_output()
            assert port.statistics().errors == 1
            await port.aclose()
        finally:
            os.close(r)
            os.close(w)

    asyncio.run(main())
