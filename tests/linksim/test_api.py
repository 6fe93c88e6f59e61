"""linksim's public surface and its sans-I/O cores."""

from __future__ import annotations

import ast
import pathlib

import linksim

ROOT = pathlib.Path(__file__).resolve().parents[2]
FORBIDDEN = {"trio", "serial", "socket", "time", "random", "threading", "asyncio", "os", "select"}


def imports_of(path: pathlib.Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_engine_config_and_modem_are_sans_io() -> None:
    for module in ("_impair", "_config", "_modem"):
        bad = imports_of(ROOT / "linksim" / f"{module}.py") & FORBIDDEN
        assert not bad, f"linksim/{module}.py imports {bad}"


def test_public_names_are_pinned() -> None:
    assert sorted(linksim.__all__) == sorted(
        [
            "DEFAULT_WORLD",
            "PRESETS",
            "PUMA560",
            "TRANSITIONS",
            "ArmModel",
            "ArmStatistics",
            "CallOutcome",
            "CommandRecord",
            "CommandState",
            "ConfigError",
            "ConsoleOptions",
            "ConsoleResult",
            "ConsoleSession",
            "ConsoleSnapshot",
            "DemoOptions",
            "DemoReport",
            "DirectionConfig",
            "DirectionStatistics",
            "Divergence",
            "FaultAction",
            "GilbertElliott",
            "ImpairedLink",
            "LinkConfig",
            "LinkDirection",
            "LinkEnd",
            "LinkStatistics",
            "ModemConfig",
            "ModemPair",
            "ModemState",
            "ModemStateError",
            "ModelState",
            "ObjectSpec",
            "ObstacleSpec",
            "Outage",
            "PredictedOutcome",
            "Predictor",
            "PreviewReport",
            "RelayStatistics",
            "RockTask",
            "ScriptedFault",
            "SimulatedArm",
            "TaskRun",
            "TelemetryLog",
            "WorldConfig",
            "endpoint_config_for",
            "open_impaired_link",
            "preview",
            "read_log",
            "rock_task",
            "run_console",
            "run_demo",
            "run_relay",
            "serial_socket_pair",
        ]
    )
    for name in linksim.__all__:
        assert getattr(linksim, name) is not None


def test_modem_transition_table_covers_every_state() -> None:
    assert set(linksim.TRANSITIONS) == set(linksim.ModemState)
