"""Kermit server mode: the sans-I/O dispatcher, ours against ours over a pty,
and C-Kermit (``get``, ``kermit -g``, ``remote dir/cd/delete/space``, ``send``,
``finish``, ``bye``) and G-Kermit (``-g``) against our server through the relay.

The interop cases skip, saying why, when the program is absent.
"""

from __future__ import annotations

import io
import pathlib

import pytest
import trio

from linksim.bench._kermit import TransferSetup, _ckermit_argv, available, run_against_server
from linksim.link import DirectionConfig, LinkConfig, run_relay
from serialsocket import open_port, open_pty_pair
from serialsocket.kermit import (
    FileData,
    KermitConfig,
    KermitReceiver,
    KermitServer,
    KermitStatistics,
    KermitTransferError,
    OutgoingFile,
    RemoteReply,
    TransferComplete,
    kermit_get,
    kermit_remote,
    kermit_send,
    kermit_server,
)
from serialsocket.kermit._server import (
    Refuse,
    Reply,
    SendFiles,
    ServerRequest,
    ServerState,
    ShowText,
    TransactionEnded,
    TransactionStarted,
)
from serialsocket.packets import BlockCheck, Packet, build_packet

from .test_kermit import _simulate

# -- the sans-I/O server against our client machine --------------------------------


def _answers(request: ServerRequest) -> SendFiles | ShowText | Reply | Refuse:
    if request.kind == "get" and request.argument == "a.bin":
        return SendFiles([OutgoingFile("a.bin", 5, io.BytesIO(b"12345"))])
    if request.kind == "dir":
        return ShowText("Directory listing", b"a.bin 5\r\n")
    if request.kind in ("cd", "finish"):
        return Reply(f"ok {request.argument}".strip())
    return Refuse(f"No files match {request.argument}")


def _server_events(server: KermitServer) -> list[object]:
    out: list[object] = []
    while (e := server.next_event()) is not None:
        out.append(e)
    return out


def _run(server: KermitServer, client: KermitReceiver) -> tuple[bytes, list[object]]:
    # The model wire of test_kermit.py drives any two machines with the surface.
    got, _, events, _ = _simulate(server, client)  # type: ignore[arg-type]
    return got, events


def test_get_sends_the_named_file() -> None:
    config = KermitConfig()
    server = KermitServer(config, 0.0, _answers)
    client = KermitReceiver(config, 0.0, request=("R", b"a.bin"))
    got, events = _run(server, client)
    assert got == b"12345"
    assert events[-1] == TransferComplete()
    assert server.state is ServerState.IDLE  # ready for the next request
    assert server.transactions == 1


def test_remote_dir_comes_as_screen_text() -> None:
    config = KermitConfig()
    server = KermitServer(config, 0.0, _answers)
    client = KermitReceiver(config, 0.0, request=("G", b"D"))
    got, events = _run(server, client)
    assert got == b"a.bin 5\r\n"
    assert any(isinstance(e, FileData) for e in events)


def test_remote_cd_is_answered_in_the_ack_and_finish_ends_the_server() -> None:
    config = KermitConfig()
    server = KermitServer(config, 0.0, _answers)
    client = KermitReceiver(config, 0.0, request=("G", b"C#sub"))
    _, events = _run(server, client)
    assert events == [RemoteReply("ok sub"), TransferComplete()]
    finish = KermitReceiver(config, 0.0, request=("G", b"F"))
    _, events = _run(server, finish)
    assert events == [RemoteReply("ok"), TransferComplete()]
    assert server.finished


def test_a_refusal_is_an_e_packet_and_the_server_stays_up() -> None:
    server = KermitServer(KermitConfig(), 0.0, _answers)
    request = build_packet(Packet(seq=0, type="R", data=b"nothing"), BlockCheck.SUM6)
    server.receive_data(request, 1.0)
    error = build_packet(Packet(seq=0, type="E", data=b"No files match nothing"), BlockCheck.SUM6)
    assert server.data_to_send() == error
    assert _server_events(server) == [
        TransactionStarted(ServerRequest("get", "nothing")),
        TransactionEnded(ServerRequest("get", "nothing"), "No files match nothing"),
    ]
    assert server.state is ServerState.IDLE
    assert server.get_timer() is None  # idle: no timer


