"""The distribution as a user installs it: build the wheel and sdist, install the wheel
into a fresh virtual environment with no extras, and run the demo from there (issue 24)."""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import tarfile
import venv
import zipfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
LIMIT = 600.0
"""Seconds for a step that may download the runtime dependencies (a guard, not a target)."""


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=LIMIT,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return out


def _version() -> str:
    import tcpstream

    return tcpstream.__version__


def test_the_wheel_ships_what_the_docstrings_cite(dist: pathlib.Path) -> None:
    [wheel] = dist.glob("telelink-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    for doc in ("serialsocket/PROTOCOL.md", "serialsocket/KERMIT.md", "tcpstream/PROTOCOL.md"):
        assert doc in names
    for package in ("serialsocket", "tcpstream", "linksim"):
        assert f"{package}/py.typed" in names
    version = _version()
    assert f"telelink-{version}.dist-info/licenses/LICENSE" in names
    assert f"telelink-{version}.data/data/share/doc/telelink/RELIABILITY.md" in names
    [sdist] = dist.glob("telelink-*.tar.gz")
    with tarfile.open(sdist) as archive:
        members = {m.split("/", 1)[1] for m in archive.getnames() if "/" in m}
    assert {"LICENSE", "README.md", "RELIABILITY.md", "tcpstream/PROTOCOL.md"} <= members


def test_a_fresh_venv_runs_the_demo_from_the_wheel(
    dist: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    [wheel] = dist.glob("telelink-*.whl")
    env = tmp_path / "venv"
    venv.create(env, with_pip=True)
    bin_dir = env / "bin"
    install = subprocess.run(
        [str(bin_dir / "python"), "-m", "pip", "install", "--quiet", str(wheel)],
        capture_output=True,
        text=True,
        timeout=LIMIT,
    )
    assert install.returncode == 0, install.stderr[-3000:]
    # No extras: the demo needs none; run from elsewhere so the checkout is not imported.
    demo = subprocess.run(
        [str(bin_dir / "linksim"), "demo", "--virtual", "--json"],
        capture_output=True,
        text=True,
        timeout=LIMIT,
        cwd=tmp_path,
    )
    assert demo.returncode == 0, demo.stderr[-3000:]
    report = json.loads(demo.stdout)
    assert report["ok"] is True
    assert report["commands"]["completed"] == 11
    version = _version()
    for tool in ("serialsocket", "tcpstream", "linksim"):
        said = subprocess.run(
            [str(bin_dir / tool), "--version"], capture_output=True, text=True, timeout=60
        )
        assert said.stdout.strip() == f"{tool} {version}"
    where = subprocess.run(
        [str(bin_dir / "python"), "-c", "import linksim, tcpstream; print(tcpstream.__file__)"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert str(env) in where.stdout  # the installed copy, not the checkout
