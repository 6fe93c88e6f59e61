"""The documentation site (issue 24, part 6): ``mkdocs build --strict`` keeps building.

The site is the README's tour, the protocol documents and the API reference
generated from the docstrings (mkdocs.yml, docs/).  Any warning fails the
build, so a docstring that mkdocstrings cannot read, a broken link between the
documents or a module that no longer imports fails this test.  It needs the
``docs`` extra (part of ``test``; ``make docs`` installs it alone) and skips,
saying so, without it.
"""

from __future__ import annotations

import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    for module in ("mkdocs", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason="the docs extra is not installed: pip install '.[docs]'")
    out = tmp_path_factory.mktemp("docs") / "site"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    assert "WARNING" not in done.stderr, done.stderr[-4000:]
    return out


def test_the_tour_and_protocol_documents_are_pages(site: pathlib.Path) -> None:
    home = (site / "index.html").read_text()
    assert "Two commands" in home  # the README is the home page
    # Its links to the protocol documents point at their pages.
    assert 'href="protocol/serialsocket/"' in home
    assert 'href="protocol/tcpstream/"' in home
    assert 'href="reliability/"' in home
    serial = (site / "protocol" / "serialsocket" / "index.html").read_text()
    assert "The serialsocket wire protocol" in serial
    assert "CRC-16/KERMIT" in serial
    assert "216 bytes" in (site / "protocol" / "tcpstream" / "index.html").read_text()
    assert (site / "protocol" / "kermit" / "index.html").is_file()


@pytest.mark.parametrize(
    ("page", "names"),
    [
        ("serialsocket", ["SerialSocket", "EndpointConfig", "open_port", "connect"]),
        ("serialsocket.packets", ["PacketParser", "build_packet", "crc16_kermit"]),
        ("serialsocket.kermit", ["KermitSender", "kermit_send"]),
        ("serialsocket.capture", ["PcapngWriter", "CaptureFile", "read_pcapng"]),
        ("tcpstream", ["ArmClient", "Server", "connect_tcp"]),
        ("tcpstream.commands", ["encode_packet", "decode_packet", "CommandCode"]),
        ("linksim.link", ["LinkConfig", "run_relay"]),
    ],
)
def test_public_names_have_reference_entries(
    site: pathlib.Path, page: str, names: list[str]
) -> None:
    html = (site / "api" / page / "index.html").read_text()
    for name in names:
        assert f'id="{page}.{name}"' in html, f"{page}.{name} has no entry on its page"