def test_unknown_generic_command_is_unimplemented() -> None:
    server = KermitServer(KermitConfig(), 0.0, _answers)
    server.receive_data(build_packet(Packet(seq=0, type="G", data=b"W"), BlockCheck.SUM6), 1.0)
    assert server.data_to_send() == build_packet(
        Packet(seq=0, type="E", data=b"Unimplemented server function"), BlockCheck.SUM6
    )


def test_an_upload_is_received() -> None:
    from serialsocket.kermit import KermitSender

    config = KermitConfig()
    server = KermitServer(config, 0.0, _answers)
    sender = KermitSender([OutgoingFile("u", 3, io.BytesIO(b"abc"))], config, 0.0)
    got = bytearray()

    def collect(event: object) -> None:
        if isinstance(event, FileData):
            got.extend(event.data)

    # The server is the receiving side here.
    _, _, events, _ = _simulate(sender, server)  # type: ignore[arg-type]
    for e in events:
        collect(e)
    assert bytes(got) == b"abc"
    assert events[0] == TransactionStarted(ServerRequest("send"))
    last = events[-1]
    assert isinstance(last, TransactionEnded)
    assert (last.request, last.failure) == (ServerRequest("send"), None)
    assert last.statistics is not None
    assert last.statistics.file_bytes == 3


# -- ours against ours over a pty ---------------------------------------------------


def test_our_client_against_our_server(tmp_path: pathlib.Path) -> None:
    root = tmp_path / "served"
    (root / "sub").mkdir(parents=True)
    (root / "a.txt").write_bytes(b"hello\n" * 100)
    (root / "sub" / "b.bin").write_bytes(bytes(range(256)))
    (tmp_path / "secret").write_bytes(b"outside")
    down = tmp_path / "down"
    down.mkdir()
    upload = tmp_path / "up.bin"
    upload.write_bytes(b"up" * 500)
    config = KermitConfig(timeout=5.0)
    log: list[str] = []

    async def run() -> int:
        a, b = open_pty_pair()
        count = []
        with trio.fail_after(60):
            async with a, b, trio.open_nursery() as nursery:

                async def serve() -> None:
                    count.append(await kermit_server(b, root, config))

                nursery.start_soon(serve)
                log.append(await kermit_remote(a, "dir", "", config))
                await kermit_get(a, "a.txt", down, config)
                log.append(await kermit_remote(a, "cd", "sub", config))
                await kermit_get(a, "b.bin", down, config)
                outside = "outside the served directory"
                with pytest.raises(KermitTransferError, match=outside):
                    await kermit_remote(a, "cd", "../..", config)
                with pytest.raises(KermitTransferError, match=outside):
                    await kermit_get(a, "../../secret", down, config)
                log.append(await kermit_remote(a, "cd", "", config))
                await kermit_send(a, [upload], config)
                log.append(await kermit_remote(a, "delete", "a.txt", config))
                log.append(await kermit_remote(a, "space", "", config))
                log.append(await kermit_remote(a, "bye", "", config))
        return count[0]

    count = trio.run(run)
    assert count == 11
    assert log[0].startswith("Directory /\r\na.txt ")
    assert log[1:3] == ["/sub", "/"]
    assert log[3] == "1 file deleted"
    assert log[4].endswith(" bytes free")
    assert (down / "a.txt").read_bytes() == b"hello\n" * 100
    assert (down / "b.bin").read_bytes() == bytes(range(256))
    assert not (down / "secret").exists()
    assert (root / "up.bin").read_bytes() == upload.read_bytes()
    assert not (root / "a.txt").exists()


# -- other Kermits against our server --------------------------------------------------


def _tree(tmp_path: pathlib.Path) -> tuple[pathlib.Path, pathlib.Path]:
    root = tmp_path / "served"
    (root / "sub").mkdir(parents=True)
    (root / "a.txt").write_bytes(b"hello kermit\n" * 200)
    (root / "sub" / "b.bin").write_bytes(bytes(range(256)) * 8)
    (root / "del.me").write_bytes(b"x")
    (tmp_path / "secret.txt").write_bytes(b"outside the tree")
    client = tmp_path / "client"
    client.mkdir()
    (client / "up.bin").write_bytes(bytes(range(256)) * 4)
    return root, client


