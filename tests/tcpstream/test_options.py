"""One set of client options, typed everywhere (issue 18: one ClientConfig; issue 19:
``BlockingClient.tcp(**options: Any)`` let ``kye=`` through ``mypy --strict``)."""

from __future__ import annotations

import dataclasses
import pathlib
import typing

import pytest
import trio

from tcpstream import (
    DEFAULT_PORT,
    ArmClient,
    BlockingClient,
    ClientConfig,
    ClientOptions,
    connect_stream,
    connect_tcp,
)


def test_the_keyword_options_are_the_config_fields() -> None:
    fields = {f.name: f.type for f in dataclasses.fields(ClientConfig)}
    assert fields.keys() == typing.get_type_hints(ClientOptions).keys()
    assert ClientOptions.__optional_keys__ == frozenset(fields)


async def _never() -> trio.abc.Stream:
    raise AssertionError("not reached")


def test_keywords_override_a_config_and_unknown_ones_are_refused() -> None:
    base = ClientConfig(identity="base", reconnect_attempts=7)
    client = ArmClient(_never, base, identity="override")
    assert client.config == dataclasses.replace(base, identity="override")
    with pytest.raises(TypeError, match="kye"):
        ArmClient(_never, kye=b"0123456789abcdef")  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="kye"):
        connect_tcp("localhost", kye=b"0123456789abcdef")  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="kye"):
        BlockingClient.tcp("localhost", kye=b"0123456789abcdef")  # type: ignore[call-arg]
    with pytest.raises(ValueError, match="reconnect_delay"):
        ClientConfig(reconnect_delay=float("nan"))


def test_connect_stream_without_a_reconnect_factory_never_reconnects() -> None:
    async def main() -> None:
        left, _right = trio.testing.memory_stream_pair()
        client = connect_stream(left, reconnect_attempts=5)
        assert client.config.reconnect_attempts == 0

    trio.run(main)


def test_blocking_tcp_defaults_to_the_same_port_as_connect_tcp() -> None:
    import inspect

    assert inspect.signature(BlockingClient.tcp).parameters["port"].default == DEFAULT_PORT
    assert inspect.signature(connect_tcp).parameters["port"].default == DEFAULT_PORT


def test_mypy_strict_rejects_a_misspelt_option_in_user_code(tmp_path: pathlib.Path) -> None:
    mypy_api = pytest.importorskip("mypy.api")
    user = tmp_path / "controller.py"
    user.write_text(
        "import tcpstream\n"
        "def main() -> None:\n"
        '    with tcpstream.BlockingClient.tcp("arm", kye=b"k" * 16) as arm:\n'
        "        arm.status()\n"
        "async def amain() -> None:\n"
        '    async with tcpstream.connect_tcp("arm", identity=7) as arm:\n'
        "        await arm.status()\n"
    )
    out, _err, status = mypy_api.run(
        ["--strict", "--no-incremental", "--cache-dir", str(tmp_path / "cache"), str(user)]
    )
    assert status == 1, out
    assert 'Unexpected keyword argument "kye"' in out, out
    assert 'Argument "identity"' in out, out