def test_c_kermit_session_against_our_server(tmp_path: pathlib.Path) -> None:
    if not available("ckermit"):
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    root, client = _tree(tmp_path)
    setup = TransferSetup(
        sender="ckermit", receiver="ours", window=8, delay=0.02, byte_error_rate=1e-5, limit=60
    )
    commands = [
        "get a.txt",
        "remote dir",
        "remote cd sub",
        "get b.bin",
        "remote cd ..",
        "remote delete del.me",
        "remote space",
        "send up.bin",
        "finish",
    ]
    count, status, output = run_against_server(setup, root, client, commands)
    assert (count, status) == (9, 0), output
    assert (client / "a.txt").read_bytes() == (root / "a.txt").read_bytes()
    assert (client / "b.bin").read_bytes() == (root / "sub" / "b.bin").read_bytes()
    assert (root / "up.bin").read_bytes() == (client / "up.bin").read_bytes()
    assert not (root / "del.me").exists()
    assert "Directory /" in output
    assert "a.txt" in output
    assert "1 file deleted" in output
    assert " bytes free" in output


def test_c_kermit_cannot_leave_the_served_tree(tmp_path: pathlib.Path) -> None:
    if not available("ckermit"):
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    root, client = _tree(tmp_path)
    setup = TransferSetup(sender="ckermit", receiver="ours", window=8, limit=60)
    commands = [
        "get ../secret.txt",
        "remote cd ..",
        "remote delete ../secret.txt",
        "remote dir",
        "bye",
    ]
    count, _, output = run_against_server(setup, root, client, commands)
    assert count == 5, output
    assert not (client / "secret.txt").exists()
    assert (tmp_path / "secret.txt").exists()
    # Still at the top of the tree: the listing is of it, and the file outside
    # never showed up.
    assert "Directory /\n" in output, output
    assert "secret" not in output


@pytest.mark.parametrize("client", ["ckermit", "gkermit"])
def test_command_line_get_fetches_from_our_server(tmp_path: pathlib.Path, client: str) -> None:
    """``kermit -g a.txt`` and ``gkermit -g a.txt``."""
    if not available(client):
        pytest.skip(f"{client} not installed: .ci/run installs it")
    root, where = _tree(tmp_path)
    setup = TransferSetup(sender=client, receiver="ours", window=8, limit=60)
    count, status, output = run_against_server(setup, root, where, ["-i -g a.txt"])
    assert status == 0, output
    assert count == -1  # no FINISH: the server is still serving
    assert (where / "a.txt").read_bytes() == (root / "a.txt").read_bytes()


# -- REGET ---------------------------------------------------------------------------------


def test_c_kermit_reget_fetches_only_the_rest(tmp_path: pathlib.Path) -> None:
    """C-Kermit's ``reget``: the J packet; our server sends with RESEND, and
    C-Kermit answers with the size of the part it holds."""
    if not available("ckermit"):
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    root, client = _tree(tmp_path)
    data = bytes(range(256)) * 400
    (root / "big.bin").write_bytes(data)
    (client / "big.bin").write_bytes(data[:40_000])
    setup = TransferSetup(
        sender="ckermit", receiver="ours", window=8, delay=0.02, byte_error_rate=1e-5, limit=60
    )
    ended: list[TransactionEnded] = []
    count, status, output = run_against_server(
        setup, root, client, ["reget big.bin", "finish"], ended
    )
    assert (count, status) == (2, 0), output
    assert (client / "big.bin").read_bytes() == data
    stats = ended[0].statistics
    assert ended[0].request == ServerRequest("reget", "big.bin")
    assert stats is not None
    assert (stats.resumed_bytes, stats.file_bytes) == (40_000, len(data) - 40_000)


def test_our_reget_against_our_server(tmp_path: pathlib.Path) -> None:
    root = tmp_path / "served"
    root.mkdir()
    data = bytes(range(256)) * 100
    (root / "r.bin").write_bytes(data)
    down = tmp_path / "down"
    down.mkdir()
    (down / "r.bin.part").write_bytes(data[:10_000])  # what an interrupted GET left
    config = KermitConfig(timeout=5.0)

    async def run() -> KermitStatistics:
        a, b = open_pty_pair()
        with trio.fail_after(60):
            async with a, b, trio.open_nursery() as nursery:
                nursery.start_soon(kermit_server, b, root, config)
                stats = await kermit_get(a, "r.bin", down, config, recover=True)
                await kermit_remote(a, "finish", "", config)
                return stats

    stats = trio.run(run)
    assert (down / "r.bin").read_bytes() == data
    assert (stats.resumed_bytes, stats.file_bytes) == (10_000, len(data) - 10_000)


# -- our client against C-Kermit's server ----------------------------------------------------


def test_our_client_against_c_kermit_server(tmp_path: pathlib.Path) -> None:
    """``serialsocket kermit get`` and ``remote dir/space/finish`` against C-Kermit's SERVER."""
    if not available("ckermit"):
        pytest.skip("ckermit not installed: .ci/run installs it (apt-get install ckermit)")
    served = tmp_path / "served"
    served.mkdir()
    (served / "a.txt").write_bytes(b"from c-kermit\n" * 50)
    down = tmp_path / "down"
    down.mkdir()
    setup = TransferSetup(sender="ckermit", receiver="ours", delay=0.02, byte_error_rate=1e-5)
    config = KermitConfig(timeout=5.0, literal_names=True)
    answers: list[str] = []
    status: list[int] = []

    async def main() -> None:
        line = LinkConfig.symmetric(
            DirectionConfig(delay=setup.delay, byte_error_rate=setup.byte_error_rate), seed=2
        )
        with trio.fail_after(60):
            async with trio.open_nursery() as nursery:
                ready: list[tuple[str, str]] = []
                got = trio.Event()

                def on_ready(a: str, b: str) -> None:
                    ready.append((a, b))
                    got.set()

                nursery.start_soon(lambda: run_relay(line, stop=trio.Event(), on_ready=on_ready))
                await got.wait()
                ours, theirs = ready[0]
                argv = _ckermit_argv(setup, theirs, [])
                argv[-1] = argv[-1].replace("receive, exit \\v(status)", "server, exit")

                async def serve() -> None:
                    result = await trio.run_process(
                        argv, cwd=served, capture_stdout=True, capture_stderr=True, check=False
                    )
                    status.append(result.returncode)

                nursery.start_soon(serve)
                await trio.sleep(1.0)  # C-Kermit opens its line and enters server mode
                port = await open_port(ours)
                async with port:
                    await kermit_get(port, "a.txt", down, config)
                    answers.append(await kermit_remote(port, "dir", "", config))
                    answers.append(await kermit_remote(port, "space", "", config))
                    answers.append(await kermit_remote(port, "finish", "", config))
                while not status:
                    await trio.sleep(0.05)
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert (down / "a.txt").read_bytes() == (served / "a.txt").read_bytes()
    assert "a.txt" in answers[0]
    assert "Available" in answers[1] or "free" in answers[1].lower()
    assert answers[2] == ""
    assert status == [0]


def test_a_request_in_the_same_read_as_the_last_ack_keeps_its_file_open(
    tmp_path: pathlib.Path,
) -> None:
    """The server learns that a GET ended and that the next one started from
    the same read; the end must close the first file only.  Closing every
    handle at the end crashed the server with "read of closed file" when the
    client's next request arrived with its last ACK (one run in four of
    test_our_client_against_our_server under load)."""
    from serialsocket.kermit._serve import _Served

    (tmp_path / "one").write_bytes(b"1" * 10)
    (tmp_path / "two").write_bytes(b"2" * 10)
    served = _Served(tmp_path)
    first = served._open(tmp_path / "one")
    served.begin()  # TransactionStarted(get one)
    second = served._open(tmp_path / "two")  # the next GET, in the same read
    served.end()  # TransactionEnded(get one), reported after that read
    served.begin()  # TransactionStarted(get two)
    assert first.source.closed
    assert not second.source.closed
    assert second.source.read() == b"2" * 10
    served.close()
    assert second.source.closed
